#pragma once

// The bindings of one application support actor (pure core): for each
// proxy, the remote APO it is bound to (watched, with the watch renewed
// periodically) or, for a rebinding proxy between targets, what it looks
// for and when to look next.
//
// No clock and no I/O: time comes in as arguments, watches go into the
// caller's asl_outbox; the caller creates and ends proxies. Proxies are held weakly (a binding never
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
#include "actors/asl_outbox.hpp"

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
};

class binding_table {
public:
  using time_point = binding::time_point;

  /// A new binding, unbound, with its id (never 0, never reused while the
  /// table lives; not before 2^32 bindings).
  std::pair<uint32_t, binding&> add(time_point now);

  /// The binding, or nullptr.
  binding* find(uint32_t id);

  const binding* find(uint32_t id) const {
    return const_cast<binding_table*>(this)->find(id);
  }

  /// Points `b` at `ref` at `now` and watches it (if it is not on module
  /// `self`).
  static void bind(binding& b, const apo_ref& ref, module_id self,
                   time_point now, asl_outbox& out);

  /// Every bound binding to APO `apo` on module `m` (`apo` 0: any there).
  std::vector<uint32_t> bound_to(module_id m, uint32_t apo) const;

  /// The target of binding `id` is gone at `now`: a rebinding one becomes
  /// unbound and looks for a new target at once (returns nullptr); any
  /// other is removed, and its proxy (if still alive) returned to be ended.
  caf::strong_actor_ptr lose(uint32_t id, time_point now);

  /// Nobody holds binding `id`'s proxy any more: removes it. When it was
  /// the last binding to a remote APO (not on module `self`), the watch
  /// ends.
  void close(uint32_t id, module_id self, asl_outbox& out);

  /// A discovery to start for a rebinding binding without a target.
  struct search {
    uint32_t id = 0;
    /// Collects for half of rebind_interval, ends at the first match.
    apo_query query;
  };

  /// Renews the watches made `watch_refresh` ago or longer; returns the
  /// searches to start now (for bindings unbound, not searching, whose
  /// next_search came; they are searching from now on).
  std::vector<search> housekeep(time_point now,
                                std::chrono::milliseconds watch_refresh,
                                std::chrono::milliseconds rebind_interval,
                                module_id self, asl_outbox& out);

  /// The search for binding `id` ended at `now` with `found`: the next one
  /// is due `rebind_interval` later, and an unbound binding is bound to
  /// the first match. True if it was bound now.
  bool found(uint32_t id, const std::vector<apo_ref>& found, module_id self,
             time_point now, std::chrono::milliseconds rebind_interval,
             asl_outbox& out);

  const std::map<uint32_t, binding>& all() const {
    return bindings_;
  }

  /// Removes every binding; returns their proxies still alive (to end).
  std::vector<caf::strong_actor_ptr> take_proxies();

private:
  static void watch(binding& b, module_id self, time_point now,
                    asl_outbox& out);

  uint32_t next_ = 1;
  std::map<uint32_t, binding> bindings_;
};

} // namespace herm
