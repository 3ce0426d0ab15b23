#pragma once

// Internal to the routing agent (routing_agent.cpp, agent_auth.cpp,
// agent_reports.cpp): its state and what those files share. Nothing but
// them includes it; the agent's interface is routing/routing_agent.hpp.
// Everything here runs in the agent's thread only.

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "routing/address_allocator.hpp"
#include "routing/auth.hpp"
#include "routing/flood_cache.hpp"
#include "routing/neighbour_table.hpp"
#include "routing/route_table.hpp"
#include "routing/routing_agent.hpp"
#include "routing/seqno_requests.hpp"
#include "routing/type_ids.hpp"
#include "routing/wire.hpp"

namespace herm::agent_detail {

struct channel_state {
  channel_actor handle;
  channel_info info;
  metric_vector cost = infinite_metrics;
  link_code code = link_code::unknown;
};

/// The agent's state: the pure cores (route table, neighbour table, flood
/// cache, seqno requests, address allocator, authenticator) and what only
/// an actor has (handles, pending messages, counters).
struct agent_state {
  static inline const char* name = "herm.routing";

  routing_config cfg;
  io_manager_actor io;
  /// The pure cores; init() sizes them from cfg.
  route_table table{no_module};
  neighbour_table neighbours;
  /// Floods seen recently: control packets (claims, conflicts, seqno
  /// requests) and broadcasts, keyed by packet type; one bound.
  flood_cache floods{1};
  seqno_requests requested;
  std::unique_ptr<address_allocator> alloc;
  std::map<channel_id, channel_state> channels;
  std::map<uint8_t, network_receiver_actor> receivers;
  /// Triggered updates not sent yet (see apply_change).
  std::set<module_id> pending_changed;
  std::set<module_id> pending_starving;
  bool flush_scheduled = false;
  uint32_t next_flood_id = 1;
  /// Route listeners and what they were told last, per destination
  /// reachable (a subset of the table's destinations), and the
  /// destinations whose selected route may have changed since the last
  /// flush (a subset of the table's destinations too, and of the ones it
  /// dropped since): both bounded by the table's bound.
  std::vector<route_listener_actor> route_listeners;
  std::map<module_id, reachability> told;
  std::set<module_id> pending_told;
  routing_stats stats;
  uint16_t hello_seqno = 0;
  /// Hello intervals since start.
  uint32_t ticks = 0;
  /// The housekeeping tick (agent_tick.cpp): when the next hello is due,
  /// when the tick on its way is due, and its generation (only the latest
  /// counts). Hellos are due an interval after the last one was due, not
  /// after it went out, so ticks that fire late (lax) do not stretch the
  /// hello interval.
  caf::actor_clock::time_point next_hello{};
  caf::actor_clock::time_point next_tick{};
  uint64_t tick_generation = 0;
  /// Said goodbye: sends no more hellos.
  bool leaving = false;
  /// Where the other holder of our static id was last reported heard.
  std::string conflict_heard;
  byte_buffer buf;
  /// Signs and verifies packets when the network has a key.
  std::unique_ptr<authenticator> auth;
  /// Destinations this module originated unicast packets to, and others it
  /// forwarded unicast packets to, whose next hops it publishes in
  /// cfg.fast_routes (routing/fast_routes.hpp); each bounded by
  /// route_cell::max_destinations(), disjoint. A destination leaves when
  /// the table forgets it.
  std::set<module_id> fast_dests;
  std::set<module_id> fast_transit;
  /// Link addresses in their link's notation ("127.0.0.1:47001"), as the
  /// channels named them when they first heard a peer (link_event
  /// peer_heard): what neighbours, routes and logs show instead of the
  /// packed number. Forgotten with the channel; bounded by
  /// max_peer_names (further peers show as numbers).
  std::map<next_hop, std::string> peer_names;
  size_t max_peer_names() const {
    return 2 * cfg.max_neighbours;
  }

  /// How long a route learned from a neighbour that says hellos every
  /// `neighbour_interval` holds without a refresh: that neighbour's update
  /// period (its hello interval, at least ours, times update_every) times
  /// hold_factor. A neighbour with slower hellos than ours refreshes its
  /// routes less often; held for our own period only, its routes would
  /// expire between two of its updates (Babel holds a route 3.5 times the
  /// interval its sender announced, RFC 8966 3.5.3). The neighbour's
  /// interval counts up to max_interval_factor times ours: a neighbour
  /// saying a huge one (16 bits: 65.5 s) must not keep routes it stopped
  /// advertising, and the route table's feasibility sources, for minutes.
  static constexpr int max_interval_factor = 16;
  std::chrono::steady_clock::duration
  hold(std::chrono::milliseconds neighbour_interval = {}) const {
    auto interval = std::clamp(neighbour_interval, cfg.hello_interval,
                               cfg.hello_interval * max_interval_factor);
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      interval * cfg.update_every * cfg.hold_factor);
  }
};

using agent_impl = routing_agent_actor::stateful_pointer<agent_state>;

// -- helpers (header-only) ------------------------------------------------------

/// `x` encoded into the agent's scratch buffer (valid until the next use).
template <class T>
inline const byte_buffer& encoded(agent_impl self, const T& x) {
  auto& buf = self->state.buf;
  buf.clear();
  encode(x, buf);
  return buf;
}

/// True if `x` decoded; counts a malformed packet otherwise.
template <class T>
inline bool decoded(agent_impl self, const caf::expected<T>& x) {
  if (!x)
    ++self->state.stats.rx_malformed;
  return static_cast<bool>(x);
}

/// The link address of `nh` in its link's notation, or its number when the
/// channel never named it. O(log n).
inline std::string link_address_text(agent_impl self, const next_hop& nh) {
  auto& names = self->state.peer_names;
  auto i = names.find(nh);
  return i != names.end() ? i->second : std::to_string(nh.neighbour);
}

/// Tells cfg.on_neighbour that the neighbour at `nh` (module `id`,
/// `instance`) came up or was lost, and why. No-op without a callback.
/// routing_agent.cpp.
void report_neighbour(agent_impl self, const next_hop& nh, module_id id,
                      uint64_t instance, bool up, const char* reason);

/// Publishes the next hops of `fast_dests` and `fast_transit` in
/// cfg.fast_routes (dropping those the table forgot), or
/// withdraws the snapshot while the fast path is not allowed (no address,
/// a key, a tracer or observer, leaving). No-op without a cell.
/// O(|fast_dests| log N). agent_fast_routes.cpp.
void publish_fast_routes(agent_impl self);

/// Adds `dst`, just sent to through the agent, to `fast_dests` (or, when
/// `forwarded`, to `fast_transit`) and publishes; past cfg.fast_routes'
/// bound it counts `fast_routes_refused` instead. O(|fast_dests| log N).
/// agent_fast_routes.cpp.
void note_fast_destination(agent_impl self, module_id dst,
                           bool forwarded = false);

// -- sending (routing_agent.cpp) ------------------------------------------------

/// `bytes` as they leave on channel `cs`: with a trailer for that link when
/// `sign` (a keyed network), else unchanged. Data packets get their
/// authenticated flag set first.
byte_buffer outgoing(agent_impl self, const channel_state& cs,
                     const byte_buffer& bytes, bool sign);

/// Sends a control packet to `dst` on channel `ch` (signed whenever the
/// network has a key); nothing if the channel is gone.
void send_on(agent_impl self, channel_id ch, link_addr dst,
             const byte_buffer& bytes, uint8_t prio = prio_control);

/// Broadcasts `bytes` on every channel but `except` (signed per link in a
/// keyed network: every hop signs with its own counter).
void send_all(agent_impl self, const byte_buffer& bytes, channel_id except = 0,
              uint8_t prio = prio_control);

/// This module's next hello, encoded into the scratch buffer; a goodbye
/// (interval 0) when `leaving`.
const byte_buffer& make_hello(agent_impl self, bool leaving);

/// Hellos on every channel; a goodbye (interval 0) when `leaving`.
void send_hellos(agent_impl self, bool leaving = false);

/// Advertises `dests` on every channel (or only `only` when not 0).
void send_update(agent_impl self, const std::vector<module_id>& dests,
                 channel_id only = 0);

// -- route changes and addressing (routing_agent.cpp) ----------------------------

/// Collects what changed; a flush message queued behind the messages being
/// processed sends one triggered update for the whole burst (a cold start
/// or a failure changes many destinations through many updates at once),
/// and one route event per destination changed. O(|change| log N).
void apply_change(agent_impl self, const table_change& change);

/// Carries out what the address allocator decided: a dispute over our id,
/// the claims and conflicts to send, an id newly ours (advertised at once);
/// `where` says where the packet that led to it was heard, for the log.
void act(agent_impl self, address_allocator::actions acts,
         const std::string& where = "");

// -- the housekeeping tick (agent_tick.cpp) --------------------------------------

/// Liveness, expiry and addressing; at a hello also hellos, periodic
/// updates and announcements; then sends itself the next tick.
void tick(agent_impl self);

// -- authentication (agent_auth.cpp) --------------------------------------------

/// In a keyed network: checks the trailer of a received packet of `type`
/// and strips it. False (and counted) when the packet must be dropped.
/// Challenge requests and replies are handled here, and never go further.
bool authenticate(agent_impl self, packet_received& pkt, packet_type type);

// -- reports (agent_reports.cpp) ------------------------------------------------

/// Tells route listeners what changed for `dests` since they were told:
/// one event per destination whose selected class-0 route differs in any
/// way (appeared, withdrawn, other cost, hops, next hop or path).
/// O(|dests| log N).
void tell_route_changes(agent_impl self, const std::vector<module_id>& dests);

/// Registers a route listener and tells it the current state.
void subscribe_routes(agent_impl self, route_listener_actor& l);

/// A unicast data packet's trace with its incoming half filled in (`in`:
/// the channel it came on, 0 for none).
packet_trace make_trace(agent_impl self, packet_trace::what_t what,
                        const data_header& h, size_t bytes,
                        channel_id in = 0);

/// Fills the outgoing half of a trace and hands it to the tracer.
void trace_out(agent_impl self, packet_trace& t, const data_header& h,
               const next_hop& nh);

/// What `get routes`, `get neighbors` and `get stats` answer.
std::vector<route_info> route_rows(agent_impl self);
std::vector<neighbour_info> neighbour_rows(agent_impl self);
routing_stats stats_now(agent_impl self);

} // namespace herm::agent_detail
