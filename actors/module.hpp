#pragma once

// Embedding HERM: one call starts a module (its three layers) inside a
// user's actor system, one call stops it.

#include <chrono>
#include <string>
#include <vector>

#include "caf/expected.hpp"
#include "caf/fwd.hpp"

#include "actors/app_support.hpp"
#include "channels/io_manager.hpp"
#include "channels/messages.hpp"
#include "routing/routing_agent.hpp"

namespace herm {

/// What a module runs.
struct module_config {
  /// Identity (a static id, or no_module for dynamic addressing) and the
  /// routing timers.
  routing_config routing;
  /// The application support layer's timers and bounds.
  app_support_config apps;
  /// The interfaces; each gets one persistent channel to every peer ("*").
  std::vector<device_config> devices;
  /// Optional, parallel to `devices`: where each was configured
  /// ("robot.yaml:12"); prefixed to its start-up errors.
  std::vector<std::string> device_origins;
};

/// A running module: its IO manager, routing agent and application support
/// actor.
struct module_handles {
  io_manager_actor io;
  routing_agent_actor agent;
  app_support_actor apps;
};

/// Starts a module in `sys` and opens its channels. Blocks until every
/// device is added and every channel open, at most `timeout` per step. On
/// failure, stops what it started and returns the first error (naming the
/// device).
caf::expected<module_handles>
start_module(caf::actor_system& sys, const module_config& cfg,
             std::chrono::milliseconds timeout = std::chrono::seconds(5));

/// Stops a module's actors. Neighbours see its channels end.
void stop_module(const module_handles& m);

} // namespace herm
