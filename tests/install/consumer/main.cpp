// A user's module process, built against the installed HERM package: starts
// one module (IO manager, routing agent, application support) on an
// in-process segment, registers an APO, asks the routing layer for a link's
// cost, prints one line and stops.

#include <chrono>
#include <iostream>
#include <string>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/link_profile.hpp"

using namespace std::chrono_literals;

namespace {

caf::behavior echo(caf::event_based_actor*) {
  return {[](const std::string& s) { return s; }};
}

} // namespace

int main() {
  // [embed]
  caf::actor_system_config cfg;
  herm::configure(cfg); // HERM's type IDs, error category and scheduler
  caf::actor_system sys{cfg};
  herm::module_config mc;
  mc.routing.id = 7;
  // One interface; on a robot: "udp", "can", "serial" instead of "inproc".
  mc.devices.push_back({"lo0", "inproc", "consumer", {}});
  auto m = herm::start_module(sys, mc);
  if (!m) {
    std::cout << "start_module failed: " << herm::render(m.error()) << std::endl;
    return 1;
  }
  // [embed-end]
  caf::scoped_actor self{sys};
  auto apo = sys.spawn(echo);
  int rc = 1;
  self->request(m->apps, 5s, herm::atom::add_v, std::string{"echo"},
                std::string{"consumer.echo"}, apo)
    .receive(
      [&](herm::apo_ref& ref) {
        auto can = herm::find_profile("can2.0");
        std::cout << "herm consumer: registered '" << ref.name << "' ("
                  << ref.type << ") as APO " << ref.apo
                  << "; link_cost(can2.0) = " << (can ? herm::link_cost(*can) : 0)
                  << std::endl;
        rc = 0;
      },
      [&](caf::error& e) {
        std::cout << "register failed: " << herm::render(e) << std::endl;
      });
  self->send_exit(apo, caf::exit_reason::user_shutdown);
  herm::stop_module(*m);
  return rc;
}
