#pragma once

// Application Support Layer on a simulated network (actors/testing/
// sim_network.hpp): every module gets its application support actor, started
// again whenever the module is, and the test's own APOs live on modules of
// its choice. Public testing kit; link with herm_asl.
//
//   add_app_support(net);                           // before net.start()
//   net.add_start_hook([&](size_t i, sim_network::module&) {
//     if (i == sensor)
//       spawn_apo(net, i, "sonar", "example.sonar", sonar_behavior);
//   });
//   net.start();
//   net.advance(2s);                                // routes converge
//   auto proxy = bind_apo(net, controller,
//                         bind_request{query_by::name, "sonar", 300, false});
//
// Everything here runs on the test's thread, like the rest of the kit.

#include <iostream>
#include <string>
#include <utility>

#include "caf/actor_cast.hpp"
#include "caf/event_based_actor.hpp"

#include "actors/app_support.hpp"
#include "actors/runtime/error.hpp"
#include "actors/testing/sim_network.hpp"

namespace herm::testkit {

/// Gives every module of `net` an application support actor with `cfg`
/// (set before `net.start()`). `net.at(i).apps` holds it. Takes the
/// network's `on_start` hook; add hooks of your own with
/// `net.add_start_hook` (they run after this one, so the module's
/// application support actor is there for them).
inline void add_app_support(deterministic_system& fx, sim_network& net,
                            app_support_config cfg = {}) {
  net.on_start = [&fx, cfg](size_t, sim_network::module& m) {
    auto c = cfg;
    c.fast_routes = m.cfg.fast_routes; // what the module's agent publishes
    auto asl = fx.track(spawn_app_support(fx.sys(), m.agent, std::move(c)));
    m.apps = caf::actor_cast<caf::actor>(asl);
  };
}

/// `add_app_support` on the network's own harness.
inline void add_app_support(sim_network& net, app_support_config cfg = {}) {
  add_app_support(net.harness(), net, std::move(cfg));
}

/// The application support actor of module `i` (invalid if the module has
/// none, or before it started).
inline app_support_actor apps_of(sim_network& net, size_t i) {
  return caf::actor_cast<app_support_actor>(net.at(i).apps);
}

/// Spawns an APO living on module `i`, as `net.sys().spawn(xs...)` does
/// (e.g. `spawn_apo(net, i, "sonar", "example.sonar", sonar, arg)`), and
/// registers it under `name` and `type` at the module's application support
/// actor, which `add_app_support` must have started. `kill(i)` kills the
/// APO with its module; spawn it from a start hook to have it come back when
/// the module restarts. Runs no actor: the registration completes when
/// actors next run, then `net.at(i).apos` holds its `apo_ref`. A refused
/// registration (e.g. a name over 255 bytes) is written to stderr, and the
/// APO stays unknown to the network (binding to it fails with
/// app_ec::not_found). Returns the APO's handle.
template <class... Ts>
auto spawn_apo(sim_network& net, size_t i, std::string name, std::string type,
               Ts&&... xs) {
  auto apo = net.spawn_on(i, std::forward<Ts>(xs)...);
  auto asl = apps_of(net, i);
  if (!asl) {
    std::cerr << "herm testkit: module " << i
              << " has no application support actor: APO '" << name
              << "' not registered (call add_app_support before start)\n";
    return apo;
  }
  auto* where = &net;
  auto hdl = caf::actor_cast<caf::actor>(apo);
  net.sys().spawn([=](caf::event_based_actor* self) {
    self->request(asl, caf::infinite, atom::add_v, name, type, hdl)
      .then([=](apo_ref& ref) { where->at(i).apos.push_back(std::move(ref)); },
            [=](caf::error& err) {
              std::cerr << "herm testkit: registering APO '" << name
                        << "' on module " << i << " failed: " << render(err)
                        << '\n';
            });
  });
  return apo;
}

/// Binds from module `i` to an APO found by name or type, as
/// `(atom::bind, req)` at its application support actor does, moving
/// simulated time until the answer (at most `req.timeout_ms` plus 100 ms).
/// Returns the proxy (or the APO itself if it lives on module `i`), or the
/// error: app_ec::not_found when nothing answered, routing_ec::no_route, ec::timeout
/// when the layer did not answer in time.
inline caf::expected<caf::actor> bind_apo(sim_network& net, size_t i,
                                          bind_request req) {
  auto wait = std::chrono::milliseconds(req.timeout_ms + 100);
  auto res = net.harness().call_for<caf::actor>(wait, apps_of(net, i),
                                                atom::bind_v, std::move(req));
  if (!res)
    return std::move(res.error());
  return std::get<0>(*res);
}

/// Binds from module `i` to the APO `ref` names (from `find`, or
/// `net.at(j).apos`), without discovery. Errors: app_ec::apo_gone,
/// routing_ec::no_route.
inline caf::expected<caf::actor> bind_apo(sim_network& net, size_t i,
                                          apo_ref ref) {
  auto res = net.harness().call<caf::actor>(apps_of(net, i), atom::bind_v,
                                            std::move(ref));
  if (!res)
    return std::move(res.error());
  return std::get<0>(*res);
}

/// Module i's Application Support Layer counters (empty when it does not
/// answer).
inline app_support_stats app_stats(sim_network& net, size_t i) {
  auto res = net.harness().call<app_support_stats>(apps_of(net, i),
                                                   atom::get_v, atom::stats_v);
  return res ? std::get<0>(*res) : app_support_stats{};
}

} // namespace herm::testkit
