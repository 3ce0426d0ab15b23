#pragma once

// The application table of one module (pure core of the application support
// actor): the APOs registered here, the remote APOs learned from discovery
// answers, and which modules watch which local APO. No clock and no I/O:
// time comes in as arguments.

#include <chrono>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "actors/asl_wire.hpp"
#include "routing/module_id.hpp"

namespace herm {

class app_table {
public:
  using time_point = std::chrono::steady_clock::time_point;

  struct local_entry {
    std::string name;
    std::string type;
    std::set<module_id> watchers;
  };

  struct remote_entry {
    std::string name;
    std::string type;
    time_point heard;
  };

  /// APO numbers start at `first` (random per module start, so that numbers
  /// of a previous life are not taken for current ones) and never repeat
  /// while the table lives (they wrap after 2^32, skipping 0).
  explicit app_table(uint32_t first = 1);

  // -- local APOs ---------------------------------------------------------------

  /// Registers a local APO; returns its number.
  uint32_t add_local(std::string name, std::string type);

  /// Removes a local APO; returns the modules that watched it (empty if the
  /// number is unknown).
  std::set<module_id> remove_local(uint32_t apo);

  const local_entry* local(uint32_t apo) const;

  const std::map<uint32_t, local_entry>& locals() const {
    return locals_;
  }

  /// Local APOs matching a query, in number order.
  std::vector<asl_entry> match(query_by by, const std::string& pattern) const;

  // -- watchers -----------------------------------------------------------------

  /// Module `m` watches local APO `apo`; false if there is no such APO.
  bool watch(uint32_t apo, module_id m);

  void unwatch(uint32_t apo, module_id m);

  /// Forgets every watch of module `m` (it became unreachable).
  void drop_watcher(module_id m);

  // -- remote APOs ----------------------------------------------------------------

  /// Records (or refreshes) what module `m` answered.
  void learn(module_id m, const asl_entry& e, time_point now);

  void forget(module_id m, uint32_t apo);

  void forget_module(module_id m);

  /// Drops remote entries not heard from within `ttl`.
  void expire(time_point now, std::chrono::steady_clock::duration ttl);

  const std::map<std::pair<module_id, uint32_t>, remote_entry>& remotes() const {
    return remotes_;
  }

  /// True if `e` matches a query.
  static bool matches(query_by by, const std::string& pattern,
                      const std::string& name, const std::string& type);

private:
  uint32_t next_;
  std::map<uint32_t, local_entry> locals_;
  std::map<std::pair<module_id, uint32_t>, remote_entry> remotes_;
};

} // namespace herm
