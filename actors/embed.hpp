#pragma once

// Embedding HERM without boilerplate (include <herm/herm.hpp>): a module
// with its control service in one call, binding that waits for the APO to
// be discovered, typed topics, and CAF's errors turned into HERM's.
//
//   caf::actor_system sys{cfg};
//   auto m = herm::serve_module(sys, mc, "arm");   // hermctl sees "arm"
//   if (!m) return 1;
//   auto calc = herm::bind_within(sys, (*m)->apps, "calculator", 10s);
//   herm::subscribe<calc_result>(sys, (*m)->apps, "calculator.results",
//     [](const herm::topic_message<calc_result>& x) { ... });

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <utility>

#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/expected.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"

#include "actors/app_support.hpp"
#include "actors/control.hpp"
#include "actors/marshal.hpp"
#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm {

// -- a module with its control service ---------------------------------------------

/// A running module and its control service on a local socket, so that
/// hermctl (and other modules, through it) see a program that embeds HERM
/// as they see hermd. Stops both when destroyed (the socket first).
/// Movable, not copyable; declare it after the actor system.
class served_module {
public:
  served_module() = default;
  served_module(running_module m, control_actor service,
                std::unique_ptr<control_server> server);
  served_module(served_module&&) noexcept = default;
  served_module& operator=(served_module&&) noexcept;
  ~served_module();

  /// Stops the control service, then the module (running_module::stop).
  void stop();

  const module_handles& handles() const noexcept {
    return module_.handles();
  }
  const module_handles* operator->() const noexcept {
    return &module_.handles();
  }
  const module_handles& operator*() const noexcept {
    return module_.handles();
  }
  operator const module_handles&() const noexcept {
    return module_.handles();
  }
  explicit operator bool() const noexcept {
    return static_cast<bool>(module_);
  }

  /// The control socket's path ("" if none).
  std::string socket() const;

private:
  running_module module_;
  control_actor service_;
  std::unique_ptr<control_server> server_;
};

/// Starts a module (run_module) and its control service named `name`,
/// listening at `socket` (default: default_control_socket(name), where
/// hermctl looks; "-": no socket, the service is then reachable from other
/// modules only). Errors: those of run_module and control_server::start.
caf::expected<served_module>
serve_module(caf::actor_system& sys, const module_config& cfg,
             const std::string& name, std::string socket = {},
             std::chrono::milliseconds timeout = std::chrono::seconds(5));

// -- binding -------------------------------------------------------------------------

/// Binds to the APO named `name` (or as `req` says), retrying while it is
/// not found or not reachable yet (right after start-up routes converge),
/// until `deadline` has passed. Blocks the calling thread: call it from
/// main or a detached actor, never from an event-based one. Errors, all
/// typed: app_ec::not_found ("no APO named 'calculator' within 10000 ms"),
/// routing_ec::no_route, or any other error of the bind at once.
caf::expected<caf::actor>
bind_within(caf::actor_system& sys, const app_support_actor& apps,
            bind_request req, std::chrono::milliseconds deadline);

/// The same for a name.
caf::expected<caf::actor>
bind_within(caf::actor_system& sys, const app_support_actor& apps,
            const std::string& name, std::chrono::milliseconds deadline);

// -- typed topics --------------------------------------------------------------------

/// One value of a topic with where and when it came from.
template <class T>
struct topic_message {
  std::string topic;
  /// The module that published it.
  module_id publisher = no_module;
  /// Its sequence number at the publisher.
  uint32_t seq = 0;
  /// When this module received it (system clock).
  caf::timestamp time;
  T value;
};

/// Publishes `value` on `topic` (asynchronous; refusals are counted in the
/// ASL's tx_refused).
template <class T>
void publish(const app_support_actor& apps, std::string topic, T value) {
  caf::anon_send(apps, atom::publish_v, std::move(topic),
                 caf::make_message(std::move(value)));
}

/// Spawns an actor that receives every value of `topic` whose message is a
/// single T and calls `f` with it (in that actor); values of other types
/// are skipped and counted in `*skipped` if given. Ends, and unsubscribes,
/// when exited (caf::anon_send_exit) or with the actor system. Fails like
/// the subscription (ec::invalid_parameter for a bad topic name).
template <class T, class F>
caf::expected<caf::actor>
subscribe(caf::actor_system& sys, const app_support_actor& apps,
          std::string topic, F f,
          std::shared_ptr<std::atomic<uint64_t>> skipped = nullptr) {
  auto sub = sys.spawn([f = std::move(f), skipped](caf::event_based_actor* self)
                         -> caf::behavior {
    return {
      [self, f, skipped](topic_sample& s) {
        auto msg = unmarshal(self->system(), s.payload.data(), s.payload.size());
        if (!msg || !msg->template match_elements<T>()) {
          if (skipped)
            ++*skipped;
          return;
        }
        f(topic_message<T>{std::move(s.topic), s.publisher, s.seq, s.time,
                           msg->template get_as<T>(0)});
      },
    };
  });
  caf::error err;
  caf::scoped_actor self{sys};
  self
    ->request(apps, std::chrono::seconds(10), atom::subscribe_v, topic, sub,
              atom::sample_v)
    .receive([] {}, [&](caf::error& e) { err = typed_error(e); });
  if (err) {
    caf::anon_send_exit(sub, caf::exit_reason::user_shutdown);
    return err;
  }
  return sub;
}

} // namespace herm
