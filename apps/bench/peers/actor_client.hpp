#pragma once

// The client both actor transports share (herm through a proxy, caf through
// CAF's own remote actor): an event-based actor, written the way users write
// one, that sends `request(target, timeout, payload)` and sends the next
// request from the reply's `then` callback (or after the gap, from a
// delayed message to itself). Each round trip is timed from just before
// `request` to the start of the `then` callback, so it includes everything
// a user's code sees: the requester's mailbox and scheduling on both ends.

#include "caf/fwd.hpp"

#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

/// Runs `p.warmup + p.count` round trips against `target` and returns the
/// last `p.count`. With `retry_no_route`, a herm.no_route error before the
/// first reply is retried after 50 ms (the client's route to the server may
/// still be converging right after binding); that wait is never timed.
/// Blocks the calling thread.
client_result run_actor_client(caf::actor_system& sys, const caf::actor& target,
                               const endpoint_params& p, bool retry_no_route);

/// The echo actor both servers run: replies with the bytes it got.
caf::behavior echo_actor(caf::event_based_actor* self);

} // namespace herm::bench
