#pragma once

#include <cstddef>
#include <string>

#include "caf/fwd.hpp"

namespace herm {

/// Prepares an actor system configuration for HERM: registers HERM's three
/// type-ID blocks (one per layer) and the "herm" error category, and
/// selects the scheduler.
///
/// `scheduler_policy` is "sharing" (default: one shared queue, about 12 us
/// per cross-thread wake-up on small machines) or "stealing" (CAF's default,
/// about 100 us here); see docs/performance.md. `threads` is the number of
/// worker threads; 0 means CAF's default, one per core. One worker is the
/// default: every hand-off between HERM's actors then stays on one thread
/// instead of waking another (a request round trip over udp takes about
/// half the time it takes with one worker per core; docs/performance.md).
/// Spawn long computations as detached actors, or give the module more
/// workers.
void configure(caf::actor_system_config& cfg,
               const std::string& scheduler_policy = "sharing",
               size_t threads = 1);

/// Like `configure`, but for deterministic tests: CAF's test_coordinator
/// drives every actor, and time moves only when the test advances it.
void configure_for_testing(caf::actor_system_config& cfg);

} // namespace herm
