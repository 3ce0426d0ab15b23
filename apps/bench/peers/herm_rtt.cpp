// HERM: two modules, one per process, joined by a udp link on 127.0.0.1
// (each lists the other in `peers`). The server registers an echo APO; the
// client binds a proxy to it by name and runs the shared event-based client
// (actor_client.hpp) through the proxy: APO payload marshalling, the
// application support actor, the routing agent, the IO manager, the udp
// channel and driver on both sides, both ways.

#include <unistd.h>

#include <iostream>
#include <thread>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/bench/peers/actor_client.hpp"
#include "apps/bench/peers/bench_types.hpp"

using namespace std::chrono_literals;

namespace herm::bench {

namespace {

constexpr const char* apo_name = "rtt.echo";

module_config make_module(module_id id, uint16_t port, uint16_t peer,
                          std::chrono::milliseconds hello) {
  module_config mc;
  mc.routing.id = id;
  mc.routing.hello_interval = hello;
  mc.devices.push_back({"eth0", "udp", "127.0.0.1:" + std::to_string(port),
                        {{"peers", "127.0.0.1:" + std::to_string(peer)}}});
  return mc;
}

void configure_system(caf::actor_system_config& cfg, const std::string& policy) {
  configure(cfg, policy);
  cfg.add_message_types<caf::id_block::herm_bench>();
}

} // namespace

int herm_server(const endpoint_params& p) {
  caf::actor_system_config cfg;
  configure_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  auto m = start_module(sys, make_module(0x20, p.port, p.port2, p.hello));
  if (!m) {
    std::cout << "error " << render(m.error()) << std::endl;
    return 1;
  }
  auto echo = sys.spawn(echo_actor);
  caf::error err;
  {
    caf::scoped_actor self{sys};
    self->request(m->apps, 5s, atom::add_v, std::string{apo_name},
                  std::string{"bench.echo"}, echo)
      .receive([](apo_ref&) {}, [&](caf::error& e) { err = e; });
  }
  if (err) {
    std::cout << "error " << render(err) << std::endl;
    return 1;
  }
  std::cout << "ready " << p.port << std::endl;
  for (;;)
    ::pause(); // until the orchestrator's SIGTERM
}

client_result herm_client(const endpoint_params& p) {
  client_result res;
  caf::actor_system_config cfg;
  configure_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  auto m = start_module(sys, make_module(0x21, p.port2, p.port, p.hello));
  if (!m) {
    res.error = render(m.error());
    return res;
  }
  caf::actor proxy;
  {
    // Routes converge first: not_found and no_route mean "try again".
    caf::scoped_actor self{sys};
    auto until = std::chrono::steady_clock::now() + 20s;
    caf::error err;
    while (!proxy && std::chrono::steady_clock::now() < until) {
      self->request(m->apps, 5s, atom::bind_v,
                    bind_request{query_by::name, apo_name, 1000, false})
        .receive([&](caf::actor& x) { proxy = x; },
                 [&](caf::error& e) { err = e; });
      if (!proxy && !is(err, ec::not_found) && !is(err, ec::no_route))
        break;
      if (!proxy)
        std::this_thread::sleep_for(50ms);
    }
    if (!proxy)
      res.error = "bind: " + (err ? render(err) : std::string{"timed out"});
  }
  if (proxy)
    res = run_actor_client(sys, proxy, p, true);
  proxy = nullptr;
  stop_module(*m);
  return res;
}

} // namespace herm::bench
