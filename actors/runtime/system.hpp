#pragma once

#include <string>

#include "caf/fwd.hpp"

namespace herm {

/// Prepares an actor system configuration for HERM: registers the project's
/// type-ID block and the "herm" error category, and selects the scheduler.
///
/// `scheduler_policy` is "sharing" (default: one shared queue, about 12 us
/// per cross-thread wake-up on small machines) or "stealing" (CAF's default,
/// about 100 us here); see docs/performance.md.
void configure(caf::actor_system_config& cfg,
               const std::string& scheduler_policy = "sharing");

/// Like `configure`, but for deterministic tests: CAF's test_coordinator
/// drives every actor, and time moves only when the test advances it.
void configure_for_testing(caf::actor_system_config& cfg);

} // namespace herm
