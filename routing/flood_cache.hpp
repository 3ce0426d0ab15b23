#pragma once

// The flood cache: what a module remembers of the packets it relayed by
// flooding (claims, conflicts, seqno requests, flooded broadcasts), so that
// each is relayed at most once and a copy arriving over another path is
// dropped. Pure: no clock, no I/O; time is passed in. One cache, one bound,
// serves every kind of flood; each entry carries its own lifetime, as kinds
// differ in how long a duplicate can still arrive (half a hello interval
// for control floods, routing_config::flood_memory for broadcasts).

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <tuple>
#include <utility>

namespace herm {

class flood_cache {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;

  /// Identifies one flood: a kind (the agent uses the packet type) and two
  /// numbers the kind chooses (origin and seqno, source and flood id, ...).
  struct key {
    uint8_t kind = 0;
    uint64_t a = 0;
    uint64_t b = 0;

    friend bool operator<(const key& x, const key& y) {
      return std::tie(x.kind, x.a, x.b) < std::tie(y.kind, y.a, y.b);
    }
  };

  /// Holds at most `capacity` entries (at least 1; 0 is taken as 1).
  explicit flood_cache(size_t capacity);

  /// True if `k` is not remembered (never seen, or its lifetime has passed
  /// by `now`): then it is remembered until `now + lifetime`. False for a
  /// duplicate, which changes nothing (the lifetime runs from the first
  /// copy). Entries whose lifetime has passed are forgotten first; when the
  /// cache is still full, the one that would expire soonest (of entries
  /// with one lifetime: the oldest) is forgotten early and counted in
  /// evicted(): a duplicate of it may then be relayed once more, which hop
  /// limits bound. `now` must not go backwards between calls.
  /// O(log capacity) amortised; one entry evicted per call at most.
  bool admit(const key& k, time_point now, duration lifetime);

  /// Entries remembered now (some may have expired: they go at the next
  /// admit()).
  size_t size() const {
    return expiry_.size();
  }

  size_t capacity() const {
    return capacity_;
  }

  /// Entries of `kind` forgotten early to stay within the capacity.
  uint64_t evicted(uint8_t kind) const;

  /// Entries of any kind forgotten early.
  uint64_t evicted() const;

private:
  /// When an entry expires, and its admission number (the tie-breaker that
  /// makes the order of equal expiries the admission order).
  using stamp = std::pair<time_point, uint64_t>;

  void forget(std::map<stamp, key>::iterator i);

  size_t capacity_;
  uint64_t admitted_ = 0;
  /// The same entries, by key and by expiry.
  std::map<key, stamp> expiry_;
  std::map<stamp, key> order_;
  std::map<uint8_t, uint64_t> evicted_;
};

} // namespace herm
