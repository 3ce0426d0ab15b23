// A user's module process, built against the installed HERM package and its
// one header <herm/herm.hpp>: a message type in one line (HERM_MESSAGE),
// one module (IO manager, routing agent, application support) on an
// in-process segment, an APO registered, a link's cost from the routing
// layer; prints one line and stops.

#include <chrono>
#include <iostream>
#include <string>

#include <herm/herm.hpp>

#include "channels/link_profile.hpp"

using namespace std::chrono_literals;

struct reading {
  uint16_t distance_mm = 0;
  std::string source;
};
HERM_MESSAGE(reading, distance_mm, source)

CAF_BEGIN_TYPE_ID_BLOCK(consumer, caf::id_block::herm::end)
  CAF_ADD_TYPE_ID(consumer, (reading))
CAF_END_TYPE_ID_BLOCK(consumer)

namespace {

caf::behavior echo(caf::event_based_actor*) {
  return {[](const std::string& s) { return s; }};
}

} // namespace

int main() {
  // [embed]
  caf::actor_system_config cfg;
  herm::configure(cfg); // HERM's type IDs, error category and scheduler
  herm::add_message_types<caf::id_block::consumer>(cfg); // and our own
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
                  << "; reading has "
                  << herm::find_description("reading")->fields.size()
                  << " described fields" << std::endl;
        rc = 0;
      },
      [&](caf::error& e) {
        std::cout << "register failed: " << herm::render(e) << std::endl;
      });
  self->send_exit(apo, caf::exit_reason::user_shutdown);
  herm::stop_module(*m);
  return rc;
}
