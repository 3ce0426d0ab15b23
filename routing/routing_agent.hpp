#pragma once

// Typed interface of the routing agent: one per module. It learns
// neighbours from hellos on every channel the IO manager opens, runs the
// route table (routing/route_table.hpp) and the address allocator, and
// forwards data packets hop by hop (re-fragmented by each outgoing channel).

#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "caf/fwd.hpp"
#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "routing/atoms.hpp"
#include "channels/io_manager.hpp"
#include "channels/messages.hpp"
#include "routing/auth.hpp"
#include "routing/fast_routes.hpp"
#include "routing/module_id.hpp"
#include "routing/route_table.hpp"
#include "routing/wire.hpp"

namespace herm {

/// A data packet for another module, or for every module when `dst` is
/// `broadcast_module`: then the packet is flooded (each module relays it
/// once on every channel but the one it came from, duplicates suppressed,
/// hop-limited) and delivered to every module's receiver of its protocol but
/// the sender's.
struct send_packet {
  module_id dst = no_module;
  uint8_t protocol = 0;
  uint8_t priority = prio_normal;
  byte_buffer payload;
  /// In a keyed network: sign the packet whatever `auth.data` says (remote
  /// control travels so; docs/user-guide.md, "auth"). No effect without a
  /// key.
  bool sign = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, send_packet& x) {
  return f(caf::meta::type_name("send_packet"), x.dst, x.protocol, x.priority,
           x.payload, x.sign);
}

/// The selected size-class-0 route to a destination changed: it appeared,
/// went away (withdrawn), or changed its cost, hop count, next hop or
/// forwarding path; sent to route listeners. Carries everything a log line
/// needs, so that nobody has to query the table to explain a change.
/// Coalesced: one event per destination per burst of updates (the agent's
/// flush), saying how the route differs from the previous event's.
struct reachability {
  module_id id = no_module;
  bool reachable = false;
  /// Of the selected route when reachable.
  uint8_t hops = 0;
  uint32_t cost = 0;
  /// What the previous event for `id` said (false and 0 for the first).
  bool was_reachable = false;
  uint32_t old_cost = 0;
  /// The selected route when reachable: the next hop's module id
  /// (no_module when its hello did not say), the channel and link address
  /// it is reached on, and the link kinds from here to `id`
  /// ("Ethernet-CAN2.0").
  module_id next = no_module;
  channel_id channel = 0;
  link_addr neighbour = 0;
  std::string path;
  /// The channel's device name ("eth0") and the next hop's link address in
  /// its link's notation ("127.0.0.1:47001", a CAN node id; the number when
  /// the channel never named it), when reachable.
  std::string device;
  std::string link_address;
  /// What the previous event said when `was_reachable`: its next hop's
  /// module id and the device it was reached on.
  module_id old_next = no_module;
  std::string old_device;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, reachability& x) {
  return f(caf::meta::type_name("reachability"), x.id, x.reachable, x.hops,
           x.cost, x.was_reachable, x.old_cost, x.next, x.channel, x.neighbour,
           x.path, x.device, x.link_address, x.old_next, x.old_device);
}

inline bool operator==(const reachability& a, const reachability& b) {
  return a.id == b.id && a.reachable == b.reachable && a.hops == b.hops
         && a.cost == b.cost && a.was_reachable == b.was_reachable
         && a.old_cost == b.old_cost && a.next == b.next
         && a.channel == b.channel && a.neighbour == b.neighbour
         && a.path == b.path && a.device == b.device
         && a.link_address == b.link_address && a.old_next == b.old_next
         && a.old_device == b.old_device;
}

/// A neighbour appeared or was lost: what routing_config::on_neighbour is
/// told. Not a message.
struct neighbour_event {
  /// True: its first hello (or the first of a new instance: it restarted);
  /// false: lost.
  bool up = false;
  module_id id = no_module;
  uint64_t instance = 0;
  channel_id channel = 0;
  /// The channel's device name, link kind ("Ethernet") and the neighbour's
  /// link address in the link's notation ("127.0.0.1:47001").
  std::string device;
  std::string link_kind;
  std::string link_address;
  /// Why: "hello", "restarted" (up); "goodbye", "hellos lost",
  /// "channel closed" (down).
  std::string reason;
};

/// One neighbour as the agent sees it.
struct neighbour_info {
  channel_id channel = 0;
  std::string link_address;
  module_id id = no_module;
  uint64_t instance = 0;
  std::string link_kind;
  /// Direct cost per size class.
  std::vector<uint32_t> cost;
  /// Milliseconds since the last hello.
  uint32_t last_heard_ms = 0;
  /// The neighbour says it holds this module's own id: a duplicate static
  /// id (see routing_stats::id_conflicts).
  bool duplicate_id = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, neighbour_info& x) {
  return f(caf::meta::type_name("neighbour_info"), x.channel, x.link_address,
           x.id, x.instance, x.link_kind, x.cost, x.last_heard_ms,
           x.duplicate_id);
}

/// One route row for people and scripts (the paper's five fields per class).
struct route_info {
  module_id destination = no_module;
  uint8_t size_class = 0;
  channel_id channel = 0;
  std::string neighbour;
  uint32_t cost = 0;
  uint8_t hops = 0;
  /// "CAN2.0-Ethernet": link kinds from here to the destination.
  std::string forwarding;
  bool selected = false;
  bool feasible = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, route_info& x) {
  return f(caf::meta::type_name("route_info"), x.destination, x.size_class,
           x.channel, x.neighbour, x.cost, x.hops, x.forwarding, x.selected,
           x.feasible);
}

/// The agent's identity and counters.
struct routing_stats {
  module_id self = no_module;
  uint64_t instance = 0;
  bool assigned = false;
  uint32_t renumberings = 0;
  /// Destinations with a selected route (size class 0).
  uint32_t reachable = 0;
  uint64_t delivered = 0;
  uint64_t forwarded = 0;
  uint64_t originated = 0;
  uint64_t dropped_no_route = 0;
  uint64_t dropped_hop_limit = 0;
  uint64_t dropped_no_receiver = 0;
  uint64_t broadcasts_originated = 0;
  uint64_t broadcasts_relayed = 0;
  uint64_t dropped_duplicate = 0;
  uint64_t rx_malformed = 0;
  /// Updates from a link address that is not a neighbour and could not
  /// become one: past a neighbour bound, or its sender said goodbye in that
  /// life (routing_agent.cpp, on_update).
  uint64_t rx_unknown_neighbour = 0;
  uint64_t rx_refused_routes = 0;
  /// Neighbours that said goodbye (and were dropped at once).
  uint64_t rx_goodbyes = 0;
  uint64_t tx_hellos = 0;
  uint64_t tx_updates = 0;
  uint64_t tx_update_entries = 0;
  uint64_t tx_claims = 0;
  uint64_t tx_conflicts = 0;
  uint64_t tx_seqno_requests = 0;
  /// Keyed networks (routing_config::auth): packets dropped for a missing,
  /// wrong or forged trailer (rx_auth_failed), a counter not above the
  /// sender's last (rx_replayed), a data packet that must be signed but is
  /// not (rx_unsigned), a new sender while the sender table is full of live
  /// ones (rx_auth_table_full); packets signed (tx_signed, one per channel).
  uint64_t rx_auth_failed = 0;
  uint64_t rx_replayed = 0;
  uint64_t rx_unsigned = 0;
  uint64_t rx_auth_table_full = 0;
  uint64_t tx_signed = 0;
  /// RFC 8967's challenge (docs/protocol.md, "Authentication"): packets with
  /// a right tag from a sender index not known (yet), dropped and answered
  /// with a challenge (rx_auth_challenged; every neighbour's first packets
  /// after either side started, and any recording of a sender gone);
  /// challenge replies that answered no live challenge (rx_challenge_failed:
  /// a stale or wrong nonce, too late); challenge requests sent
  /// (tx_challenges) and answered (tx_challenge_replies).
  uint64_t rx_auth_challenged = 0;
  uint64_t rx_challenge_failed = 0;
  uint64_t tx_challenges = 0;
  uint64_t tx_challenge_replies = 0;
  /// What the route table and the neighbour table hold now (gauges), each
  /// bounded by routing_config::limits.
  uint32_t destinations = 0;
  uint32_t routes = 0;
  uint32_t neighbours = 0;
  /// Refused because a bound was reached (routing_config::limits): new
  /// destinations or routes past any of the table's bounds
  /// (rx_routes_over_limit), of which past one neighbour's share
  /// (rx_routes_over_share), one per update entry; hellos of new
  /// neighbours past the total or a channel's share
  /// (rx_neighbours_over_limit); seqno requests not sent because
  /// routing_config::max_seqno_requests were sent within the last hello
  /// interval (seqno_requests_over_limit).
  uint64_t rx_routes_over_limit = 0;
  uint64_t rx_routes_over_share = 0;
  uint64_t rx_neighbours_over_limit = 0;
  uint64_t seqno_requests_over_limit = 0;
  /// Remembered ids forgotten early to stay within their bound: of the
  /// flood cache (routing_config::max_floods, soonest to expire first),
  /// flooded control packets (claims, conflicts, seqno requests;
  /// floods_evicted: a duplicate may then be relayed once more) and flooded
  /// broadcasts (flood_ids_evicted: likewise); feasibility distances of
  /// origins without a route, oldest first (sources_evicted).
  uint64_t floods_evicted = 0;
  uint64_t flood_ids_evicted = 0;
  uint64_t sources_evicted = 0;
  /// Static ids: disputes over this module's id (another instance heard
  /// holding it; one per other holder, again when it comes back after
  /// falling silent), and the other holder while it was heard within the
  /// last few hello intervals (0 and "" otherwise): its instance and where
  /// it was heard ("channel 1 (eth0) from 127.0.0.1:9000, hello").
  uint64_t id_conflicts = 0;
  uint64_t id_conflict_instance = 0;
  std::string id_conflict_heard;
  /// The data path of established routes (routing/fast_routes.hpp): data
  /// packets the module's senders put straight on a channel (counted in
  /// `originated` too), and destinations left out of the snapshot because
  /// it held route_cell::max_destinations() already (one per packet sent or
  /// forwarded to them through the agent).
  uint64_t fast_sent = 0;
  uint64_t fast_routes_refused = 0;
  /// Data packets for this module's receivers that went from the channel
  /// straight to them (fast_receiver; counted in `delivered` too).
  uint64_t fast_delivered = 0;
  /// Data packets for other modules that went from the channel straight to
  /// the next hop's channel (fast_receiver; counted in `forwarded` too).
  uint64_t fast_forwarded = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, routing_stats& x) {
  return f(caf::meta::type_name("routing_stats"), x.self, x.instance,
           x.assigned, x.renumberings, x.reachable, x.delivered, x.forwarded, x.originated,
           x.dropped_no_route, x.dropped_hop_limit, x.dropped_no_receiver,
           x.broadcasts_originated, x.broadcasts_relayed, x.dropped_duplicate,
           x.rx_malformed, x.rx_unknown_neighbour, x.rx_refused_routes, x.rx_goodbyes,
           x.tx_hellos, x.tx_updates, x.tx_update_entries, x.tx_claims,
           x.tx_conflicts, x.tx_seqno_requests, x.rx_auth_failed,
           x.rx_replayed, x.rx_unsigned, x.rx_auth_table_full, x.tx_signed,
           x.rx_auth_challenged, x.rx_challenge_failed, x.tx_challenges,
           x.tx_challenge_replies, x.destinations, x.routes, x.neighbours,
           x.rx_routes_over_limit, x.rx_routes_over_share,
           x.rx_neighbours_over_limit, x.seqno_requests_over_limit,
           x.floods_evicted, x.flood_ids_evicted, x.sources_evicted,
           x.id_conflicts, x.id_conflict_instance, x.id_conflict_heard,
           x.fast_sent, x.fast_routes_refused, x.fast_delivered,
           x.fast_forwarded);
}

/// Learns each change of a destination's selected route (reachability).
using route_listener_actor = caf::typed_actor<caf::reacts_to<reachability>>;

using routing_agent_actor = caf::typed_actor<
  /// Sends a data packet; one-way: failures are counted.
  caf::reacts_to<send_packet>,
  /// Sends a data packet; the reply says whether a route existed
  /// (routing_ec::no_route naming the destination otherwise).
  caf::replies_to<atom::send, send_packet>::with<void>,
  /// Registers the receiver of one protocol.
  caf::reacts_to<atom::subscribe, uint8_t, network_receiver_actor>,
  /// Registers a route listener: it gets one reachability message per
  /// destination reachable now (the current state, never a history), then
  /// one per change, coalesced per burst; it is forgotten when it exits.
  caf::reacts_to<atom::subscribe, atom::routes, route_listener_actor>,
  caf::replies_to<atom::get, atom::routes>::with<std::vector<route_info>>,
  caf::replies_to<atom::get, atom::neighbors>::with<std::vector<neighbour_info>>,
  caf::replies_to<atom::get, atom::stats>::with<routing_stats>,
  /// Leaves the network (a clean shutdown): sends a goodbye on every
  /// channel, so that neighbours drop this module's routes at once instead
  /// of after 1.5 silent hello intervals, and stops sending hellos. Replies
  /// once every channel has handed its goodbye to its driver.
  caf::replies_to<atom::close>::with<void>,
  // -- from the IO manager and the channels -----------------------------------
  caf::reacts_to<channel_up>, caf::reacts_to<channel_down>,
  caf::reacts_to<packet_received>, caf::reacts_to<link_event>,
  // -- timers -----------------------------------------------------------------
  /// The housekeeping tick; only the latest generation counts.
  caf::reacts_to<atom::tick, uint64_t>,
  /// Sends the triggered updates collected while processing a burst.
  caf::reacts_to<atom::flush>>;

/// One unicast data packet as a module handled it, for logs and traces
/// (hermd's debug log, the testbed's trace). Not a message: a plain value
/// handed to `routing_config::tracer`.
struct packet_trace {
  enum what_t : uint8_t { originated, forwarded, delivered };
  what_t what = originated;
  module_id self = no_module;
  module_id src = no_module;
  module_id dst = no_module;
  uint8_t protocol = 0;
  uint8_t size_class = 0;
  /// The whole network packet (header and payload), bytes.
  uint32_t bytes = 0;
  /// Link profile name and MTU of the channel it came on (forwarded,
  /// delivered) and leaves on (originated, forwarded).
  std::string in_link;
  uint32_t in_mtu = 0;
  std::string out_link;
  uint32_t out_mtu = 0;
  /// The next hop's module id (originated, forwarded).
  module_id next = no_module;
  /// The selected route's cost to dst in the packet's class, and its
  /// forwarding list ("Ethernet-CAN2.0"), when leaving.
  uint32_t cost = 0;
  std::string forwarding;
};

/// Another instance holds (or claims) this module's static id: what the
/// agent reports to routing_config::on_id_conflict. Not a message.
struct id_conflict {
  module_id id = no_module;
  /// The other holder's instance nonce.
  uint64_t other_instance = 0;
  /// Where it was heard: channel, link address and packet kind.
  std::string heard;
  /// True when this module is the newcomer and refuses to join: its agent
  /// says goodbye and ends with ec::already_exists.
  bool refused = false;
};

/// Timers and identity of one agent.
struct routing_config {
  /// Static id, or no_module for dynamic addressing.
  module_id id = no_module;
  /// Hello interval. A neighbour is lost when no hello arrived for
  /// `hello_loss` intervals (checked at the first quarter interval after
  /// that), or at once when its channel ends. The default 1.5 (the first missed hello plus half an
  /// interval of margin for jitter) moves traffic off a silently failed link
  /// within 1.75 intervals; raise it on lossy links, where one lost hello
  /// would otherwise drop a neighbour.
  std::chrono::milliseconds hello_interval{1000};
  double hello_loss = 1.5;
  /// Full (periodic) updates every this many hello intervals.
  uint32_t update_every = 4;
  /// Routes expire after this many update intervals without refresh.
  double hold_factor = 3.5;
  /// A module re-floods its claim (an announcement) every this many hello
  /// intervals, so that a holder of the same id in a partition that merged
  /// detects the conflict (a static module also announces once per hello
  /// interval during its start-up probation: address_allocator.hpp).
  uint32_t announce_every = 10;
  /// How long a flooded broadcast's id is remembered to suppress its
  /// duplicates (flooded control packets: claims, conflicts, seqno
  /// requests, are remembered for half a hello interval).
  std::chrono::milliseconds flood_memory{30000};
  /// The one bound of the flood cache (routing/flood_cache.hpp), which
  /// remembers flooded control packets and broadcasts alike: at most this
  /// many entries, the soonest to expire forgotten first when full (counted
  /// in routing_stats::floods_evicted or flood_ids_evicted by what was
  /// forgotten). Config: module.limits.floods.
  size_t max_floods = 8192;
  /// Bounds on the route table (see route_limits).
  route_limits limits;
  /// Neighbours at most, in total and per channel. A fake peer on a
  /// broadcast link can appear from any number of link addresses; a robot's
  /// bus or Ethernet segment has tens of modules. New neighbours past a
  /// bound are ignored (their hellos counted) until one is lost.
  size_t max_neighbours = 512;
  size_t max_neighbours_per_channel = 128;
  /// Seqno requests this module originates per hello interval at most.
  /// Each is flooded towards its origin, and a neighbour can make every
  /// destination it advertised starve at once (RFC 8966 3.8.2.1): the
  /// excess waits for a later interval (counted).
  size_t max_seqno_requests = 64;
  /// Instance nonce and seed for the address allocator; 0: random.
  uint64_t instance = 0;
  uint64_t seed = 0;
  /// Pre-shared key authentication (routing/auth.hpp); no key: none. With a
  /// key every control packet sent carries a trailer and every one received
  /// must carry a valid one; data packets as `auth.data` says. A neighbour's
  /// packets count only once it has answered a challenge (`auth.challenge`,
  /// on by default): the agent challenges unknown sender indexes on the
  /// link they came from, answers challenges (followed by its hello, so
  /// that the challenger has a neighbour one round trip after it asked).
  auth_config auth;
  /// Test hook: called for every data packet this module handles (delivered
  /// or forwarded), with the module's id; used by packet-path checkers.
  std::function<void(module_id self, const data_header&, const byte_buffer&)>
    observer;
  /// Called for every unicast data packet this module originates, forwards
  /// or delivers (see packet_trace); runs in the agent's thread, must not
  /// block. Costs nothing when empty.
  std::function<void(const packet_trace&)> tracer;
  /// Called (in the agent's thread, must not block) when a dispute over
  /// this module's static id starts: once per other holder, again when it
  /// comes back after falling silent. Empty: not reported (the counters in
  /// routing_stats still count).
  std::function<void(const id_conflict&)> on_id_conflict;
  /// Called (in the agent's thread, must not block) once per neighbour
  /// that appears (its first hello, or the first of a restarted instance)
  /// and once per neighbour lost (goodbye, hellos lost, channel closed):
  /// changes only, never per hello. Empty: not reported.
  std::function<void(const neighbour_event&)> on_neighbour;
  /// Where the agent publishes the next hops of established routes for the
  /// module's senders (routing/fast_routes.hpp); start_module shares one
  /// with the application support layer. Null: nothing is published.
  std::shared_ptr<route_cell> fast_routes;
};

/// Spawns the agent and subscribes it to `io`'s channels.
routing_agent_actor spawn_routing_agent(caf::actor_system& sys,
                                        io_manager_actor io,
                                        routing_config cfg);

} // namespace herm
