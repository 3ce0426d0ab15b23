#pragma once

// Drives HERM's actors with CAF's deterministic test_coordinator: nothing
// runs until the caller says so, and time moves only when the caller
// advances it. Public testing kit: HERM's own tests and benchmarks use it,
// and so can users' tests, with any test framework. With GoogleTest, derive
// the fixture from both:
//
//   class my_test : public ::testing::Test,
//                   public herm::testkit::deterministic_system {};
//
// (apps/examples/testing_apos/sonar_test.cpp is a complete example;
// docs/user-guide.md, "Testing your APOs", walks through it). CAF's own
// caf/test/dsl.hpp macros crash under GoogleTest, so this does not use them.
//
// Threading: everything here runs on the test's thread; actors run only
// inside run(), advance() and the other calls that say they run actors.
// Link with herm_system (herm_asl brings it along).

#include <functional>
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
  /// Down messages of the channels it subscribed to (a channel monitors
  /// itself on its subscribers' behalf).
  std::vector<caf::down_msg> monitor_downs;
};

/// Down messages a `deterministic_system::watch` monitor received, in order.
using down_log = std::vector<caf::down_msg>;

/// A test actor that reads channels and listens to the IO manager: subscribe
/// it at a channel as a `channel_reader_actor`, or at an IO manager as an
/// `io_listener_actor` (both by `caf::actor_cast`).
using probe_actor
  = caf::typed_actor<caf::reacts_to<packet_received>,
                     caf::reacts_to<link_event>, caf::reacts_to<channel_up>,
                     caf::reacts_to<channel_down>>;

/// An actor system under CAF's test_coordinator, configured for HERM, with
/// the calls a deterministic test needs: run actors, move simulated time,
/// ask an actor and wait for its answer, watch an actor's exit. Every actor
/// given to `track` (and every probe and monitor spawned here) is stopped
/// when the harness is destroyed. Not copyable; one per test.
class deterministic_system {
public:
  /// More configuration, applied after HERM's (`configure_for_testing`) and
  /// before the actor system starts: register your own type-ID blocks here
  /// (see `with_message_types`).
  using config_hook = std::function<void(caf::actor_system_config&)>;

  deterministic_system() : deterministic_system(config_hook{}) {
    // nop
  }

  /// Applies `extra` to the configuration before the system starts.
  explicit deterministic_system(config_hook extra)
    : sys_(init(cfg_, extra)),
      sched(dynamic_cast<scheduler_type&>(sys_.scheduler())) {
    // Start away from the clock's epoch.
    sched.clock().current_time += std::chrono::hours(1);
  }

  /// A `config_hook` registering the type-ID blocks `IdBlocks` (e.g.
  /// `caf::id_block::my_app`), so that the user's message types can travel
  /// between modules: `deterministic_system(with_message_types<...>())`.
  template <class... IdBlocks>
  static config_hook with_message_types() {
    return [](caf::actor_system_config& cfg) {
      (cfg.add_message_types<IdBlocks>(), ...);
    };
  }

  deterministic_system(const deterministic_system&) = delete;
  deterministic_system& operator=(const deterministic_system&) = delete;

  virtual ~deterministic_system() {
    // The actor system waits for every actor at destruction: stop what the
    // test spawned (IO managers take their devices and channels along).
    for (auto& hdl : tracked_)
      caf::anon_send_exit(hdl, caf::exit_reason::user_shutdown);
    sched.run();
  }

  /// Stops `hdl` (exit reason user_shutdown) when the harness is destroyed.
  /// Track every long-lived actor a test spawns: the actor system waits for
  /// all actors at shutdown. Returns `hdl`.
  template <class Handle>
  Handle track(Handle hdl) {
    tracked_.push_back(caf::actor_cast<caf::actor>(hdl));
    return hdl;
  }

  using scheduler_type = caf::scheduler::test_coordinator;

  /// The actor system: spawn your actors here (and `track` them).
  caf::actor_system& sys() {
    return sys_;
  }

  /// Runs every actor until no message is left; fires no timer. Returns the
  /// number of jobs run.
  size_t run() {
    return sched.run();
  }

  /// The simulated time (starts one hour after the clock's epoch).
  caf::actor_clock::time_point now() const {
    return sched.clock().now();
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

  /// Like `advance(max)`, but stops as soon as `done()` holds, checked after
  /// every run (before the first timer, then after each): the clock stays
  /// at the timer that made it true. Returns `done()`. Use it for "within
  /// `max` of simulated time" assertions without overshooting.
  template <class Predicate>
  bool advance_until(caf::timespan max, Predicate done) {
    auto& clk = sched.clock();
    auto target = clk.current_time + max;
    sched.run();
    if (done())
      return true;
    while (!clk.schedule().empty() && clk.schedule().begin()->first <= target) {
      clk.trigger_timeout();
      sched.run();
      if (done())
        return true;
    }
    clk.current_time = target;
    sched.run();
    return done();
  }

  /// Sends a request to `hdl` from a fresh actor, runs every actor until the
  /// answer arrives, and returns it (a tuple of the reply's values `Rs`, or
  /// the error). Fires no timer: an answer that needs one (a discovery, a
  /// timeout) yields ec::timeout here; use `call_for` for those.
  template <class... Rs, class Handle, class... Ts>
  caf::expected<std::tuple<Rs...>> call(const Handle& hdl, Ts... xs) {
    return call_for<Rs...>(caf::timespan{0}, hdl, std::move(xs)...);
  }

  /// Like `call`, but moves simulated time forward (timer by timer, as
  /// `advance_until`) for at most `wait` until the answer arrives. Fails
  /// with ec::timeout when none came within `wait`.
  template <class... Rs, class Handle, class... Ts>
  caf::expected<std::tuple<Rs...>> call_for(caf::timespan wait,
                                            const Handle& hdl, Ts... xs) {
    auto result
      = std::make_shared<std::optional<caf::expected<std::tuple<Rs...>>>>();
    sys_.spawn([=](caf::event_based_actor* self) {
      self->request(hdl, caf::infinite, xs...)
        .then([=](Rs&... rs) { *result = std::make_tuple(rs...); },
              [=](caf::error& err) { *result = std::move(err); });
    });
    if (wait == caf::timespan{0})
      sched.run();
    else
      advance_until(wait, [&] { return result->has_value(); });
    if (!*result)
      return make_error(ec::timeout, wait == caf::timespan{0}
                                       ? "no reply after running every actor"
                                       : "no reply within the simulated wait");
    return std::move(**result);
  }

  /// Monitors `hdl` (any actor handle, a proxy of a remote APO included)
  /// from a tracked helper actor and returns the log its down message will
  /// be appended to. Runs every actor, so the monitor is in place on return.
  template <class Handle>
  std::shared_ptr<down_log> watch(const Handle& hdl) {
    auto log = std::make_shared<down_log>();
    auto target = caf::actor_cast<caf::actor>(hdl);
    track(sys_.spawn([log, target](caf::event_based_actor* self) {
      self->set_down_handler(
        [log](caf::down_msg& msg) { log->push_back(std::move(msg)); });
      self->monitor(target);
      // A behavior keeps the helper alive until the test ends.
      return caf::behavior{[](atom::done) {}};
    }));
    sched.run();
    return log;
  }

  /// Spawns a tracked probe that logs everything it receives (see
  /// `probe_actor`).
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
  static caf::actor_system_config& init(caf::actor_system_config& cfg,
                                        const config_hook& extra) {
    configure_for_testing(cfg);
    if (extra)
      extra(cfg);
    return cfg;
  }

  caf::actor_system_config cfg_;
  caf::actor_system sys_;
  std::vector<caf::actor> tracked_;

public:
  /// CAF's test scheduler, for what the calls above do not cover
  /// (`sched.clock()`, `sched.run(n)`, `sched.trigger_timeouts()`).
  scheduler_type& sched;
};

} // namespace herm::testkit
