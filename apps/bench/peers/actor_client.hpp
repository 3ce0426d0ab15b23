#pragma once

// The client both actor transports share (herm through a proxy, caf through
// CAF's own remote actor): an event-based actor, written the way users write
// one, that sends `request(target, timeout, payload)` and sends the next
// request from the reply's `then` callback (or after the gap, from a
// delayed message to itself). Each round trip is timed from just before
// `request` to the start of the `then` callback, so it includes everything
// a user's code sees: the requester's mailbox and scheduling on both ends.
// The oneway client and the counting receiver both actor transports share
// are below.

#include <future>
#include <memory>

#include "caf/event_based_actor.hpp"
#include "caf/fwd.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/app_support.hpp"
#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

/// Sets up `cfg` for a process of an actor transport: the scheduler named by
/// `policy` ("name[:threads]", see split_policy) and the bench's message
/// types. The caller loads any further modules (caf: the middleman).
void configure_actor_system(caf::actor_system_config& cfg, const std::string& policy);

/// State of count_actor.
struct count_state {
  static inline const char* name = "herm.bench.count";
  oneway_counter counter;
  caf::actor ack;
};

/// Runs `p.warmup + p.count` round trips against `target` and returns the
/// last `p.count`. With `retry_no_route`, a herm.no_route error before the
/// first reply is retried after 50 ms (the client's route to the server may
/// still be converging right after binding); that wait is never timed.
/// Blocks the calling thread.
client_result run_actor_client(caf::actor_system& sys, const caf::actor& target,
                               const endpoint_params& p, bool retry_no_route);

/// The echo actor both servers run: replies with the bytes it got.
caf::behavior echo_actor(caf::event_based_actor* self);

// -- oneway ---------------------------------------------------------------------------
// Both actor transports speak the same protocol: the client requests
// `std::string{"hello"}` (answered "ok" once the server knows where to send
// acknowledgements), sends every message one-way as a std::vector<uint8_t>
// (`self->send(target, bytes)`), gets acknowledgements as uint32_t (the
// highest sequence number seen + 1) and finally requests int32_t{0}, answered
// with (uint64_t received, int64_t elapsed_ns, double allocs_per_message).

/// Spawns the oneway client (it waits); the caller may register it (herm:
/// as the APO "rtt.ack") before `run_oneway_client` starts it.
caf::actor spawn_oneway_client(caf::actor_system& sys, const caf::actor& target,
                               const endpoint_params& p,
                               std::shared_ptr<std::promise<client_result>> done);

/// Starts a client spawned by `spawn_oneway_client` and waits for its
/// outcome. Blocks the calling thread.
client_result run_oneway_client(const caf::actor& client,
                                std::future<client_result> outcome);

/// The counting receiver. With `apps` (herm), acknowledgements go to the APO
/// named "rtt.ack", bound when the hello comes; without (caf), to the
/// hello's sender.
caf::behavior count_actor(caf::stateful_actor<count_state>* self,
                          endpoint_params p, app_support_actor apps);

} // namespace herm::bench
