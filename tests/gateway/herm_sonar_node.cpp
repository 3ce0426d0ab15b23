// The HERM end of gateway_process_test: a module of its own (an embedding
// program, as a robot's sensor module would be) on one UDP channel that
//  - publishes an SRF04 reading on topic "sonar" every 100 ms: seq i,
//    distance 1000 + 10 i mm (every fifth one out of range), and
//  - subscribes to "cmd_vel" and "sonar_in" and prints what comes:
//      twist <linear.x> <angular.z>
//      sonar_in <seq> <distance_mm>
//  - serves the APO "adder": a request (int64_t a, int64_t b) is answered
//    with a + b, and
//  - every 500 ms calls each of the APOs dds_adder, dds_silent and
//    dds_nobody (bound by name, one call in flight per name) with (7, 8)
//    and prints "call <name> <sum>" or "call <name> error <error>".
//
//   herm_sonar_node PORT PEER_PORT SECONDS
//
// Prints "started" once the module runs; ends after SECONDS.

#include <chrono>
#include <map>
#include <cstdio>
#include <string>
#include <thread>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/dds_gateway/types.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

caf::behavior publisher(caf::event_based_actor* self, app_support_actor apps) {
  self->send(self, atom::tick_v);
  return {
    [self, apps, seq = uint16_t{0}](atom::tick) mutable {
      self->delayed_send(self, 100ms, atom::tick_v);
      ++seq;
      hermd::srf04_reading r{seq, static_cast<uint16_t>(1000 + 10 * seq), 0};
      if (seq % 5 == 0)
        r.distance_mm = hermd::srf04_out_of_range;
      r.echo_us = r.distance_mm * 2000u / 343u;
      self->send(apps, atom::publish_v, std::string{"sonar"},
                 caf::make_message(r));
    },
  };
}

caf::behavior printer(caf::event_based_actor*) {
  return {
    [](const dds_gateway::twist& t) {
      std::printf("twist %.2f %.2f\n", t.linear.x, t.angular.z);
      std::fflush(stdout);
    },
    [](const hermd::srf04_reading& r) {
      std::printf("sonar_in %u %u\n", r.seq, r.distance_mm);
      std::fflush(stdout);
    },
  };
}

caf::behavior adder(caf::event_based_actor*) {
  return {
    [](int64_t a, int64_t b) { return a + b; },
  };
}

struct caller_state {
  static inline const char* name = "herm.test.caller";
  std::map<std::string, bool> busy;
};

void call_once(caf::stateful_actor<caller_state>* self, app_support_actor apps,
               const std::string& name) {
  self->state.busy[name] = true;
  auto done = [self, name](const std::string& what) {
    std::printf("call %s %s\n", name.c_str(), what.c_str());
    std::fflush(stdout);
    self->state.busy[name] = false;
  };
  self->request(apps, 5s, atom::bind_v, bind_request{query_by::name, name, 500})
    .then(
      [self, done](caf::actor& proxy) {
        self->request(proxy, 10s, int64_t{7}, int64_t{8})
          .then([done](int64_t sum) { done(std::to_string(sum)); },
                [done](caf::error& err) { done("error " + render(err)); });
      },
      [done](caf::error& err) { done("error " + render(err)); });
}

caf::behavior caller(caf::stateful_actor<caller_state>* self,
                     app_support_actor apps) {
  self->send(self, atom::tick_v);
  return {
    [self, apps](atom::tick) {
      self->delayed_send(self, 500ms, atom::tick_v);
      for (auto name : {"dds_adder", "dds_silent", "dds_nobody"})
        if (!self->state.busy[name])
          call_once(self, apps, name);
    },
  };
}

} // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: herm_sonar_node PORT PEER_PORT SECONDS\n");
    return 2;
  }
  caf::actor_system_config cfg;
  configure(cfg);
  cfg.add_message_types<caf::id_block::herm_apos>();
  dds_gateway::add_gateway_types(cfg);
  caf::actor_system sys{cfg};
  module_config mc;
  mc.routing.id = 0x63;
  mc.routing.hello_interval = 100ms;
  mc.devices.push_back(
    device_config{"eth0", "udp", std::string{"127.0.0.1:"} + argv[1],
                  {{"peers", std::string{"127.0.0.1:"} + argv[2]}}});
  auto m = run_module(sys, mc);
  if (!m) {
    std::printf("start failed: %s\n", render(m.error()).c_str());
    return 1;
  }
  const module_handles& h = *m;
  auto pr = sys.spawn(printer);
  for (auto topic : {"cmd_vel", "sonar_in"})
    caf::anon_send(h.apps, atom::subscribe_v, std::string{topic}, pr);
  auto pub = sys.spawn(publisher, h.apps);
  auto add = sys.spawn(adder);
  caf::anon_send(h.apps, atom::add_v, std::string{"adder"},
                 std::string{"herm.adder"}, add);
  auto calls = sys.spawn(caller, h.apps);
  std::printf("started\n");
  std::fflush(stdout);
  // Every second, what the module's topics did (for a failing test's log).
  caf::scoped_actor self{sys};
  for (int i = 0; i < std::stoi(argv[3]); ++i) {
    std::this_thread::sleep_for(1s);
    self->request(h.apps, 1s, atom::get_v, atom::stats_v)
      .receive(
        [](const app_support_stats& st) {
          std::printf("stats published %llu sent %llu received %llu "
                      "delivered %llu\n",
                      static_cast<unsigned long long>(st.published),
                      static_cast<unsigned long long>(st.publications_sent),
                      static_cast<unsigned long long>(st.publications_received),
                      static_cast<unsigned long long>(
                        st.publications_delivered));
          std::fflush(stdout);
        },
        [](caf::error&) {});
  }
  caf::anon_send_exit(pub, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(add, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(calls, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(pr, caf::exit_reason::user_shutdown);
  return 0;
}
