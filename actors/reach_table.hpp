#pragma once

// Which modules the application support actor can reach (pure core): the
// modules with a route now, and since when the others lost theirs, so that
// a module is given up only after a grace period (routes converging after
// a change come back sooner).
//
// No clock and no I/O: time comes in as arguments. Not thread-safe (one
// actor owns it). One entry per module heard of; up, down and reachable
// O(log n), lost O(n).

#include <chrono>
#include <map>
#include <set>
#include <vector>

#include "routing/module_id.hpp"

namespace herm {

class reach_table {
public:
  using time_point = std::chrono::steady_clock::time_point;

  /// Module `m` has a route now.
  void up(module_id m);

  /// Module `m` lost its route at `now`; no effect unless it had one.
  void down(module_id m, time_point now);

  bool reachable(module_id m) const {
    return reachable_.count(m) != 0;
  }

  /// The modules unreachable for `grace` or longer at `now`, in id order:
  /// each is reported once (then forgotten until it comes up again).
  std::vector<module_id> lost(time_point now,
                              std::chrono::steady_clock::duration grace);

private:
  std::set<module_id> reachable_;
  std::map<module_id, time_point> unreachable_since_;
};

} // namespace herm
