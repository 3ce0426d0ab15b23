#pragma once

// Drives HERM's actors with CAF's deterministic test_coordinator: nothing
// runs until the caller says so, and time moves only when the caller
// advances it. Public testing kit: HERM's own tests and benchmarks use it,
// and so can users' tests (with any test framework; see
// tests/support/actor_fixture.hpp for the GoogleTest fixture). CAF's own
// caf/test/dsl.hpp macros crash under GoogleTest, so this does not use them.

#include <memory>
#include <optional>
#include <tuple>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scheduler/test_coordinator.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm::testkit {

/// Everything a probe actor received, in order.
struct probe_log {
  std::vector<packet_received> packets;
  std::vector<link_event> events;
  std::vector<channel_up> ups;
  std::vector<channel_down> downs;
  std::vector<caf::down_msg> monitor_downs;
};

/// A test actor that reads channels and listens to the IO manager.
using probe_actor
  = caf::typed_actor<caf::reacts_to<packet_received>,
                     caf::reacts_to<link_event>, caf::reacts_to<channel_up>,
                     caf::reacts_to<channel_down>>;

class deterministic_system {
public:
  deterministic_system() : sys_(init(cfg_)), sched(dynamic_cast<scheduler_type&>(sys_.scheduler())) {
    // Start away from the clock's epoch.
    sched.clock().current_time += std::chrono::hours(1);
  }

  virtual ~deterministic_system() {
    // The actor system waits for every actor at destruction: stop what the
    // test spawned (IO managers take their devices and channels along).
    for (auto& hdl : tracked_)
      caf::anon_send_exit(hdl, caf::exit_reason::user_shutdown);
    sched.run();
  }

  /// Stops `hdl` when the test ends. Returns `hdl`.
  template <class Handle>
  Handle track(Handle hdl) {
    tracked_.push_back(caf::actor_cast<caf::actor>(hdl));
    return hdl;
  }

  using scheduler_type = caf::scheduler::test_coordinator;

  caf::actor_system& sys() {
    return sys_;
  }

  /// Runs every actor until no message is left.
  size_t run() {
    return sched.run();
  }

  /// Moves the clock forward by `dt`, stopping at every timer due on the
  /// way: the clock is set to the timer's exact time, the timer fires and
  /// every actor runs until idle, so timers set by those actors fire on
  /// time too. Then the clock is set to the end and actors run again.
  void advance(caf::timespan dt) {
    auto& clk = sched.clock();
    auto target = clk.current_time + dt;
    sched.run();
    while (!clk.schedule().empty() && clk.schedule().begin()->first <= target) {
      clk.trigger_timeout();
      sched.run();
    }
    clk.current_time = target;
    sched.run();
  }

  /// Sends a request to `hdl`, runs until the answer arrives, and returns it
  /// (a tuple of the reply's values, or the error).
  template <class... Rs, class Handle, class... Ts>
  caf::expected<std::tuple<Rs...>> call(const Handle& hdl, Ts... xs) {
    auto result
      = std::make_shared<std::optional<caf::expected<std::tuple<Rs...>>>>();
    sys_.spawn([=](caf::event_based_actor* self) {
      self->request(hdl, caf::infinite, xs...)
        .then([=](Rs&... rs) { *result = std::make_tuple(rs...); },
              [=](caf::error& err) { *result = std::move(err); });
    });
    sched.run();
    if (!*result)
      return make_error(ec::timeout, "no reply after running every actor");
    return std::move(**result);
  }

  /// Spawns a probe that logs what it receives and monitors `watch`ed actors.
  std::pair<probe_actor, std::shared_ptr<probe_log>> spawn_probe() {
    auto log = std::make_shared<probe_log>();
    auto hdl = sys_.spawn([log](probe_actor::pointer self) -> probe_actor::behavior_type {
      self->set_down_handler([log](caf::down_msg& msg) {
        log->monitor_downs.push_back(msg);
      });
      return {
        [log](packet_received& x) { log->packets.push_back(std::move(x)); },
        [log](link_event& x) { log->events.push_back(std::move(x)); },
        [log](channel_up& x) { log->ups.push_back(std::move(x)); },
        [log](channel_down& x) { log->downs.push_back(std::move(x)); },
      };
    });
    track(hdl);
    return {hdl, log};
  }

private:
  static caf::actor_system_config& init(caf::actor_system_config& cfg) {
    configure_for_testing(cfg);
    return cfg;
  }

  caf::actor_system_config cfg_;
  caf::actor_system sys_;
  std::vector<caf::actor> tracked_;

public:
  scheduler_type& sched;
};

} // namespace herm::testkit
