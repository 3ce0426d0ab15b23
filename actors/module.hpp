#pragma once

// Embedding HERM: one call starts a module (its three layers) inside a
// user's actor system, one call stops it. A module whose core actor ends
// while it runs is broken (no routing, or no applications): it says so
// through module_config::on_failure and through the down message of its
// supervisor (module_handles::supervisor), so that the program can exit or
// restart it instead of running on as a zombie.

#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "caf/expected.hpp"
#include "caf/fwd.hpp"

#include "actors/app_support.hpp"
#include "channels/io_manager.hpp"
#include "channels/messages.hpp"
#include "routing/routing_agent.hpp"

namespace herm {

/// A core actor of a module ended while the module was not being stopped.
struct module_failure {
  /// Which: "herm.io" (IO manager), "herm.routing" (routing agent),
  /// "herm.apps" (application support), or the name given to
  /// watch_module_actor ("herm.control" in hermd).
  std::string actor;
  /// Why: its exit reason (an uncaught exception is
  /// system.runtime_error with the exception's what(); a routing agent
  /// that refuses to join because its static id is taken ends with
  /// herm.already_exists; an actor that returned normally: system.normal).
  caf::error reason;
};

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
  /// Called at most once, in the supervisor's thread, when a core actor
  /// ends for any reason other than user_shutdown (the reason stop_module
  /// uses) before the module is stopped. Must not block: log, then tell
  /// your main thread (hermd raises SIGTERM at itself and exits 3).
  std::function<void(const module_failure&)> on_failure;
};

/// A running module: its IO manager, routing agent and application support
/// actor, and the supervisor watching them. Plain handles, copyable; they
/// do not stop the module (running_module does).
struct module_handles {
  io_manager_actor io;
  routing_agent_actor agent;
  app_support_actor apps;
  /// Monitors the core actors. When one fails (see on_failure) it exits
  /// with that actor's reason, its context prefixed with the actor's name
  /// ("herm.routing: std::bad_alloc"); stopped by stop_module, it exits
  /// with user_shutdown. Monitor it to learn of a failure as a down
  /// message.
  caf::actor supervisor;
};

/// Starts a module in `sys` and opens its channels. Blocks until every
/// device is added and every channel open, at most `timeout` per step. On
/// failure, stops what it started and returns the first error (naming the
/// device).
caf::expected<module_handles>
start_module(caf::actor_system& sys, const module_config& cfg,
             std::chrono::milliseconds timeout = std::chrono::seconds(5));

/// Stops a module's actors (the supervisor first, so that this counts as
/// no failure). Neighbours see its channels end. Does not wait.
void stop_module(const module_handles& m);

/// Has `m`'s supervisor watch `a` as one more core actor named `name`
/// (hermd adds its control service). Asynchronous; `a` ending with
/// user_shutdown is a clean stop, anything else a failure.
void watch_module_actor(const module_handles& m, caf::actor a,
                        std::string name);

/// Owns a started module: stops it when destroyed (a program that returns
/// from main without stop_module would otherwise wait for ever in the
/// actor system's destructor, which waits for every actor). Movable, not
/// copyable. Declare it after the actor_system it runs in, so that it is
/// destroyed first.
///
///   caf::actor_system sys{cfg};
///   auto m = herm::run_module(sys, mc);
///   if (!m) return 1;
///   ... (*m)->agent, or pass *m where a const module_handles& is taken
///   // returning stops the module, then the actor system ends
class running_module {
public:
  running_module() = default;

  /// Takes over `m`: destroying this stops it.
  explicit running_module(module_handles m) : m_(std::move(m)) {
    // nop
  }

  running_module(running_module&& other) noexcept;
  running_module& operator=(running_module&& other) noexcept;
  running_module(const running_module&) = delete;
  running_module& operator=(const running_module&) = delete;

  /// Stops the module (stop()).
  ~running_module();

  /// Stops the module and waits until its core actors have ended, at most
  /// `timeout`; afterwards this owns nothing. Idempotent.
  void stop(std::chrono::milliseconds timeout = std::chrono::seconds(5));

  /// Gives up ownership: the module runs on until stop_module.
  module_handles release();

  /// True while this owns a module.
  explicit operator bool() const noexcept {
    return static_cast<bool>(m_.io);
  }

  const module_handles& handles() const noexcept {
    return m_;
  }

  const module_handles& operator*() const noexcept {
    return m_;
  }

  const module_handles* operator->() const noexcept {
    return &m_;
  }

  operator const module_handles&() const noexcept {
    return m_;
  }

private:
  module_handles m_;
};

/// start_module, owned: the module stops when the result goes out of
/// scope.
caf::expected<running_module>
run_module(caf::actor_system& sys, const module_config& cfg,
           std::chrono::milliseconds timeout = std::chrono::seconds(5));

} // namespace herm
