#pragma once

// The route table: Babel-style loop-free distance vector (RFC 8966) with one
// topology per packet-size class (routing/metric.hpp). Pure: no clock, no
// I/O; time is passed in. The routing agent actor feeds it hellos' results
// (neighbour metrics), updates and timers, and sends what it returns.

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <array>
#include <optional>
#include <vector>

#include "channels/messages.hpp"
#include "routing/metric.hpp"
#include "routing/module_id.hpp"

namespace herm {

/// Maximum hops a route may have; longer ones are refused.
constexpr uint8_t max_route_hops = 32;

/// Where a packet goes next: a channel and a neighbour on it (multi-access
/// links have many neighbours per channel).
struct next_hop {
  channel_id channel = 0;
  link_addr neighbour = 0;

  friend bool operator==(const next_hop& x, const next_hop& y) {
    return x.channel == y.channel && x.neighbour == y.neighbour;
  }
  friend bool operator<(const next_hop& x, const next_hop& y) {
    return x.channel != y.channel ? x.channel < y.channel
                                  : x.neighbour < y.neighbour;
  }
};

/// Babel sequence numbers: 16 bits compared modulo 2^16 (RFC 8966 3.2.1).
using seqno_t = uint16_t;

/// True if `a` is newer than `b` modulo 2^16.
bool seqno_newer(seqno_t a, seqno_t b);

/// A destination as advertised by one neighbour, in every class.
struct advertised {
  module_id origin = no_module;
  seqno_t seqno = 0;
  metric_vector metrics = infinite_metrics;
  std::array<uint8_t, size_classes> hops{};
  /// Link kinds along the path, from this neighbour to the origin, per class.
  std::array<std::vector<link_code>, size_classes> path;
};

/// One row of the table: the paper's five fields for one class.
struct route_row {
  module_id destination = no_module;
  uint8_t size_class = 0;
  next_hop via;
  metric cost = infinite_metric;
  uint8_t hops = 0;
  /// Link kinds from here to the destination (the paper's forwarding list).
  std::vector<link_code> path;
  seqno_t seqno = 0;
  bool selected = false;
  bool feasible = false;
};

/// What the agent must send after a change (triggered updates).
struct table_change {
  /// Destinations whose selected route changed in some class (or was
  /// retracted): advertise them to every neighbour now.
  std::vector<module_id> changed;
  /// Destinations for which no feasible route exists while an unfeasible one
  /// does: send a seqno request for them (RFC 8966 3.8.2.1).
  std::vector<module_id> starving;
};

class route_table {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;

  /// `self` is this module's id; routes to it are never installed.
  explicit route_table(module_id self);

  ~route_table();

  route_table(route_table&&) noexcept;

  route_table& operator=(route_table&&) noexcept;

  module_id self() const noexcept;

  /// Renumbers this module (dynamic addressing). Routes to the new id are
  /// dropped; the agent announces the old id's retraction itself.
  void set_self(module_id id);

  // -- neighbours ------------------------------------------------------------------

  /// Sets the cost of reaching neighbour `nh` directly (from its link
  /// profile), per class, and the link kind. A neighbour must be set before
  /// updates from it are accepted.
  table_change set_neighbour(next_hop nh, metric_vector cost, link_code kind);

  /// Removes a neighbour (lost hellos, channel down): its routes become
  /// unreachable at once.
  table_change remove_neighbour(next_hop nh);

  /// Removes every neighbour on `channel`.
  table_change remove_channel(channel_id channel);

  // -- updates ---------------------------------------------------------------------

  /// Applies one advertised destination heard from neighbour `from` at
  /// `now`; the route expires at now + `hold` unless refreshed. Absurd input
  /// (the origin is us, broadcast or none; a hop count above max_route_hops;
  /// a path longer than its hop count) is refused and returns false.
  bool update(next_hop from, const advertised& adv, time_point now,
              duration hold, table_change& out);

  /// Drops routes whose hold time ran out (and sources unused for long).
  table_change expire(time_point now);

  // -- what to advertise ---------------------------------------------------------------

  /// What this module advertises for `dest`: the selected routes' metrics
  /// per class (infinite where none), our own seqno for ourselves.
  std::optional<advertised> advertisement(module_id dest) const;

  /// Every destination we have any route to, plus ourselves.
  std::vector<module_id> destinations() const;

  /// Increments our own seqno.
  void bump_own_seqno();

  /// Raises our own seqno to `x` if `x` is newer (answering a seqno request
  /// for us, RFC 8966 3.8.1.2); otherwise leaves it.
  void set_own_seqno(seqno_t x);

  seqno_t own_seqno() const noexcept;

  // -- forwarding --------------------------------------------------------------------

  /// The selected next hop towards `dest` for a packet of class `k`.
  std::optional<next_hop> lookup(module_id dest, uint8_t k) const;

  /// Every route (one row per destination, neighbour and class), for
  /// hermctl and tests.
  std::vector<route_row> rows() const;

  /// Number of destinations with a selected route in class 0.
  size_t reachable() const;

private:
  struct impl;
  std::unique_ptr<impl> impl_;
};

} // namespace herm
