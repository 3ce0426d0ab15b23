#pragma once

// The discoveries one application support actor has running (pure core;
// docs/protocol.md, "Discovery"): per query id, what is looked for, the
// matches collected so far and whom to tell at the end. The caller sends
// the query, answers it, and ends each discovery when its time is over
// (or as soon as it is satisfied).
//
// No clock and no I/O. Not thread-safe (one actor owns it). Each discovery
// holds at most `max_found` matches (more distinct ones are refused and
// counted); start and answered are O(e log f) for e entries and f found.

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <vector>

#include "actors/app_support.hpp"
#include "actors/app_table.hpp"

namespace herm {

class discovery_table {
public:
  /// Called once with the matches when a discovery ends.
  using callback = std::function<void(std::vector<apo_ref>)>;

  struct counters {
    /// Matching answer entries not collected: max_found held already.
    uint64_t discovery_entries_refused = 0;
  };

  /// Query ids come from a scrambled_sequence keyed with `key` (one id
  /// seen gives away no other).
  discovery_table(uint64_t key, size_t max_found);

  /// Starts a discovery of `q` with the matches on this module (`local`,
  /// not bounded): returns its query id, never 0 or one running.
  uint32_t start(apo_query q, std::vector<apo_ref> local, callback finish);

  /// Whether discovery `qid` may end now: it wants the first answer and
  /// has a match. False for an unknown id.
  bool satisfied(uint32_t qid) const;

  /// Module `src` answered `entries` to `qid`: collects those that match.
  /// Returns satisfied(qid). An unknown (ended, forged) id is ignored.
  bool answered(uint32_t qid, module_id src,
                const std::vector<asl_entry>& entries);

  struct finished {
    callback finish;
    /// The matches of module `self` first, then by module and number.
    std::vector<apo_ref> found;
  };

  /// Ends discovery `qid`; nullopt if it is not running.
  std::optional<finished> finish(uint32_t qid, module_id self);

  /// The ids of every discovery running, in id order.
  std::vector<uint32_t> running() const;

  const counters& stats() const {
    return stats_;
  }

private:
  struct discovery {
    apo_query query;
    std::set<apo_ref> found;
    callback finish;
  };

  scrambled_sequence<uint32_t> ids_;
  size_t max_found_;
  counters stats_;
  std::map<uint32_t, discovery> running_;
};

} // namespace herm
