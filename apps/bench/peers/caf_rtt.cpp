// CAF 0.17's own remote actors: the server publishes an echo actor with
// caf::io::middleman on 127.0.0.1 (TCP, CAF's BASP protocol), the client
// gets a handle with remote_actor and runs the same event-based client as
// herm (actor_client.hpp). What a CAF user picks to talk between processes.

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
  configure(cfg, policy);
  cfg.add_message_types<caf::id_block::herm_bench>();
  cfg.load<caf::io::middleman>();
}

} // namespace

int caf_server(const endpoint_params& p) {
  caf::actor_system_config cfg;
  configure_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  auto echo = sys.spawn(echo_actor);
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
  return run_actor_client(sys, *echo, p, false);
}

} // namespace herm::bench
