// An embedding program that returns from main without stop_module: its
// running_module stops the module on the way out, so the actor system's
// destructor (which waits for every actor) returns and the program exits.
// Run by embed_exit_test; argv[1] is a free UDP port on loopback for the
// module's one channel (a real driver, as a user's program has).

#include <chrono>
#include <iostream>
#include <string>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: embed_returns_from_main PORT\n";
    return 2;
  }
  caf::actor_system_config cfg;
  herm::configure(cfg);
  caf::actor_system sys{cfg};
  herm::module_config mc;
  mc.routing.id = 0x61;
  mc.routing.hello_interval = std::chrono::milliseconds(100);
  mc.devices.push_back(herm::device_config{
    "eth0", "udp", std::string{"127.0.0.1:"} + argv[1], {}});
  auto m = herm::run_module(sys, mc);
  if (!m) {
    std::cout << "start failed: " << herm::render(m.error()) << std::endl;
    return 1;
  }
  std::cout << "started" << std::endl;
  return 0; // no stop_module: *m stops the module, then sys ends
}
