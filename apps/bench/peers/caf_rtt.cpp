// CAF 0.17's own remote actors: the server publishes an echo actor with
// caf::io::middleman on 127.0.0.1 (TCP, CAF's BASP protocol), the client
// gets a handle with remote_actor and runs the same event-based client as
// herm (actor_client.hpp). What a CAF user picks to talk between processes.
// oneway: the server publishes the counting actor instead, which sends its
// acknowledgements to the hello's sender (a BASP proxy of the client).

#include <unistd.h>

#include <iostream>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/io/middleman.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/bench/peers/actor_client.hpp"
#include "apps/bench/peers/bench_types.hpp"

namespace herm::bench {

namespace {

void configure_system(caf::actor_system_config& cfg, const std::string& policy) {
  configure_actor_system(cfg, policy);
  cfg.load<caf::io::middleman>();
}

} // namespace

int caf_server(const endpoint_params& p) {
  caf::actor_system_config cfg;
  configure_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  auto echo = p.mode == "oneway" ? sys.spawn(count_actor, p, app_support_actor{})
                                 : sys.spawn(echo_actor);
  auto port = sys.middleman().publish(echo, p.port, "127.0.0.1");
  if (!port) {
    std::cout << "error publish: " << render(port.error()) << std::endl;
    return 1;
  }
  std::cout << "ready " << *port << std::endl;
  for (;;)
    ::pause(); // until the orchestrator's SIGTERM
}

client_result caf_client(const endpoint_params& p) {
  client_result res;
  caf::actor_system_config cfg;
  configure_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  auto echo = sys.middleman().remote_actor("127.0.0.1", p.port);
  if (!echo) {
    res.error = "remote_actor: " + render(echo.error());
    return res;
  }
  if (p.mode == "oneway") {
    auto done = std::make_shared<std::promise<client_result>>();
    auto fut = done->get_future();
    return run_oneway_client(spawn_oneway_client(sys, *echo, p, done), std::move(fut));
  }
  return run_actor_client(sys, *echo, p, false);
}

} // namespace herm::bench
