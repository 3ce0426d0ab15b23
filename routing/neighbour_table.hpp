#pragma once

// The neighbour table: who this module hears hellos from, on which channel
// and link address, and until when they count as alive. Pure: no clock, no
// I/O; time is passed in. The routing agent feeds it hellos, goodbyes, lost
// channels and its timer, and tells the route table what it returns.
//
// Bounded: a fake peer on a broadcast link can say hello from any number of
// link addresses, so the table holds at most `limits::total` neighbours,
// `limits::per_channel` on one channel; a new neighbour past a bound is
// refused (counted in refused()) until one is lost. Neighbours already held
// keep being refreshed.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <vector>

#include "routing/module_id.hpp"
#include "routing/route_table.hpp"

namespace herm {

class neighbour_table {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;

  struct limits {
    /// Neighbours at most, in total and per channel (routing_config's
    /// max_neighbours, max_neighbours_per_channel).
    size_t total = 512;
    size_t per_channel = 128;
    /// This module's hello interval, and how many intervals without a hello
    /// lose a neighbour (routing_config's hello_interval, hello_loss). A
    /// neighbour saying a longer interval than ours is given its own.
    std::chrono::milliseconds hello_interval{1000};
    double hello_loss = 1.5;
  };

  /// One neighbour as its last hello described it.
  struct neighbour {
    module_id id = no_module;
    uint64_t instance = 0;
    time_point last_hello;
    /// The hello interval it said it uses.
    std::chrono::milliseconds interval{0};
  };

  /// What heard() did with a hello.
  enum class hello_result : uint8_t {
    /// A neighbour not held before, now held.
    added,
    /// A neighbour held, with the same instance: refreshed.
    refreshed,
    /// A neighbour held, with another instance (it restarted): refreshed.
    restarted,
    /// A neighbour not held, past a bound: ignored (counted).
    refused,
  };

  /// With the default limits.
  neighbour_table();
  explicit neighbour_table(limits lim);

  /// A hello (interval not 0) from `from`, which says it is `id`, instance
  /// `instance`, sending hellos every `interval`. O(log n).
  hello_result heard(const next_hop& from, module_id id, uint64_t instance,
                     std::chrono::milliseconds interval, time_point now);

  /// A goodbye from `from`: drops it if held with that `instance` (a
  /// goodbye of an earlier life changes nothing) and remembers that it
  /// left (departed). True if dropped. O(log n); O(n) when it forgets the
  /// oldest goodbye for the bound.
  bool goodbye(const next_hop& from, uint64_t instance);

  /// Whether `from` said goodbye as `instance` and has not said hello since:
  /// what it sent before its goodbye and arrives after it must not make it
  /// a neighbour again. Remembers the last `limits::total` goodbyes (the
  /// oldest is forgotten first). O(log n).
  bool departed(const next_hop& from, uint64_t instance) const;

  /// Drops every neighbour on channel `ch` (it ended). O(n on ch + log n).
  void remove_channel(channel_id ch);

  /// Drops the neighbours whose last hello is older than hello_loss times
  /// their interval (at least ours) at `now`; returns them in next_hop
  /// order, and appends what each was to `was` when given (parallel to the
  /// result: for reports of lost neighbours). O(n).
  std::vector<next_hop> expire(time_point now,
                               std::vector<neighbour>* was = nullptr);

  /// The earliest time at which expire() drops a neighbour, if one is held.
  /// O(n).
  std::optional<time_point> next_expiry() const;

  /// The neighbour at `at`, or nullptr. O(log n).
  const neighbour* find(const next_hop& at) const;

  /// Every neighbour, in next_hop order (channel, then link address).
  const std::map<next_hop, neighbour>& entries() const {
    return neighbours_;
  }

  size_t size() const {
    return neighbours_.size();
  }

  /// Hellos of new neighbours refused because a bound was reached.
  uint64_t refused() const {
    return refused_;
  }

private:
  void erase(std::map<next_hop, neighbour>::iterator i);

  /// How long `n` may stay silent before it is lost.
  duration silence_limit(const neighbour& n) const;

  limits limits_;
  std::map<next_hop, neighbour> neighbours_;
  /// Goodbyes heard (departed): next hop -> the instance that left, and
  /// when, in goodbyes (for the bound).
  struct departure {
    uint64_t instance = 0;
    uint64_t order = 0;
  };
  std::map<next_hop, departure> departed_;
  uint64_t next_departure_ = 0;
  /// Neighbours per channel (only channels with some).
  std::map<channel_id, size_t> on_channel_;
  uint64_t refused_ = 0;
};

} // namespace herm
