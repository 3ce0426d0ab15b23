#pragma once

// The APOs registered on one module (pure core of the application support
// actor): the application table (names, types, numbers, watchers, the
// remote APOs learned) and, per local APO, its actor handle and who may use
// it (apo_access).
//
// No clock and no I/O: time comes in as arguments, what is to be sent goes
// into the caller's asl_outbox; handles are held, never used. Not
// thread-safe (one actor owns it). One entry per registered APO, at most
// `max_watches` watches by other modules over all of them (more are
// refused, counted); add, find, remove O(log n + w) for w watchers, list
// O(n).

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
#include "actors/asl_outbox.hpp"

namespace herm {

class apo_registry {
public:
  using time_point = app_table::time_point;

  /// `key` seeds the APO numbers (app_table). Counts registered,
  /// withdrawn and watches_refused into `stats`, which must outlive it.
  apo_registry(uint64_t key, size_t max_watches, app_support_stats& stats);

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

  /// Unregisters local APO `apo`, which ended for `reason`: its watchers
  /// hear so, and its withdrawal is broadcast. Returns its name; nullopt if
  /// there is no such APO.
  std::optional<std::string> remove(uint32_t apo, const caf::error& reason,
                                    asl_outbox& out);

  /// Module `src` watches local APO `w.apo`: told at once if there is no
  /// such APO on this module (`self`); refused silently (counted) past
  /// max_watches (the watcher finds out by renewing).
  void on_watch(module_id src, const asl_watch& w, module_id self,
                asl_outbox& out);

  void on_unwatch(module_id src, const asl_unwatch& w) {
    table_.unwatch(w.apo, src);
  }

  /// The application table for people: the local APOs (as module `self`'s,
  /// with their watcher counts), then the remote ones with their age at
  /// `now`.
  std::vector<apo_info> list(module_id self, time_point now) const;

private:
  app_table table_;
  size_t max_watches_;
  app_support_stats* stats_;
  std::map<uint32_t, caf::actor> apos_;
  std::map<caf::actor_addr, uint32_t> numbers_;
  std::set<uint32_t> signed_only_;
};

} // namespace herm
