#pragma once

// The APOs registered on one module (pure core of the application support
// actor): the application table (names, types, numbers, watchers, the
// remote APOs learned) and, per local APO, its actor handle and who may use
// it (apo_access).
//
// No clock and no I/O: time comes in as arguments; handles are held, never
// used. Not thread-safe (one actor owns it). One entry per registered APO;
// add, find, remove O(log n), list O(n).

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "caf/actor.hpp"
#include "caf/actor_addr.hpp"
#include "caf/expected.hpp"

#include "actors/app_support.hpp"
#include "actors/app_table.hpp"

namespace herm {

class apo_registry {
public:
  using time_point = app_table::time_point;

  /// `key` seeds the APO numbers (app_table).
  explicit apo_registry(uint64_t key);

  app_table& table() {
    return table_;
  }

  const app_table& table() const {
    return table_;
  }

  /// Registers actor `apo` under `name` and `type`: its number. Errors:
  /// ec::invalid_parameter (a name or type empty or over max_asl_string
  /// bytes, an invalid handle), ec::already_exists (`apo` is registered).
  caf::expected<uint32_t> add(std::string name, std::string type,
                              const caf::actor& apo, apo_access access);

  /// The local APO number `apo`; nullptr if none.
  const caf::actor* find(uint32_t apo) const;

  /// The number of registered actor `who`; 0 if it is not registered.
  uint32_t number_of(const caf::actor_addr& who) const;

  /// Whether local APO `apo` is registered apo_access::signed_only.
  bool signed_only(uint32_t apo) const {
    return signed_only_.count(apo) != 0;
  }

  struct removed {
    std::string name;
    /// The modules that watched it.
    std::set<module_id> watchers;
  };

  /// Unregisters local APO `apo`; nullopt if there is none.
  std::optional<removed> remove(uint32_t apo);

  /// The application table for people: the local APOs (as module `self`'s,
  /// with their watcher counts), then the remote ones with their age at
  /// `now`.
  std::vector<apo_info> list(module_id self, time_point now) const;

private:
  app_table table_;
  std::map<uint32_t, caf::actor> apos_;
  std::map<caf::actor_addr, uint32_t> numbers_;
  std::set<uint32_t> signed_only_;
};

} // namespace herm
