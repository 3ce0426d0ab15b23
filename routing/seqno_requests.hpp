#pragma once

// Seqno-request bookkeeping (RFC 8966 3.8.2.1): which destinations this
// module asked a new seqno for within the last hello interval. Pure: no
// clock, no I/O; time is passed in. The routing agent asks it before it
// floods a request for a starving destination.
//
// Bounded: a neighbour can make every destination it advertised starve at
// once, and each request is flooded towards its origin, so at most
// `limits::per_interval` destinations are remembered (requested within the
// last interval); a request for another one is held back (counted in
// over_limit()) until expire() makes room.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>

#include "routing/module_id.hpp"

namespace herm {

class seqno_requests {
public:
  using time_point = std::chrono::steady_clock::time_point;

  struct limits {
    /// routing_config::hello_interval: one request per destination per
    /// interval, and the window of the bound below.
    std::chrono::milliseconds interval{1000};
    /// routing_config::max_seqno_requests.
    size_t per_interval = 64;
  };

  /// What request() decided.
  enum class decision : uint8_t {
    /// Send the request now (recorded as sent at `now`).
    send,
    /// One was sent for this destination less than an interval ago.
    duplicate,
    /// A new destination while `per_interval` are remembered (counted).
    over_limit,
  };

  /// With the default limits.
  seqno_requests();
  explicit seqno_requests(limits lim);

  /// Whether to send a seqno request for `dst` at `now`. A destination
  /// still remembered but requested an interval ago or more is sent again
  /// without counting against the bound (it holds its place until
  /// expire()). `now` must not go backwards. O(log per_interval).
  decision request(module_id dst, time_point now);

  /// Forgets the destinations requested an interval ago or more: they no
  /// longer hold back new ones. O(remembered).
  void expire(time_point now);

  /// The earliest time at which expire() forgets a destination, if one is
  /// remembered. O(remembered).
  std::optional<time_point> next_expiry() const;

  /// Destinations remembered now.
  size_t size() const {
    return sent_.size();
  }

  /// Requests held back because `per_interval` destinations were
  /// remembered.
  uint64_t over_limit() const {
    return over_limit_;
  }

private:
  limits limits_;
  /// When a request for each destination was last sent.
  std::map<module_id, time_point> sent_;
  uint64_t over_limit_ = 0;
};

} // namespace herm
