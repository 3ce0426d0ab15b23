#pragma once

// The bindings of one application support actor (pure core): for each
// proxy, the remote APO it is bound to (watched, with the watch renewed
// periodically) or, for a rebinding proxy between targets, what it looks
// for and when to look next.
//
// No clock and no I/O: time comes in as arguments; the caller creates and
// ends proxies and sends watches. Proxies are held weakly (a binding never
// keeps one alive). Not thread-safe (one actor owns it). One binding per
// live proxy; find and add are O(log n), the scans O(n).

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "caf/actor_control_block.hpp"
#include "caf/weak_intrusive_ptr.hpp"

#include "actors/app_support.hpp"

namespace herm {

/// A proxy and what it is bound to.
struct binding {
  using time_point = std::chrono::steady_clock::time_point;

  caf::weak_actor_ptr proxy;
  bool bound = false;
  apo_ref target;
  /// Rebinding proxies: what to look for while unbound.
  bool rebind = false;
  query_by by = query_by::name;
  std::string pattern;
  time_point next_search;
  bool searching = false;
  time_point last_watch;
  /// Requests through this proxy travel in reliable mode.
  bool reliable = false;
  /// ... and signed (apo_access::signed_only).
  bool sign = false;

  /// The watch of the target is (re)newed at `now`: true if the target is
  /// on another module than `self` (then a watch is to be sent there).
  bool watch(module_id self, time_point now) {
    last_watch = now;
    return target.module != self;
  }
};

class binding_table {
public:
  using time_point = binding::time_point;

  /// A new binding, unbound, with its id (never 0, never reused while the
  /// table lives; not before 2^32 bindings).
  std::pair<uint32_t, binding&> add(time_point now);

  /// The binding, or nullptr.
  binding* find(uint32_t id);

  /// Every bound binding to APO `apo` on module `m` (`apo` 0: any there).
  std::vector<uint32_t> bound_to(module_id m, uint32_t apo) const;

  /// The target of binding `id` is gone at `now`: a rebinding one becomes
  /// unbound and looks for a new target at once (returns nullptr); any
  /// other is removed, and its proxy (if still alive) returned to be ended.
  caf::strong_actor_ptr lose(uint32_t id, time_point now);

  /// Nobody holds binding `id`'s proxy any more: removes it. Returns its
  /// target when it was the last binding to that remote APO (not on
  /// module `self`), to be unwatched.
  std::optional<apo_ref> close(uint32_t id, module_id self);

  struct due_list {
    /// Bound, watched `watch_refresh` ago or longer: renew the watch.
    std::vector<uint32_t> watch;
    /// Rebinding, unbound, not searching, next_search reached: search.
    std::vector<uint32_t> search;
  };

  due_list due(time_point now, std::chrono::milliseconds watch_refresh) const;

  const std::map<uint32_t, binding>& all() const {
    return bindings_;
  }

  void clear() {
    bindings_.clear();
  }

private:
  uint32_t next_ = 1;
  std::map<uint32_t, binding> bindings_;
};

} // namespace herm
