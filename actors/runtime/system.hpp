#pragma once

#include <cstddef>
#include <string>

#include "caf/fwd.hpp"

namespace herm {

/// Prepares an actor system configuration for HERM: registers HERM's three
/// type-ID blocks (one per layer) and the "herm" error category, and
/// selects the scheduler.
///
/// `scheduler_policy` is "loop" (default: the loop scheduler of
/// actors/runtime/loop_scheduler.hpp, one thread that runs every actor and
/// the event loop of every driver, so a packet reaches its APO on the thread
/// the kernel woke), "sharing" (CAF's one shared queue) or "stealing" (CAF's
/// default, about 100 us per cross-thread wake-up here); see
/// docs/performance.md. `threads` is the number of worker threads of
/// "sharing" and "stealing" (0: one per core); the loop scheduler has one.
/// On any of them, spawn blocking work as detached actors. `busy_poll_us`:
/// the loop scheduler's bounded busy-poll (load_loop_scheduler), 0: off.
void configure(caf::actor_system_config& cfg,
               const std::string& scheduler_policy = "loop",
               size_t threads = 1, size_t busy_poll_us = 0);

/// Like `configure`, but for deterministic tests: CAF's test_coordinator
/// drives every actor, and time moves only when the test advances it.
void configure_for_testing(caf::actor_system_config& cfg);

} // namespace herm
