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

/// Bounds on what neighbours can make the table hold. Neighbours decide how
/// many destinations they advertise, so without bounds one hostile or broken
/// neighbour decides how much memory a module uses.
struct route_limits {
  /// Destinations in the table (reachable, or retracted and still advertised
  /// as such). Robot networks have tens to hundreds of modules: 4096 leaves
  /// room for a fleet while a full table stays around a megabyte.
  size_t destinations = 4096;
  /// Routes learned from one neighbour. A quarter of `destinations`: a
  /// neighbour that floods the table takes at most a quarter of it, and the
  /// rest stays for the others; a leaf module behind a single neighbour
  /// still reaches 1024 modules (some 50 robots of 20 modules each). Raise
  /// both for larger networks.
  size_t per_neighbour = 1024;
  /// Routes in total (a destination has one per neighbour advertising it):
  /// four per destination on average.
  size_t routes = 16384;
};

/// What update() did with an advertised destination.
enum class update_result : uint8_t {
  /// Installed, refreshed or retracted (or a retraction of nothing).
  accepted,
  /// Absurd: the origin is us, broadcast or none; a hop count above
  /// max_route_hops; a path longer than its hop count.
  malformed,
  /// Not from a neighbour set with set_neighbour().
  unknown_neighbour,
  /// A new destination while the table holds `route_limits::destinations`,
  /// or a new route while it holds `route_limits::routes`.
  over_limit,
  /// A new route from a neighbour that has `route_limits::per_neighbour`.
  over_share,
};

class route_table {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;

  /// `self` is this module's id; routes to it are never installed.
  explicit route_table(module_id self, route_limits limits = {});

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
  /// `now`; the route expires at now + `hold` unless refreshed. Says why
  /// when it refuses (see update_result). Past a limit, routes already held
  /// keep being refreshed and served and retractions are always applied;
  /// only new routes are refused. O(log N).
  update_result update(next_hop from, const advertised& adv, time_point now,
                       duration hold, table_change& out);

  /// Drops routes whose hold time ran out (and sources unused for long).
  table_change expire(time_point now);

  /// The earliest time at which expire() drops a route, a tombstone or an
  /// idle source, if any is held. O(1).
  std::optional<time_point> next_expiry() const;

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

  // -- bounds --------------------------------------------------------------------------

  const route_limits& limits() const noexcept;

  /// Destinations held (reachable or retracted), bounded by
  /// `limits().destinations`.
  size_t size() const;

  /// Routes held, bounded by `limits().routes`.
  size_t routes() const;

  /// Routes held from neighbour `nh`, bounded by `limits().per_neighbour`.
  size_t routes_from(next_hop nh) const;

  /// Feasibility distances of origins without routes are kept a while
  /// (loop avoidance) but at most `limits().destinations` of them; this
  /// counts those forgotten early, oldest first, to stay within that.
  uint64_t sources_evicted() const;

private:
  struct impl;
  std::unique_ptr<impl> impl_;
};

} // namespace herm
