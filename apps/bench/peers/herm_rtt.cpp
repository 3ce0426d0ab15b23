// HERM: two modules, one per process, joined by a udp link on 127.0.0.1
// (each lists the other in `peers`). The server registers an echo APO; the
// client binds a proxy to it by name and runs the shared event-based client
// (actor_client.hpp) through the proxy: APO payload marshalling, the
// application support actor, the routing agent, the IO manager, the udp
// channel and driver on both sides, both ways.
//
// Other modes: oneway (the server registers a counting APO "rtt.count", the
// client registers itself as "rtt.ack" for the acknowledgements and sends
// one-way through a proxy), router (a third process, a router module with
// two udp devices, is the only peer of both: every packet is forwarded by
// it), inprocess (one process, one module without devices).

#include <unistd.h>

#include <future>
#include <iostream>
#include <thread>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/bench/peers/actor_client.hpp"
#include "apps/bench/peers/bench_types.hpp"

using namespace std::chrono_literals;

namespace herm::bench {

namespace {

constexpr const char* apo_name = "rtt.echo";
constexpr const char* count_name = "rtt.count";
constexpr module_id server_id = 0x20;
constexpr module_id client_id = 0x21;
constexpr module_id router_id = 0x22;

void add_udp(module_config& mc, uint16_t port, uint16_t peer) {
  auto name = "eth" + std::to_string(mc.devices.size());
  mc.devices.push_back({name, "udp", "127.0.0.1:" + std::to_string(port),
                        {{"peers", "127.0.0.1:" + std::to_string(peer)}}});
}

/// A module with one udp device on `port` whose only peer is `peer` (no
/// device at all when `port` is 0).
module_config make_module(module_id id, uint16_t port, uint16_t peer,
                          std::chrono::milliseconds hello) {
  module_config mc;
  mc.routing.id = id;
  mc.routing.hello_interval = hello;
  if (port != 0)
    add_udp(mc, port, peer);
  return mc;
}

/// Registers `apo` under `name` in the module's application table.
caf::error register_apo(caf::actor_system& sys, const module_handles& m,
                        const std::string& name, const caf::actor& apo) {
  caf::error err;
  caf::scoped_actor self{sys};
  self->request(m.apps, 5s, atom::add_v, name, std::string{"bench." + name}, apo)
    .receive([](apo_ref&) {}, [&](caf::error& e) { err = e; });
  return err;
}

/// Binds a proxy by name; routes converge first: not_found and no_route
/// mean "try again" until `until`.
caf::expected<caf::actor> bind_by_name(caf::actor_system& sys,
                                       const module_handles& m,
                                       const std::string& name, bool rebind,
                                       std::chrono::steady_clock::time_point until) {
  caf::scoped_actor self{sys};
  caf::error err;
  for (;;) {
    caf::actor proxy;
    self->request(m.apps, 5s, atom::bind_v,
                  bind_request{query_by::name, name, 1000, rebind})
      .receive([&](caf::actor& x) { proxy = x; }, [&](caf::error& e) { err = e; });
    if (proxy)
      return proxy;
    if ((!is(err, app_ec::not_found) && !is(err, routing_ec::no_route))
        || std::chrono::steady_clock::now() >= until)
      return make_error(app_ec::not_found, "bind " + name + ": " + render(err));
    std::this_thread::sleep_for(50ms);
  }
}

/// Waits until the module has a selected route to `dst`; returns its hops
/// (0: none before `until`).
uint8_t wait_for_route(caf::actor_system& sys, const module_handles& m,
                       module_id dst, std::chrono::steady_clock::time_point until) {
  caf::scoped_actor self{sys};
  for (;;) {
    uint8_t hops = 0;
    self->request(m.agent, 5s, atom::get_v, atom::routes_v)
      .receive(
        [&](std::vector<route_info>& routes) {
          for (auto& r : routes)
            if (r.destination == dst && r.selected && r.size_class == 0)
              hops = r.hops;
        },
        [](caf::error&) {});
    if (hops > 0 || std::chrono::steady_clock::now() >= until)
      return hops;
    std::this_thread::sleep_for(20ms);
  }
}

} // namespace

int herm_server(const endpoint_params& p) {
  caf::actor_system_config cfg;
  configure_actor_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  // In router mode the only peer is the router's port facing this module.
  auto peer = p.mode == "router" ? p.port4 : p.port2;
  auto m = start_module(sys, make_module(server_id, p.port, peer, p.hello));
  if (!m) {
    std::cout << "error " << render(m.error()) << std::endl;
    return 1;
  }
  auto err = p.mode == "oneway"
               ? register_apo(sys, *m, count_name, sys.spawn(count_actor, p, m->apps))
               : register_apo(sys, *m, apo_name, sys.spawn(echo_actor));
  if (err) {
    std::cout << "error " << render(err) << std::endl;
    return 1;
  }
  std::cout << "ready " << p.port << std::endl;
  for (;;)
    ::pause(); // until the orchestrator's SIGTERM
}

int herm_router(const endpoint_params& p) {
  caf::actor_system_config cfg;
  configure_actor_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  module_config mc;
  mc.routing.id = router_id;
  mc.routing.hello_interval = p.hello;
  add_udp(mc, p.port3, p.port2); // toward the client's module
  add_udp(mc, p.port4, p.port);  // toward the server's module
  auto m = start_module(sys, mc);
  if (!m) {
    std::cout << "error " << render(m.error()) << std::endl;
    return 1;
  }
  std::cout << "ready " << p.port3 << std::endl;
  for (;;)
    ::pause();
}

client_result herm_client(const endpoint_params& p) {
  client_result res;
  caf::actor_system_config cfg;
  configure_actor_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  bool router = p.mode == "router";
  auto m = start_module(sys, make_module(client_id, p.port2,
                                         router ? p.port3 : p.port, p.hello));
  if (!m) {
    res.error = render(m.error());
    return res;
  }
  auto until = std::chrono::steady_clock::now() + 20s;
  if (router) {
    // Measure only once the route through the router is there: two hops.
    auto hops = wait_for_route(sys, *m, server_id, until);
    if (hops != 2) {
      res.error = hops == 0 ? "no route to the server module within 20 s"
                            : "route to the server module of " + std::to_string(hops)
                                + " hops, expected 2 (through the router)";
      stop_module(*m);
      return res;
    }
  }
  if (p.mode == "oneway") {
    auto done = std::make_shared<std::promise<client_result>>();
    auto fut = done->get_future();
    caf::actor proxy;
    if (auto x = bind_by_name(sys, *m, count_name, false, until))
      proxy = *x;
    else
      res.error = render(x.error());
    if (proxy) {
      auto client = spawn_oneway_client(sys, proxy, p, done);
      if (auto err = register_apo(sys, *m, "rtt.ack", client)) {
        res.error = "register rtt.ack: " + render(err);
        caf::anon_send_exit(client, caf::exit_reason::user_shutdown);
      } else {
        res = run_oneway_client(client, std::move(fut));
      }
    }
    proxy = nullptr;
    stop_module(*m);
    return res;
  }
  caf::actor proxy;
  if (auto x = bind_by_name(sys, *m, apo_name, false, until))
    proxy = *x;
  else
    res.error = render(x.error());
  if (proxy)
    res = run_actor_client(sys, proxy, p, true);
  proxy = nullptr;
  stop_module(*m);
  return res;
}

client_result inprocess_client(const endpoint_params& p) {
  client_result res;
  caf::actor_system_config cfg;
  configure_actor_system(cfg, p.policy);
  caf::actor_system sys{cfg};
  // A module without devices: its application support layer is all that
  // matters when the APO is local.
  auto m = start_module(sys, make_module(client_id, 0, 0, p.hello));
  if (!m) {
    res.error = render(m.error());
    return res;
  }
  auto echo = sys.spawn(echo_actor);
  if (auto err = register_apo(sys, *m, apo_name, echo)) {
    res.error = render(err);
    stop_module(*m);
    return res;
  }
  caf::actor target = echo;
  if (p.transport != "caf-local") {
    // "herm": bind by name as users do (a local match yields the APO itself);
    // "herm-rebind": a rebinding proxy, which stays a proxy even for a local
    // match and hands every request over through the application support
    // actor.
    auto x = bind_by_name(sys, *m, apo_name, p.transport == "herm-rebind",
                          std::chrono::steady_clock::now() + 5s);
    if (!x) {
      res.error = render(x.error());
      stop_module(*m);
      return res;
    }
    target = *x;
  }
  res = run_actor_client(sys, target, p, false);
  target = nullptr;
  stop_module(*m);
  return res;
}

} // namespace herm::bench
