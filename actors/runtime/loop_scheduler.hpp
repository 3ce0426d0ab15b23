#pragma once

// The loop scheduler: a CAF 0.17 scheduler whose one thread runs every actor
// of the system and the module's event loop (channels/event_loop.hpp). Its
// idle wait is the loop's epoll_pwait2 over every driver's descriptor; the
// actor clock (timeouts, delayed messages) is a pair of timer heaps on that
// thread, so setting or cancelling a request timeout wakes no thread (nor
// allocates, once the heaps have grown); another thread that enqueues
// work writes the loop's eventfd only while the loop sleeps.
// A request timeout fires up to 20 ms late, on a wake the loop makes for
// something else if one comes: CAF 0.17 leaves the timeout of an answered
// request in the clock, and each would otherwise wake the loop for nothing.
// Application support drops the timeouts of the requests it answers
// (request_answered), so that those neither fire nor allocate.
//
// A packet is therefore read, handed to its channel, routed and delivered to
// its APO on the thread the kernel woke (docs/architecture.md, "Threads").
// An actor that must block (file IO, a long computation) is spawned
// detached (caf::detached: a thread of its own) so that it does not stall the
// loop (docs/user-guide.md, "Blocking work").

#include <cstddef>
#include <cstdint>

#include "caf/fwd.hpp"

namespace herm {

/// Makes systems built from `cfg` use the loop scheduler (CAF's documented
/// way: actor_system_config::load of a scheduler module). The loop thread is
/// named "herm-loop". `scheduler.max-throughput` bounds the messages an
/// actor handles per turn (default here: 64, so that a busy actor cannot
/// keep the loop from its descriptors).
///
/// `busy_poll_us` > 0: before the loop sleeps it polls its descriptors and
/// queue for up to that many microseconds (bounded by the next timer), so
/// that a packet arriving soon after the last finds the thread awake instead
/// of waking a halted vCPU; it burns that much CPU after every burst of
/// work. At most one spinning loop per core in a process; off (0) by
/// default. docs/performance.md measures its effect.
void load_loop_scheduler(caf::actor_system_config& cfg,
                         size_t busy_poll_us = 0);

/// What the loop scheduler of `sys` did so far; all zero when `sys` runs on
/// another scheduler. For tests and benchmarks.
struct loop_stats {
  uint64_t resumes = 0;        // actor turns run
  uint64_t foreign_enqueues = 0; // actors made ready by another thread
  uint64_t sleeps = 0;         // waits in epoll that blocked
  uint64_t wakes = 0;          // eventfd writes to end such a wait
  uint64_t busy_polls = 0;     // polls made while busy-polling
  uint64_t request_timeouts = 0; // request timeouts in the clock now
};
loop_stats loop_stats_of(caf::actor_system& sys);

/// `requester` got the response with `response_id` (its request's id's
/// response_id()): on the loop scheduler, the request's timeout is dropped
/// (CAF 0.17 would let it fire for nothing: an allocation or two and maybe
/// a wake-up, each time). Elsewhere nothing happens. Thread-safe.
void request_answered(caf::actor_system& sys, caf::abstract_actor* requester,
                      caf::message_id response_id);

} // namespace herm
