#pragma once

// Internal to the Application Support Layer's actor (app_support.cpp,
// asl_topics.cpp): its state and what those files share. Nothing but them
// includes it; the layer's interface is actors/app_support.hpp. Everything
// here runs in the actor's thread only.

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "caf/actor_clock.hpp"
#include "caf/make_message.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/apo_proxy.hpp"
#include "actors/apo_registry.hpp"
#include "actors/app_support.hpp"
#include "actors/asl_outbox.hpp"
#include "actors/binding_table.hpp"
#include "actors/discovery_table.hpp"
#include "actors/outgoing_requests.hpp"
#include "actors/reach_table.hpp"
#include "actors/reliable_requests.hpp"
#include "actors/request_server.hpp"
#include "actors/topic_table.hpp"
#include "routing/error.hpp"

namespace herm::asl_detail {

using time_point = std::chrono::steady_clock::time_point;

struct asl_state {
  static inline const char* name = "herm.asl";

  ~asl_state() {
    // Proxies end with the layer; requests still waiting fail.
    auto reason = make_error(routing_ec::no_route, "the application support "
                                                   "layer of this module "
                                                   "stopped");
    for (auto& p : bindings.take_proxies())
      detail::kill_apo_proxy(p, reason, nullptr);
    for (auto& req : pending ? pending->take_all() : std::vector<outgoing>{})
      if (req.sender)
        req.sender->enqueue(nullptr, req.mid.response_id(),
                            caf::make_message(reason), nullptr);
  }

  app_support_config cfg;
  routing_agent_actor agent;
  module_id self_id = no_module;
  /// Counters; the cores count into it too (so it outlives them).
  app_support_stats stats;
  /// The cores; later ones hold references to earlier ones.
  std::unique_ptr<apo_registry> apos;
  /// Reliable mode: round trips, copy schedules, the duplicate cache.
  std::unique_ptr<reliable_requests> reliable;
  binding_table bindings;
  std::unique_ptr<outgoing_requests> pending;
  std::unique_ptr<request_server> server;
  std::unique_ptr<discovery_table> discoveries;
  /// Why the routing agent stopped (then nothing can be sent: requests
  /// fail at once with app_ec::unavailable).
  caf::error agent_down;
  std::unique_ptr<topic_table> topics;
  /// What the cores decided to send, transmitted by flush.
  asl_outbox out;
  /// What flush is sending (the outbox's previous items).
  decltype(asl_outbox::items) flushing;
  reach_table reach;
  caf::strong_actor_ptr sink;
  /// The housekeeping tick: only the tick of the latest generation counts
  /// (an earlier one, superseded when a request brought the tick forward,
  /// is ignored), whether it runs at cfg.tick (else cfg.idle_tick), and
  /// the latest time the current one comes (it is a lax timer).
  uint64_t tick_generation = 0;
  bool tick_fast = true;
  caf::actor_clock::time_point tick_at;
  /// When the module's own id was last asked of the routing agent.
  std::optional<caf::actor_clock::time_point> self_id_asked;
  byte_buffer buf;
};

using asl_impl = app_support_actor::stateful_pointer<asl_state>;

// -- shared by the layer's files (app_support.cpp) ---------------------------------

/// Transmits what the cores put in the outbox, in order.
void flush(asl_impl self);

/// Delivers `msg` to `dst` as if `from` sent it with message id `mid`.
void post(asl_impl self, const caf::strong_actor_ptr& dst,
          caf::strong_actor_ptr from, caf::message_id mid, caf::message msg);

/// None if `bytes` (a raw_payload's, marshalled elsewhere) can be an APO
/// payload of this format, else why not (ec::invalid_parameter).
inline caf::error check_raw(const byte_buffer& bytes) {
  if (bytes.empty() || bytes[0] != apo_format_version)
    return make_error(ec::invalid_parameter, "not an APO payload of version 1");
  return caf::none;
}

/// `payload` unmarshalled, or the error after counting it (rx_unknown_type
/// or rx_malformed).
caf::expected<caf::message> unmarshal_counted(asl_impl self,
                                              const byte_buffer& payload);

/// Answers waiting request `out` with `err` (and `out` is done).
void fail(asl_impl self, const outgoing& out, const caf::error& err);

/// app_ec::unavailable once the routing agent stopped, else none.
caf::error agent_gone(asl_impl self);

// -- bindings and discovery (asl_bindings.cpp) -------------------------------------

/// Fails every request waiting on binding `id` (or, with id 0, on module
/// `dst`); with `keep_reliable`, reliable requests keep waiting.
void fail_pending(asl_impl self, uint32_t id, module_id dst,
                  const caf::error& err, bool keep_reliable = false);

/// The target of binding `id` is gone for `reason` (the remote exit reason,
/// or why it is unreachable). A rebinding proxy waits for a new target; any
/// other ends, and its monitors learn `reason`. Its waiting requests fail
/// with `request_error` (a rebinding proxy's reliable ones wait).
void lose_target(asl_impl self, uint32_t id, const caf::error& reason,
                 const caf::error& request_error);

/// A new proxy bound to `ref` (rebinding as `req` says, if given).
caf::actor make_binding(asl_impl self, const apo_ref& ref, bool reliable,
                        bool sign, const bind_request* req = nullptr);

/// Ends discovery `qid`: its callback gets what was found.
void finish_discovery(asl_impl self, uint32_t qid);

/// Why a discovery of `pattern` cannot start (the routing agent stopped,
/// a bad pattern); none if it can.
caf::error cannot_discover(asl_impl self, query_by by,
                           const std::string& pattern);

/// Starts discovery `q`: the query goes out, and `finish` gets the APOs
/// found when enough answered or at its timeout (at once when the local
/// table already satisfies it).
void discover(asl_impl self, apo_query q, discovery_table::callback finish);

// -- topics (asl_topics.cpp) -------------------------------------------------------

/// Gives a value of topic `t` (named `name`, from `publisher`, its `seq`)
/// to its local subscribers: `msg` to those that take messages (when this
/// process could decode it, else nullptr), a topic_sample with `payload`
/// to those in sample mode. O(subscribers).
void deliver_topic(asl_impl self, const std::string& name,
                   const topic_table::topic& t, module_id publisher,
                   uint32_t seq, const caf::message* msg,
                   const byte_buffer& payload);

/// A local APO publishes `msg` on `topic`: marshalled once, sent to the
/// remote subscribers and given to the local ones. A bad topic name, a
/// value that does not marshal or one above max_message is counted
/// (tx_refused) and dropped.
void on_publish_local(asl_impl self, const std::string& topic,
                      caf::message& msg);

/// A value marshalled elsewhere (hermctl) published as it is: decoded only
/// for local subscribers that take messages. Errors: the topic's name, not
/// an APO payload of version 1, or above max_message (packet_too_large).
caf::error on_publish_raw(asl_impl self, const std::string& topic,
                          byte_buffer& payload);

} // namespace herm::asl_detail
