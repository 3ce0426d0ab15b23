// herm-example-apo-test: how to test your own APOs with HERM's deterministic
// testing kit (actors/testing/), in GoogleTest.
//
// The application under test mirrors the HERM paper's testbed in small: a
// sonar APO on a sensor module (0x42) sends its readings to a collector APO
// on the main controller (0x4E) through a router module (0x45): CAN 2.0
// (1 Mbit/s, 8-byte frames) from the sensor to the router, Ethernet from the
// router to the controller. Three modules, their routing, their Application
// Support Layers and both APOs run in this one process under CAF's
// test_coordinator: nothing runs until the test says so and time moves only
// when the test advances it, so every test is exact and repeatable and
// takes milliseconds however many simulated seconds it spans.
//
// docs/user-guide.md ("Testing your APOs") quotes the regions marked
// "// [name]" ... "// [name-end]".

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "caf/event_based_actor.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/type_id.hpp"

#include "actors/testing/sim_apps.hpp"

using namespace herm;
using namespace herm::testkit;
using namespace std::chrono_literals;

// -- the application under test ------------------------------------------------

// [types]
// One sonar reading. A plain struct with an inspect overload and an entry in
// our own type-ID block (starting where HERM's ends) travels between modules.
struct sonar_reading {
  uint32_t seq = 0; // 1, 2, 3, ... since the sonar started
  uint16_t range_mm = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, sonar_reading& x) {
  return f(caf::meta::type_name("sonar_reading"), x.seq, x.range_mm);
}

CAF_BEGIN_TYPE_ID_BLOCK(sonar_example, caf::id_block::herm::end)
  CAF_ADD_TYPE_ID(sonar_example, (sonar_reading))
CAF_END_TYPE_ID_BLOCK(sonar_example)
// [types-end]

namespace {

// [collector]
/// Every reading the collector received, in order.
using reading_log = std::vector<sonar_reading>;

// The collector APO on the main controller: stores each reading in `log`
// and acknowledges it with the number of readings it holds.
caf::behavior collector(caf::event_based_actor*,
                        std::shared_ptr<reading_log> log) {
  return {
    [log](const sonar_reading& r) -> uint32_t {
      log->push_back(r);
      return static_cast<uint32_t>(log->size());
    },
  };
}
// [collector-end]

// [sonar]
/// What the sonar APO saw: every acknowledgement and every failed send.
struct sonar_log {
  std::vector<uint32_t> acks;
  std::vector<caf::error> errors;
};

// Its own timers: atoms need no type ID (at most 10 characters).
using sample_atom = caf::atom_constant<caf::atom("sample")>;
using connect_atom = caf::atom_constant<caf::atom("connect")>;

struct sonar_state {
  static inline const char* name = "sonar";
  caf::actor collector; // a proxy, once bound
  uint32_t seq = 0;
};

constexpr auto sample_period = 100ms;

// The sonar APO on the sensor module: binds to the APO named "collector"
// wherever it runs (retrying until routes and discovery find it), then
// sends it a reading every 100 ms as a request. `rebind` keeps the proxy
// across outages: while the collector is unreachable, requests fail at once
// with a typed error, and the proxy finds the collector again when it is
// back.
caf::behavior sonar(caf::stateful_actor<sonar_state>* self,
                    app_support_actor apps, std::shared_ptr<sonar_log> log) {
  self->send(self, connect_atom::value);
  self->delayed_send(self, sample_period, sample_atom::value);
  return {
    [=](connect_atom) {
      self->request(apps, 5s, atom::bind_v,
                    bind_request{query_by::name, "collector", 200, true})
        .then([=](caf::actor& proxy) { self->state.collector = proxy; },
              [=](caf::error&) {
                self->delayed_send(self, 500ms, connect_atom::value);
              });
    },
    [=](sample_atom) {
      self->delayed_send(self, sample_period, sample_atom::value);
      if (!self->state.collector)
        return;
      auto seq = ++self->state.seq;
      sonar_reading r{seq, static_cast<uint16_t>(500 + 10 * (seq % 20))};
      self->request(self->state.collector, 1s, r)
        .then([=](uint32_t held) { log->acks.push_back(held); },
              [=](caf::error& err) { log->errors.push_back(err); });
    },
  };
}
// [sonar-end]

// -- the tests -----------------------------------------------------------------

// [fixture]
// A GoogleTest fixture that is also the deterministic actor system, with our
// type-ID block registered next to HERM's. The constructor builds the
// testbed, starts it and lets the routes converge.
class sonar_test : public ::testing::Test, public deterministic_system {
public:
  sonar_test()
    : deterministic_system(with_message_types<caf::id_block::sonar_example>()) {
    sensor = net.add_module(0x42);
    router = net.add_module(0x45);
    controller = net.add_module(0x4E);
    can_bus = net.connect({sensor, router}, "can2.0");
    ethernet = net.connect({router, controller}, "ethernet");
    add_app_support(net);
    // Runs whenever a module starts, restarts included: its APOs come back.
    net.add_start_hook([this](size_t i, sim_network::module&) {
      if (i == controller)
        spawn_apo(net, i, "collector", "example.collector", collector,
                  collected);
      if (i == sensor)
        spawn_apo(net, i, "sonar", "example.sonar", sonar, apps_of(net, i),
                  seen);
    });
    net.start();
    net.advance(2s); // hellos, routes, discovery, binding: all simulated
  }

  sim_network net{*this};
  size_t sensor = 0, router = 0, controller = 0;
  size_t can_bus = 0, ethernet = 0;
  std::shared_ptr<reading_log> collected = std::make_shared<reading_log>();
  std::shared_ptr<sonar_log> seen = std::make_shared<sonar_log>();
};
// [fixture-end]

} // namespace

// [deliver]
TEST_F(sonar_test, readings_cross_can_and_ethernet_to_the_collector) {
  ASSERT_FALSE(collected->empty()) << "the sonar should be bound by now";
  auto before = collected->size();
  net.advance(1s);
  // Exactly ten samples in one simulated second, none lost, in order, each
  // acknowledged with the collector's count.
  ASSERT_EQ(collected->size() - before, 10u);
  for (size_t k = 1; k < collected->size(); ++k)
    EXPECT_EQ((*collected)[k].seq, (*collected)[k - 1].seq + 1);
  EXPECT_EQ(seen->acks.back(), collected->size());
  EXPECT_TRUE(seen->errors.empty());
  // They took two hops: CAN to the router, Ethernet on to the controller.
  auto route = net.route(sensor, 0x4E);
  ASSERT_TRUE(route);
  EXPECT_EQ(route->hops, 2u);
  EXPECT_EQ(route->forwarding, "CAN2.0-Ethernet");
  EXPECT_GE(net.stats(router).forwarded, 20u); // requests and answers
}
// [deliver-end]

// [cut]
TEST_F(sonar_test, a_cut_can_bus_fails_sends_with_typed_errors_until_restored) {
  auto before = collected->size();
  net.cut(can_bus); // the cable is pulled: the sensor has no route left
  net.advance(2s);
  EXPECT_EQ(collected->size(), before);
  ASSERT_FALSE(seen->errors.empty());
  // First no_route; once the collector's module has stayed unreachable past
  // the grace period (1 s), the rebinding proxy lets go of it: apo_gone.
  EXPECT_TRUE(is(seen->errors.front(), routing_ec::no_route))
    << render(seen->errors.front());
  EXPECT_TRUE(is(seen->errors.back(), app_ec::apo_gone))
    << render(seen->errors.back());
  // The cable is back: the channel reopens at its next retry, routes
  // return, the proxy finds the collector again, readings flow.
  net.restore(can_bus);
  auto restored = now();
  ASSERT_TRUE(advance_until(5s, [&] { return collected->size() > before; }));
  EXPECT_LE(now() - restored, 3s);
  auto resumed = collected->size();
  net.advance(1s);
  EXPECT_EQ(collected->size() - resumed, 10u);
}
// [cut-end]

// [kill]
TEST_F(sonar_test, killing_the_router_ends_a_proxy_and_its_monitor_hears_why) {
  // The controller binds to the sonar without rebinding and watches the
  // proxy: a monitor on a proxy works as on any actor.
  auto proxy = bind_apo(net, controller,
                        bind_request{query_by::name, "sonar", 300, false});
  ASSERT_TRUE(proxy) << render(proxy.error());
  auto downs = watch(*proxy);
  net.kill(router); // no goodbye: hellos stop, routes expire
  net.advance(3s);
  ASSERT_EQ(downs->size(), 1u);
  EXPECT_EQ(downs->front().source, proxy->address());
  EXPECT_TRUE(is(downs->front().reason, routing_ec::no_route))
    << render(downs->front().reason);
  // The router restarts; the sonar's rebinding proxy carries on.
  auto before = collected->size();
  net.start_module(router);
  EXPECT_TRUE(advance_until(5s, [&] { return collected->size() > before; }));
}
// [kill-end]

// [restart]
TEST_F(sonar_test, a_restarted_sensor_module_brings_a_new_sonar) {
  ASSERT_EQ(net.at(sensor).apos.size(), 1u);
  auto first = net.at(sensor).apos.front();
  net.kill(sensor); // the sonar dies with its module
  net.advance(2s);
  auto before = collected->size();
  net.advance(1s);
  EXPECT_EQ(collected->size(), before);
  // The start hook spawns and registers a new sonar, which counts from 1.
  net.start_module(sensor);
  ASSERT_TRUE(advance_until(5s, [&] { return collected->size() > before; }));
  EXPECT_EQ(collected->back().seq, 1u);
  ASSERT_EQ(net.at(sensor).apos.size(), 1u);
  EXPECT_EQ(net.at(sensor).apos.front().name, "sonar");
  EXPECT_NE(net.at(sensor).apos.front().apo, first.apo);
}
// [restart-end]
