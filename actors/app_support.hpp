#pragma once

// Typed interface of the Application Support Layer: one application support
// actor per module (section 3.3 of the HERM paper). It keeps the module's
// application table, answers and issues discovery queries, binds local
// actors to remote application objects (APOs) through proxies, watches
// remote APOs for proxies' monitors, and carries publish/subscribe topics.
//
// An APO is an ordinary CAF actor. Registering it makes it discoverable;
// binding to a remote one yields a proxy: a local `caf::actor` whose
// messages and requests are marshalled (actors/marshal.hpp), routed and
// delivered to the remote APO, and whose responses come back to the
// requester's `then` callback. Wire format: actors/asl_wire.hpp.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "caf/fwd.hpp"
#include "caf/timestamp.hpp"
#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "actors/asl_wire.hpp"
#include "actors/marshal.hpp"
#include "actors/runtime/atoms.hpp"
#include "routing/routing_agent.hpp"

namespace herm {

/// An APO as the network knows it: the module hosting it, its number there
/// (unique per module and never reused while the module runs; not
/// sequential, so that one number seen does not give away the others), its
/// name and its type (the interface it speaks).
struct apo_ref {
  module_id module = no_module;
  uint32_t apo = 0;
  std::string name;
  std::string type;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, apo_ref& x) {
  return f(caf::meta::type_name("apo_ref"), x.module, x.apo, x.name, x.type);
}

inline bool operator==(const apo_ref& a, const apo_ref& b) {
  return a.module == b.module && a.apo == b.apo && a.name == b.name
         && a.type == b.type;
}

inline bool operator<(const apo_ref& a, const apo_ref& b) {
  return a.module != b.module ? a.module < b.module : a.apo < b.apo;
}

/// A discovery: every APO whose name (or type) is `pattern`, collected for
/// `timeout_ms` (or until the first answer when `first`). Local matches are
/// included. The result is sorted by module and APO number; empty if nothing
/// answered in time.
struct apo_query {
  query_by by = query_by::name;
  std::string pattern;
  uint32_t timeout_ms = 500;
  bool first = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, apo_query& x) {
  return f(caf::meta::type_name("apo_query"), x.by, x.pattern, x.timeout_ms,
           x.first);
}

/// Binding by name or type: discover, then bind the first match (a local
/// match first). With `rebind`, the proxy outlives its target: when the APO
/// exits or its module becomes unreachable, requests fail at once with
/// app_ec::apo_gone until a new match appears (looked for every
/// `app_support_config::rebind_interval`), then go to it. Without `rebind`
/// the proxy ends with its target (monitors get a down message). Fails with
/// app_ec::not_found when nothing answered within `timeout_ms`.
///
/// With `reliable`, requests and one-way messages through the proxy travel
/// in reliable mode (docs/reliability.md, "Reliable requests"): the
/// receiving module acknowledges them end to end, this module retransmits
/// them with backoff until it hears back, and the receiving module delivers
/// each one to the APO exactly once (a retransmitted request is answered
/// from a cache of recent responses). A reliable binding rides out
/// unreachability: its requests wait and are retransmitted when the module
/// is back, and fail only at their deadline (`request_timeout`) with
/// routing_ec::no_route (the module stayed unreachable), app_ec::apo_gone (nothing bound
/// to a rebinding proxy) or ec::timeout (reachable, but no response).
struct bind_request {
  query_by by = query_by::name;
  std::string pattern;
  uint32_t timeout_ms = 500;
  bool rebind = false;
  bool reliable = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, bind_request& x) {
  return f(caf::meta::type_name("bind_request"), x.by, x.pattern,
           x.timeout_ms, x.rebind, x.reliable);
}

/// Who may use a local APO from other modules, and how a binding speaks to
/// its target.
///
/// `signed_only` (the control service, herm.control): a request from
/// another module reaches the APO only if it arrived signed and verified
/// (packet_delivered::authenticated, a keyed network, whatever its
/// `auth.data`), or if this module has no key and
/// app_support_config::allow_unsigned_remote is set. Anything else is
/// refused with app_ec::unauthorized and counted (rx_unauthorized). A binding
/// made `signed_only` asks the routing agent to sign its requests
/// (send_packet::sign), and the APO's responses are signed too.
enum class apo_access : uint8_t {
  open = 0,
  signed_only = 1,
};

/// One row of the application table, for hermctl and tests.
struct apo_info {
  apo_ref ref;
  bool local = false;
  /// Local APOs: modules watching it. Remote: milliseconds since last heard.
  uint32_t watchers = 0;
  uint32_t age_ms = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, apo_info& x) {
  return f(caf::meta::type_name("apo_info"), x.ref, x.local, x.watchers,
           x.age_ms);
}

/// One value of a topic as this module received (or published) it: what a
/// subscriber in sample mode receives (tools such as hermctl's echo and
/// record, and typed subscribers that want the publisher and the time).
struct topic_sample {
  std::string topic;
  /// The module that published it.
  module_id publisher = no_module;
  /// Its sequence number at the publisher (counts from 1).
  uint32_t seq = 0;
  /// When this module received it (or published it, when local).
  caf::timestamp time;
  /// The message, marshalled (docs/protocol.md, "APO payloads").
  byte_buffer payload;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, topic_sample& x) {
  return f(caf::meta::type_name("topic_sample"), x.topic, x.publisher, x.seq,
           x.time, x.payload);
}

/// A value already marshalled (docs/protocol.md, "APO payloads"): what
/// hermctl's topic pub and play publish, and what a proxy to a remote APO
/// sends as it is when it is the whole request; the response then comes
/// back as a raw_payload too, whatever its types, so that a process that
/// does not have the APO's types (hermctl call) can still call it. One
/// exception: when a rebinding proxy's target turns out to be local, the
/// request is unmarshalled for it and the APO answers with its own types
/// (a caller must take both).
struct raw_payload {
  byte_buffer bytes;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, raw_payload& x) {
  return f(caf::meta::type_name("raw_payload"), x.bytes);
}

/// One topic as one module sees it (hermctl topic list).
struct topic_info {
  std::string topic;
  /// This module publishes it; `seq`: its last sequence number.
  bool publishing = false;
  uint32_t seq = 0;
  /// Local actors subscribed (either kind).
  uint32_t local_subscribers = 0;
  /// Publisher side: modules holding a lease.
  std::vector<module_id> remote_subscribers;
  /// Subscriber side: modules heard publishing it.
  std::vector<module_id> publishers;
  /// The type of the first element of the last value seen ("" if none).
  std::string type;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, topic_info& x) {
  return f(caf::meta::type_name("topic_info"), x.topic, x.publishing, x.seq,
           x.local_subscribers, x.remote_subscribers, x.publishers, x.type);
}

/// Counters of one application support actor. Everything dropped is counted
/// under the reason it was dropped.
struct app_support_stats {
  module_id self = no_module;
  uint32_t local_apos = 0;
  uint32_t known_remote_apos = 0;
  uint32_t live_bindings = 0;
  uint32_t pending_requests = 0;
  uint64_t registered = 0;
  uint64_t withdrawn = 0;
  uint64_t queries_sent = 0;
  uint64_t queries_answered = 0;
  uint64_t answers_received = 0;
  uint64_t requests_sent = 0;
  uint64_t oneway_sent = 0;
  uint64_t requests_served = 0;
  uint64_t oneway_delivered = 0;
  uint64_t responses_received = 0;
  uint64_t request_timeouts = 0;
  uint64_t proxies_ended = 0;
  uint64_t published = 0;
  uint64_t publications_sent = 0;
  uint64_t publications_received = 0;
  uint64_t publications_delivered = 0;
  uint64_t publications_lost = 0;
  uint64_t rx_malformed = 0;
  uint64_t rx_unknown_apo = 0;
  uint64_t rx_unknown_type = 0;
  uint64_t rx_unexpected_response = 0;
  uint64_t tx_refused = 0;
  uint64_t dropped_no_route = 0;
  // -- refusals at the bounds of what the network can make this module hold --
  /// Requests for a `signed_only` APO (remote control) that did not arrive
  /// signed, or reached a module without a key that does not allow
  /// unsigned remote control: answered with app_ec::unauthorized.
  uint64_t rx_unauthorized = 0;
  /// Requests answered with ec::queue_full because max_pending requests of
  /// other modules were being served.
  uint64_t serving_refused = 0;
  /// Discovery answer entries not remembered: the table of remote APOs
  /// holds max_remote_apos (remote_apos_refused), or a discovery collected
  /// max_remote_apos matches already (discovery_entries_refused).
  uint64_t remote_apos_refused = 0;
  uint64_t discovery_entries_refused = 0;
  /// Watches of local APOs refused: max_watches held (the watcher learns
  /// of an exit only by its periodic renewal finding the APO gone).
  uint64_t watches_refused = 0;
  /// Per topic: remote subscribers refused (this module publishes it) and
  /// publishing modules not tracked (this module subscribes to it), above
  /// max_topic_peers.
  uint64_t subscribers_refused = 0;
  uint64_t publishers_refused = 0;
  /// Messages that actors of this process did not handle (APOs with
  /// herm::log_unexpected as their default handler, actors/unexpected.hpp):
  /// counted process-wide, logged at a bounded rate without their content.
  uint64_t unexpected_messages = 0;
  /// Watches of local APOs by other modules, now (at most max_watches).
  uint32_t watches = 0;
  // -- reliable mode ----------------------------------------------------------
  /// Requests and one-way messages sent in reliable mode (first copies).
  uint64_t reliable_sent = 0;
  /// Copies sent again because no response or ack came in time.
  uint64_t retransmissions = 0;
  /// Reliable requests that arrived again and were not delivered again
  /// (answered from the cache or acknowledged instead).
  uint64_t duplicates_suppressed = 0;
  /// Acks sent (one-way delivered, or a request still being served) and
  /// received.
  uint64_t acks_sent = 0;
  uint64_t acks_received = 0;
  /// Responses and acks for reliable requests nobody waits for any more
  /// (a late copy after the first one arrived): dropped.
  uint64_t late_duplicates = 0;
  /// Reliable requests that had to wait for a route to their module (or
  /// for a rebinding proxy's next target) before a copy could go out.
  uint64_t reliable_waited = 0;
  /// Entries now in the duplicate-suppression cache (at most
  /// app_support_config::reliable_cache).
  uint32_t cached_responses = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, app_support_stats& x) {
  return f(caf::meta::type_name("app_support_stats"), x.self, x.local_apos,
           x.known_remote_apos, x.live_bindings, x.pending_requests,
           x.registered, x.withdrawn, x.queries_sent, x.queries_answered,
           x.answers_received, x.requests_sent, x.oneway_sent,
           x.requests_served, x.oneway_delivered, x.responses_received,
           x.request_timeouts, x.proxies_ended, x.published,
           x.publications_sent, x.publications_received,
           x.publications_delivered, x.publications_lost, x.rx_malformed,
           x.rx_unknown_apo, x.rx_unknown_type, x.rx_unexpected_response,
           x.tx_refused, x.dropped_no_route, x.reliable_sent,
           x.retransmissions, x.duplicates_suppressed, x.acks_sent,
           x.acks_received, x.late_duplicates, x.reliable_waited,
           x.cached_responses, x.rx_unauthorized, x.serving_refused,
           x.remote_apos_refused, x.discovery_entries_refused,
           x.watches_refused, x.subscribers_refused, x.publishers_refused,
           x.unexpected_messages, x.watches);
}

using app_support_actor = caf::typed_actor<
  // -- application table --------------------------------------------------------
  /// Registers an APO under a name and a type; it stays registered until it
  /// exits or is unregistered, then its withdrawal is broadcast. Errors:
  /// ec::invalid_parameter (empty or over 255-byte name or type, invalid
  /// handle), ec::already_exists (that actor is registered already).
  caf::replies_to<atom::add, std::string, std::string, caf::actor>::with<apo_ref>,
  /// The same, with who may use it from other modules (apo_access).
  caf::replies_to<atom::add, std::string, std::string, caf::actor,
                  apo_access>::with<apo_ref>,
  caf::reacts_to<atom::unregister, caf::actor>,
  /// The application table: local APOs and the remote ones discovered.
  caf::replies_to<atom::get, atom::apps>::with<std::vector<apo_info>>,
  // -- discovery and binding ------------------------------------------------------
  caf::replies_to<atom::find, apo_query>::with<std::vector<apo_ref>>,
  /// A proxy for the APO `ref` names (the local actor itself if it is ours).
  /// Errors: app_ec::apo_gone (not registered there), routing_ec::no_route.
  caf::replies_to<atom::bind, apo_ref>::with<caf::actor>,
  /// The same, `true`: in reliable mode (see bind_request::reliable).
  caf::replies_to<atom::bind, apo_ref, bool>::with<caf::actor>,
  /// The same, speaking to a `signed_only` APO (apo_access): requests and
  /// their responses travel signed in a keyed network.
  caf::replies_to<atom::bind, apo_ref, apo_access>::with<caf::actor>,
  caf::replies_to<atom::bind, bind_request>::with<caf::actor>,
  // -- topics -------------------------------------------------------------------
  /// Publishes one value of a topic to every subscriber, local and remote.
  /// The last value is kept and given to subscribers that join later.
  caf::reacts_to<atom::publish, std::string, caf::message>,
  /// Subscribes `subscriber` (any actor) to a topic; it receives every value
  /// as the message that was published. Ends when it exits or unsubscribes.
  caf::replies_to<atom::subscribe, std::string, caf::actor>::with<void>,
  caf::reacts_to<atom::unsubscribe, std::string, caf::actor>,
  /// Subscribes `subscriber` in sample mode: it receives every value as a
  /// topic_sample (payload, publisher, sequence number, time), also values
  /// of types this process was not built with.
  caf::replies_to<atom::subscribe, std::string, caf::actor,
                  atom::sample>::with<void>,
  /// Publishes a value already marshalled (hermctl's topic pub and play).
  /// Local subscribers get it as a message when this process knows its
  /// types. Errors: ec::invalid_parameter (topic, not an APO payload),
  /// ec::packet_too_large (over max_message).
  caf::replies_to<atom::publish, std::string, raw_payload>::with<void>,
  /// The topics this module publishes or subscribes to.
  caf::replies_to<atom::get, atom::topics>::with<std::vector<topic_info>>,
  caf::replies_to<atom::get, atom::stats>::with<app_support_stats>,
  // -- internal: the network, proxies, the reply sink, timers ---------------------
  caf::reacts_to<packet_delivered>, caf::reacts_to<reachability>,
  /// From a proxy: its binding, the sender, the caf::message_id value and
  /// the message.
  caf::reacts_to<atom::forward, uint32_t, caf::strong_actor_ptr, uint64_t,
                 caf::message>,
  /// From the reply sink: the local request number and the response.
  caf::reacts_to<atom::reply, uint64_t, caf::message>,
  /// From a proxy's destructor: nobody holds binding `id` any longer.
  caf::reacts_to<atom::close, uint32_t>,
  /// A discovery's collection time is over.
  caf::reacts_to<atom::done, uint32_t>, caf::reacts_to<atom::tick, uint64_t>>;

/// Timers and bounds of one application support actor.
struct app_support_config {
  /// The routing agent's published next hops (routing/fast_routes.hpp),
  /// the same cell as routing_config::fast_routes: a unicast packet to a
  /// destination it holds goes straight to the channel. Null: every packet
  /// goes through the agent. start_module sets both.
  std::shared_ptr<route_cell> fast_routes;
  /// Housekeeping period: request deadlines, leases, rebinding.
  std::chrono::milliseconds tick{100};
  /// The housekeeping period while nothing needs `tick`'s granularity: no
  /// request waiting for its answer or its retransmission, none being
  /// served, no proxy looking for its target. Leases, watches and lost
  /// modules are handled on it (all far coarser). A reliable request, an
  /// ack or a response sent while idle brings the next tick forward to
  /// `tick` at once; a plain request does so only when the slow tick would
  /// come less than one `tick` before its deadline (otherwise the slow
  /// tick brings the fine one itself). Never below `tick`. On the loop
  /// scheduler it is a lax timer that may come up to half of it (at most
  /// 250 ms) late, riding on a wake something else makes
  /// (channels/lax_timer.hpp).
  std::chrono::milliseconds idle_tick{500};
  /// A request still unanswered after this fails with ec::timeout (the
  /// requester's own `request(..., timeout)` may end it sooner).
  std::chrono::milliseconds request_timeout{10000};
  /// A module unreachable for this long ends the proxies bound to it
  /// (routing_ec::no_route); shorter outages while routes converge are ridden out.
  std::chrono::milliseconds unreachable_grace{1000};
  /// How often a rebinding proxy without a target looks for one.
  std::chrono::milliseconds rebind_interval{1000};
  /// How often watches of remote APOs are renewed (a module that restarted
  /// answers that the APO is gone).
  std::chrono::milliseconds watch_refresh{5000};
  /// Subscriptions are leases, renewed at a third of this.
  std::chrono::milliseconds subscription_lease{3000};
  /// Remote APOs learned from answers are forgotten after this.
  std::chrono::milliseconds remote_entry_ttl{60000};
  /// Largest marshalled message; larger ones fail with ec::packet_too_large.
  size_t max_message = 60 * 1024;
  /// Most outstanding remote requests (then ec::queue_full) and the most
  /// this module serves at once for others (then ec::queue_full to them).
  size_t max_pending = 4096;
  /// Bounds on what arrives.
  unmarshal_limits limits;
  /// Most remote APOs remembered from discovery answers (refreshed entries
  /// always fit), and most matches one discovery collects.
  size_t max_remote_apos = 4096;
  /// Most watches of local APOs by other modules, over all APOs.
  size_t max_watches = 4096;
  /// Per topic: most remote subscribers (publisher side) and most
  /// publishing modules tracked (subscriber side).
  size_t max_topic_peers = 1024;
  /// A module WITHOUT a key: let requests from other modules reach its
  /// `signed_only` APOs (its control service: anyone who can send it a
  /// datagram can then administer it). Off by default; config key
  /// `control.allow_unsigned_remote`, which a keyed module refuses. In a
  /// keyed module (never set it there) remote control must arrive signed.
  bool allow_unsigned_remote = false;
  // -- reliable mode ------------------------------------------------------------
  /// First retransmission timeout to a module whose round trip has not been
  /// measured yet; then RTO = SRTT + 4 RTTVAR (RFC 6298, samples only from
  /// requests answered on their first copy), within [min, max]. Each further
  /// retransmission of one request doubles its timeout, up to the max.
  /// Retransmissions happen on the housekeeping tick, so `tick` is their
  /// granularity.
  std::chrono::milliseconds retransmit_initial{300};
  std::chrono::milliseconds retransmit_min{50};
  std::chrono::milliseconds retransmit_max{2000};
  /// Most copies of one reliable request (the first included); after that
  /// it waits for its deadline.
  uint32_t max_transmissions = 64;
  /// Duplicate suppression at the receiver: the most (sending module,
  /// request id) entries remembered with their response, and for how long
  /// (at least the senders' request_timeout, or a late copy could run
  /// twice). The oldest entry goes first when full.
  size_t reliable_cache = 2048;
  std::chrono::milliseconds reliable_cache_ttl{15000};
};

/// Spawns the module's application support actor on top of its routing
/// agent (it takes protocol `asl_protocol` and listens to routes).
app_support_actor spawn_app_support(caf::actor_system& sys,
                                    routing_agent_actor agent,
                                    app_support_config cfg = {});

} // namespace herm
