#pragma once

// Application Support Layer on a simulated network (actors/testing/
// sim_network.hpp): every module gets its application support actor, started
// again whenever the module is. Link with herm_asl.

#include "caf/actor_cast.hpp"

#include "actors/app_support.hpp"
#include "actors/testing/sim_network.hpp"

namespace herm::testkit {

/// Gives every module of `net` an application support actor with `cfg`
/// (set before `net.start()`). `net.at(i).apps` holds it.
inline void add_app_support(deterministic_system& fx, sim_network& net,
                            app_support_config cfg = {}) {
  net.on_start = [&fx, cfg](size_t, sim_network::module& m) {
    auto asl = fx.track(spawn_app_support(fx.sys(), m.agent, cfg));
    m.apps = caf::actor_cast<caf::actor>(asl);
  };
}

/// The application support actor of module `i`.
inline app_support_actor apps_of(sim_network& net, size_t i) {
  return caf::actor_cast<app_support_actor>(net.at(i).apps);
}

} // namespace herm::testkit
