// Deterministic actor-level simulations of the Network Adaptation Layer:
// modules (IO manager + routing agent) joined by in-process links with the
// profiles of Table 1, under CAF's test_coordinator. Converged routes are
// checked against shortest paths computed independently here (Dijkstra over
// the class-0 link costs), and a packet-path checker asserts that no packet
// ever visits a module twice.

#include <queue>
#include <random>

#include "tests/support/null_frame_handler.hpp"
#include "tests/support/topology.hpp"
#include "tests/support/actor_fixture.hpp"
#include "actors/testing/sim_network.hpp"
#include "channels/lax_timer.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

class routing_sim : public actor_fixture {
public:
  sim_network build(const topology& t) {
    sim_network net{*this, test_prefix()};
    for (size_t i = 0; i < t.n; ++i)
      net.add_module(id_of(i));
    for (auto& [members, kind] : t.links)
      net.connect(members, kind);
    net.start();
    return net;
  }

  /// Every module's selected class-0 route to every other module has the
  /// shortest-path cost. Returns the number of mismatches (0 when right).
  size_t check_costs(sim_network& net, const topology& t,
                     const std::vector<bool>& link_up = {}) {
    size_t wrong = 0;
    for (size_t a = 0; a < t.n; ++a) {
      auto dist = shortest(t, a, link_up);
      std::map<module_id, uint32_t> selected;
      for (auto& r : net.routes(a))
        if (r.size_class == 0 && r.selected)
          selected[r.destination] = r.cost;
      for (size_t b = 0; b < t.n; ++b) {
        if (a == b)
          continue;
        auto i = selected.find(id_of(b));
        bool ok = dist[b] == UINT64_MAX
                    ? i == selected.end()
                    : i != selected.end() && i->second == dist[b];
        if (!ok && ++wrong <= 5)
          ADD_FAILURE() << "module " << to_hex(id_of(a)) << " -> "
                        << to_hex(id_of(b)) << ": expected cost "
                        << (dist[b] == UINT64_MAX ? std::string{"unreachable"}
                                                  : std::to_string(dist[b]))
                        << ", got "
                        << (i == selected.end() ? std::string{"no route"}
                                                : std::to_string(i->second));
      }
    }
    return wrong;
  }

  /// Sends packets between `pairs` random pairs; all must arrive, no loops.
  void check_traffic(sim_network& net, const topology& t_, size_t pairs,
                     uint64_t seed) {
    std::mt19937_64 rng{seed};
    std::uniform_int_distribution<size_t> pick{0, net.size() - 1};
    size_t sent = 0;
    std::vector<size_t> before(net.size());
    for (size_t i = 0; i < net.size(); ++i)
      before[i] = net.at(i).received->size();
    std::map<size_t, size_t> expected;
    for (size_t k = 0; k < pairs; ++k) {
      auto a = pick(rng), b = pick(rng);
      if (a == b || shortest(t_, a)[b] == UINT64_MAX)
        continue;
      auto got = net.at(b).received->size();
      auto size = 8 + (k % 3) * 500;
      auto tag = net.send(a, id_of(b), size);
      ++expected[b];
      ++sent;
      if (net.at(b).received->size() == got) {
        std::string path;
        for (auto m : net.path(tag))
          path += to_hex(m) + " ";
        auto st = net.stats(a);
        ADD_FAILURE() << "packet of " << size << " bytes from " << to_hex(id_of(a))
                      << " to " << to_hex(id_of(b)) << " lost; path " << path
                      << "; source no_route " << st.dropped_no_route;
      }
    }
    for (auto [b, count] : expected)
      EXPECT_EQ(net.at(b).received->size() - before[b], count)
        << "module " << to_hex(id_of(b));
    EXPECT_EQ(net.loops(), 0u);
  }
};

/// Fires every timer due within `span` from now `late` after its time (as
/// a lax timer may on the loop scheduler), running the actors after each.
/// Returns the number fired.
size_t fire_timers_late(sim_network& net, caf::timespan span,
                        caf::timespan late) {
  auto& h = net.harness();
  auto& clk = h.sched.clock();
  auto end = clk.current_time + span;
  size_t fired = 0;
  h.sched.run();
  while (!clk.schedule().empty() && clk.schedule().begin()->first + late <= end) {
    clk.current_time = std::max(clk.current_time,
                                clk.schedule().begin()->first + late);
    clk.trigger_timeout();
    h.sched.run();
    ++fired;
  }
  clk.current_time = end;
  return fired;
}

/// What module 0 of `net` sent while every timer due within 20 hello
/// intervals (plus `late`) fired `late` after its time.
struct timed_run {
  uint64_t hellos = 0;
  size_t timers = 0;
};

timed_run hellos_over_20_intervals(sim_network& net, caf::timespan late) {
  auto interval = caf::timespan{net.at(0).cfg.hello_interval};
  auto before = net.stats(0).tx_hellos;
  timed_run result;
  result.timers = fire_timers_late(net, 20 * interval + late, late);
  result.hellos = net.stats(0).tx_hellos - before;
  return result;
}

} // namespace

TEST_F(routing_sim, two_modules_learn_routes_to_each_other) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  net.advance(500ms);
  auto r = net.route(0, id_of(1));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->cost, 10u);
  EXPECT_EQ(r->hops, 1u);
  EXPECT_EQ(r->forwarding, "Ethernet");
  check_traffic(net, t, 10, 1);
}

// A module that joins hears nothing from its neighbour until the
// neighbour's next hello, but the neighbour, having heard the joiner's
// hello, sends it everything it knows at once. That update counts as the
// neighbour's first sign: the joiner has a route back within a round trip,
// not a hello interval later (meanwhile a plain request would be refused
// for no route: three sonar batches lost in avr_hermd). No packet is added
// for it: no answering hello.
TEST_F(routing_sim, a_joining_module_takes_its_neighbours_update_as_its_first_hello) {
  sim_network net{*this, test_prefix()}; // hellos every 100 ms
  auto a = net.add_module(id_of(0));
  auto b = net.add_module(id_of(1));
  auto c = net.add_module(id_of(2));
  net.connect({a, b}, "ethernet");
  net.connect({a, c}, "ethernet");
  net.start_module(a);
  net.start_module(c);
  net.advance(40ms); // a's and c's first hellos
  ASSERT_TRUE(net.route(a, id_of(2)));
  auto a_hellos = net.stats(a).tx_hellos;
  ASSERT_GE(a_hellos, 1u);
  net.start_module(b);
  net.advance(20ms); // b's first hello, 60 ms before a's next one
  auto to_a = net.route(b, id_of(0));
  ASSERT_TRUE(to_a) << "b has no route to a before a's next hello";
  EXPECT_EQ(to_a->hops, 1u);
  EXPECT_TRUE(net.route(a, id_of(1)));
  // And a's update brought the rest of the network with it.
  auto to_c = net.route(b, id_of(2));
  ASSERT_TRUE(to_c);
  EXPECT_EQ(to_c->hops, 2u);
  EXPECT_EQ(net.stats(b).rx_unknown_neighbour, 0u);
  EXPECT_EQ(net.stats(a).tx_hellos, a_hellos) << "no answering hello";
  // a's next hello changes nothing: b already holds it.
  net.advance(100ms);
  EXPECT_EQ(net.route(b, id_of(0))->hops, 1u);
  EXPECT_EQ(net.stats(b).rx_unknown_neighbour, 0u);
}

TEST_F(routing_sim, the_paper_testbed_routes_by_cost_and_size) {
  // Sensor 0x40, main controller 0x4E, vision 0x30, mobile 0x50 (Fig. 5):
  // RS232C sensor-main, IEEE 1394 vision-mobile, Ethernet mobile-main and a
  // CAN bus joining main, mobile and sensor.
  sim_network net{*this, test_prefix()};
  auto sensor = net.add_module(0x40);
  auto main = net.add_module(0x4E);
  auto vision = net.add_module(0x30);
  auto mobile = net.add_module(0x50);
  net.connect({sensor, main}, "rs232c");
  net.connect({vision, mobile}, "ieee1394a");
  auto eth = net.connect({mobile, main}, "ethernet");
  net.connect({main, mobile, sensor}, "can2.0");
  net.start();
  net.advance(1s);
  // Vision reaches the main controller through mobile: 1394 (4) + Ethernet (10).
  auto r = net.route(vision, 0x4E);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->cost, 14u);
  EXPECT_EQ(r->hops, 2u);
  EXPECT_EQ(r->forwarding, "IEEE1394a-Ethernet");
  auto tag = net.send(vision, 0x4E, 100);
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{0x30, 0x50, 0x4E}));
  ASSERT_EQ(net.at(main).received->size(), 1u);
  EXPECT_EQ(net.at(main).received->back().src, 0x30);
  EXPECT_EQ(net.at(main).received->back().hops, 2u);
  EXPECT_EQ(net.stats(vision).forwarded, 0u);
  EXPECT_EQ(net.stats(vision).originated, 1u);
  EXPECT_EQ(net.stats(mobile).forwarded, 1u);
  // Small sensor messages take the CAN bus (30 < 47); a 1,000-byte batch
  // takes RS232C (47 x 32 frames = 1,504 < 30 x 128 frames = 3,840).
  auto small = net.route(sensor, 0x4E, 0);
  ASSERT_TRUE(small);
  EXPECT_EQ(small->forwarding, "CAN2.0");
  auto large = net.route(sensor, 0x4E, size_class_of(1000));
  ASSERT_TRUE(large);
  EXPECT_EQ(large->forwarding, "RS232C");
  EXPECT_EQ(large->cost, 1504u);
  // Ethernet goes down: vision's traffic moves to the CAN path via mobile.
  net.cut(eth);
  net.advance(300ms);
  r = net.route(vision, 0x4E);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->forwarding, "IEEE1394a-CAN2.0");
  EXPECT_EQ(r->cost, 34u);
  tag = net.send(vision, 0x4E, 100);
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{0x30, 0x50, 0x4E}));
  EXPECT_EQ(net.at(main).received->size(), 2u);
  EXPECT_EQ(net.loops(), 0u);
}

TEST_F(routing_sim, an_unknown_destination_is_a_typed_error) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  net.advance(500ms);
  auto res = call<>(net.at(0).agent, atom::send_v,
                    send_packet{0x999, 0, prio_normal, byte_buffer(4)});
  ASSERT_FALSE(res);
  EXPECT_TRUE(is(res.error(), routing_ec::no_route));
  EXPECT_NE(render(res.error()).find("0x999"), std::string::npos);
  auto ok = call<>(net.at(0).agent, atom::send_v,
                   send_packet{id_of(1), 0, prio_normal, byte_buffer(4)});
  EXPECT_TRUE(ok);
}

struct topo_case {
  const char* name;
  topology (*make)();
  std::chrono::milliseconds settle;
};

class routing_topologies : public routing_sim,
                           public ::testing::WithParamInterface<topo_case> {};

TEST_P(routing_topologies, converge_to_shortest_paths_without_loops) {
  auto t = GetParam().make();
  auto net = build(t);
  net.advance(GetParam().settle);
  EXPECT_EQ(check_costs(net, t), 0u);
  check_traffic(net, t, std::min<size_t>(t.n * 2, 200), 7);
}

INSTANTIATE_TEST_SUITE_P(
  routing_sim, routing_topologies,
  ::testing::Values(
    topo_case{"line10", [] { return line(10, true); }, 2s},
    topo_case{"ring10", [] { return ring(10, true); }, 2s},
    topo_case{"star10", [] { return star(10, true); }, 2s},
    topo_case{"grid10", [] { return grid(5, 2, true); }, 2s},
    topo_case{"mesh10", [] { return mesh(10, 1); }, 2s},
    topo_case{"line100", [] { return line(100, false); }, 5s},
    topo_case{"ring100", [] { return ring(100, false); }, 5s},
    topo_case{"star100", [] { return star(100, true); }, 3s},
    topo_case{"grid100", [] { return grid(10, 10, true); }, 5s},
    topo_case{"mesh100", [] { return mesh(100, 2); }, 5s}),
  [](const auto& param_info) { return std::string{param_info.param.name}; });

TEST_F(routing_sim, traffic_moves_to_the_alternate_path_and_back) {
  auto t = ring(6, false);
  auto net = build(t);
  net.advance(1s);
  // 0 -> 2 goes 0-1-2 (2 hops) rather than 0-5-4-3-2.
  auto tag = net.send(0, id_of(2));
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(0), id_of(1), id_of(2)}));
  net.cut(0); // link 0-1
  net.advance(200ms); // two hello intervals
  tag = net.send(0, id_of(2));
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(0), id_of(5), id_of(4),
                                                   id_of(3), id_of(2)}));
  std::vector<bool> up(t.links.size(), true);
  up[0] = false;
  EXPECT_EQ(check_costs(net, t, up), 0u);
  net.restore(0);
  net.advance(2s); // channel retry backoff, hellos, updates
  tag = net.send(0, id_of(2));
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(0), id_of(1), id_of(2)}));
  EXPECT_EQ(check_costs(net, t), 0u);
  EXPECT_EQ(net.loops(), 0u);
}

TEST_F(routing_sim, a_dead_module_disappears_from_every_table_and_returns) {
  auto t = grid(3, 3, false);
  auto net = build(t);
  net.advance(1s);
  ASSERT_EQ(check_costs(net, t), 0u);
  net.kill(4); // the centre
  net.advance(2s); // lost hellos, retractions, expiry
  for (size_t i = 0; i < t.n; ++i) {
    if (i != 4) {
      EXPECT_FALSE(net.route(i, id_of(4))) << "module " << i;
    }
  }
  // Traffic between corners still flows, around the centre.
  auto tag = net.send(0, id_of(8));
  EXPECT_EQ(net.path(tag).size(), 5u);
  net.start_module(4);
  net.advance(2s);
  EXPECT_EQ(check_costs(net, t), 0u);
  EXPECT_EQ(net.loops(), 0u);
}

TEST_F(routing_sim, dynamic_addresses_are_unique_across_several_hops) {
  sim_network net{*this, test_prefix()};
  for (size_t i = 0; i < 12; ++i)
    net.add_module(no_module, 1000 + i);
  for (size_t i = 0; i + 1 < 12; ++i)
    net.connect({i, i + 1}, i % 2 == 0 ? "ethernet" : "can2.0");
  net.start();
  net.advance(3s);
  std::set<module_id> ids;
  for (size_t i = 0; i < 12; ++i) {
    auto st = net.stats(i);
    EXPECT_TRUE(st.assigned) << i;
    EXPECT_GE(st.self, first_dynamic_module);
    ids.insert(st.self);
  }
  EXPECT_EQ(ids.size(), 12u);
  // And they route to each other.
  auto far = net.stats(11).self;
  net.send(0, far, 8);
  EXPECT_EQ(net.at(11).received->size(), 1u);
}

TEST_F(routing_sim, two_modules_claiming_the_same_id_at_once_end_with_different_ids) {
  sim_network net{*this, test_prefix()};
  // The same seed makes both pick the same first id.
  auto a = net.add_module(no_module, 4242);
  auto b = net.add_module(no_module, 4242);
  auto c = net.add_module(0x4E);
  net.connect({a, c}, "ethernet");
  net.connect({c, b}, "can2.0");
  net.start();
  net.advance(3s);
  auto sa = net.stats(a), sb = net.stats(b);
  EXPECT_TRUE(sa.assigned);
  EXPECT_TRUE(sb.assigned);
  // Same seed, same first pick: one of them lost the claim and picked
  // again before it was assigned (not a renumbering: it never held the id).
  EXPECT_NE(sa.self, sb.self);
  EXPECT_GT(sa.tx_claims + sb.tx_claims, 6u);
}

TEST_F(routing_sim, merging_partitions_that_hold_the_same_id_renumber_one_side) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(no_module, 99);
  auto a2 = net.add_module(0x4E);
  auto b = net.add_module(no_module, 99);
  auto b2 = net.add_module(0x50);
  net.connect({a, a2}, "ethernet");
  net.connect({b, b2}, "ethernet");
  auto bridge = net.connect({a2, b2}, "ethernet");
  net.cut(bridge);
  net.start();
  net.advance(3s);
  auto before_a = net.stats(a).self, before_b = net.stats(b).self;
  ASSERT_EQ(before_a, before_b); // two partitions, one id
  net.restore(bridge);
  // The bridge's channels retry with backoff (up to 5 s), then the next
  // announcement (every 10 hello intervals) meets the other holder.
  net.advance(10s);
  auto sa = net.stats(a), sb = net.stats(b);
  EXPECT_NE(sa.self, sb.self);
  EXPECT_EQ(sa.renumberings + sb.renumberings, 1u);
  // The renumbered side's old id is gone from the far side's table, and
  // both are reachable under their new ids.
  net.send(a2, sb.self, 8);
  net.send(b2, sa.self, 8);
  EXPECT_EQ(net.at(b).received->size(), 1u);
  EXPECT_EQ(net.at(a).received->size(), 1u);
}

TEST_F(routing_sim, malformed_routing_packets_are_counted_and_ignored) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  net.advance(500ms);
  // A raw station on module 1's segment speaks garbage.
  device_config dev{"raw", "inproc", test_prefix() + "-l0", {{"station", "9"}}};
  auto drv = find_link_kind("inproc")->open(dev);
  ASSERT_TRUE(drv);
  (*drv)->start(std::make_shared<null_frame_handler>());
  // Single-frame packets (fragment header 0x00): bad version, truncated
  // update, truncated hello.
  const uint8_t bad_version[] = {0x00, 0x72, 1, 2};
  const uint8_t short_update[] = {0x00, 0x12, 0x01};
  const uint8_t short_hello[] = {0x00, 0x11, 0x01, 0x00};
  for (auto* p : {bad_version, short_update, short_hello})
    (*drv)->send(broadcast_addr, p, p == bad_version ? 4 : p == short_update ? 3 : 4, 0);
  run();
  EXPECT_GE(net.stats(0).rx_malformed + net.stats(1).rx_malformed, 6u);
  (*drv)->stop();
  // Routing still works.
  check_traffic(net, t, 4, 3);
}

// -- flooded broadcasts ----------------------------------------------------------

TEST_F(routing_sim, a_broadcast_reaches_every_other_module_exactly_once) {
  // A 3x3 grid with mixed link kinds has many paths between any two
  // modules; every module but the sender must get the packet once.
  auto t = grid(3, 3, true);
  auto net = build(t);
  net.advance(1s);
  std::vector<size_t> before(t.n);
  for (size_t i = 0; i < t.n; ++i)
    before[i] = net.at(i).received->size();
  net.send(4, broadcast_module, 40);
  for (size_t i = 0; i < t.n; ++i) {
    auto got = net.at(i).received->size() - before[i];
    EXPECT_EQ(got, i == 4 ? 0u : 1u) << "module " << to_hex(id_of(i));
    if (got == 1) {
      auto& p = net.at(i).received->back();
      EXPECT_EQ(p.src, id_of(4));
      EXPECT_EQ(p.payload.size(), 40u);
      EXPECT_GE(p.hops, 1u);
    }
  }
  uint64_t relayed = 0, duplicates = 0;
  for (size_t i = 0; i < t.n; ++i) {
    relayed += net.stats(i).broadcasts_relayed;
    duplicates += net.stats(i).dropped_duplicate;
  }
  // Each of the 8 receivers relays once; the copies that meet on the way are
  // suppressed, not delivered.
  EXPECT_EQ(relayed, 8u);
  EXPECT_GT(duplicates, 0u);
  EXPECT_EQ(net.stats(4).broadcasts_originated, 1u);
  EXPECT_EQ(net.loops(), 0u);
}

TEST_F(routing_sim, a_broadcast_crosses_buses_and_small_mtu_links) {
  // 0 -CAN bus- {1, 2}, 2 -RS232C- 3: relayed across a bus and re-fragmented.
  topology t{4, {{{0, 1, 2}, "can2.0"}, {{2, 3}, "rs232c"}}};
  auto net = build(t);
  net.advance(2s);
  net.send(0, broadcast_module, 200);
  for (size_t i = 1; i < 4; ++i) {
    ASSERT_EQ(net.at(i).received->size(), 1u) << "module " << i;
    EXPECT_EQ(net.at(i).received->back().payload.size(), 200u);
  }
  EXPECT_EQ(net.at(3).received->back().hops, 2u);
  EXPECT_EQ(net.at(0).received->size(), 0u);
}

TEST_F(routing_sim, a_broadcast_stops_at_its_hop_limit) {
  // A line of 40 modules: the default hop limit (32) ends the flood.
  auto t = line(40, false);
  sim_network net{*this, test_prefix(), 1000ms};
  for (size_t i = 0; i < t.n; ++i)
    net.add_module(id_of(i));
  for (auto& [members, kind] : t.links)
    net.connect(members, kind);
  net.start();
  net.advance(3s);
  net.send(0, broadcast_module, 16);
  size_t reached = 0;
  for (size_t i = 1; i < t.n; ++i)
    reached += net.at(i).received->size();
  EXPECT_EQ(reached, size_t{default_hop_limit});
  EXPECT_EQ(net.at(32).received->size(), 1u);
  EXPECT_EQ(net.at(33).received->size(), 0u);
}

// -- route listeners --------------------------------------------------------------

namespace {

using reach_log = std::vector<reachability>;

route_listener_actor spawn_reach_probe(actor_fixture& fx,
                                       std::shared_ptr<reach_log> log) {
  return fx.track(fx.sys().spawn(
    [log](route_listener_actor::pointer) -> route_listener_actor::behavior_type {
      return {[log](reachability& x) { log->push_back(x); }};
    }));
}

} // namespace

TEST_F(routing_sim, route_listeners_learn_reachability_changes) {
  auto t = line(3, false); // 0 - 1 - 2
  auto net = build(t);
  net.advance(1s);
  auto log = std::make_shared<reach_log>();
  auto probe = spawn_reach_probe(*this, log);
  caf::anon_send(net.at(0).agent, atom::subscribe_v, atom::routes_v, probe);
  run();
  // The current table first: both others reachable.
  ASSERT_EQ(log->size(), 2u);
  std::map<module_id, reachability> now;
  for (auto& r : *log)
    now[r.id] = r;
  EXPECT_TRUE(now[id_of(1)].reachable);
  EXPECT_EQ(now[id_of(1)].hops, 1u);
  EXPECT_TRUE(now[id_of(2)].reachable);
  EXPECT_EQ(now[id_of(2)].hops, 2u);
  EXPECT_EQ(now[id_of(2)].cost, 20u);
  log->clear();
  net.kill(2);
  net.advance(1s);
  ASSERT_EQ(log->size(), 1u);
  reachability withdrawn;
  withdrawn.id = id_of(2);
  withdrawn.was_reachable = true;
  withdrawn.old_cost = 20;
  // What the route was: through module 1, on the device it was told with.
  withdrawn.old_next = id_of(1);
  withdrawn.old_device = now[id_of(2)].device;
  EXPECT_FALSE(withdrawn.old_device.empty());
  EXPECT_EQ(log->back(), withdrawn);
  log->clear();
  net.start_module(2);
  net.advance(1s);
  ASSERT_EQ(log->size(), 1u);
  EXPECT_EQ(log->back().id, id_of(2));
  EXPECT_TRUE(log->back().reachable);
  // A second listener starts from the same view.
  auto log2 = std::make_shared<reach_log>();
  auto probe2 = spawn_reach_probe(*this, log2);
  caf::anon_send(net.at(0).agent, atom::subscribe_v, atom::routes_v, probe2);
  run();
  EXPECT_EQ(log2->size(), 2u);
}

// Neighbours with different hello intervals: the middle module says hellos
// (and re-advertises its routes) five times less often than the ends. A
// route learned from it must hold between two of its updates: held for the
// receiver's own, shorter update period, module 0's route to module 2
// expired and came back every two seconds (seen with a slow hermd between
// a fast one and a board).
TEST_F(routing_sim, routes_from_a_neighbour_with_slower_hellos_hold_between_its_updates) {
  auto t = line(3, false); // 0 - 1 - 2
  sim_network net{*this, test_prefix()};
  for (size_t i = 0; i < t.n; ++i)
    net.add_module(id_of(i));
  net.at(1).cfg.hello_interval = 500ms;
  for (auto& [members, kind] : t.links)
    net.connect(members, kind);
  net.start();
  net.advance(3s);
  ASSERT_TRUE(net.route(0, id_of(2)));
  auto log = std::make_shared<reach_log>();
  auto probe = spawn_reach_probe(*this, log);
  caf::anon_send(net.at(0).agent, atom::subscribe_v, atom::routes_v, probe);
  run();
  log->clear(); // the current table
  // Ten of the middle module's update periods (4 hellos of 500 ms each).
  for (int i = 0; i < 100; ++i)
    net.advance(200ms);
  for (auto& r : *log)
    ADD_FAILURE() << "route to " << to_hex(r.id) << " changed: reachable "
                  << r.reachable << ", was " << r.was_reachable;
  EXPECT_TRUE(net.route(0, id_of(2)));
}

// On the loop scheduler the quarter tick is a lax timer: it may fire up to
// its slack late (an eighth of a quarter interval, at most 20 ms). Here
// every timer fires that late. The next tick counts from when the last one
// was due, so the hellos keep their interval; counted from when it fired,
// each interval would grow by four slacks (12.5 %) and 20 intervals would
// see 17 hellos.
TEST_F(routing_sim, late_quarter_ticks_do_not_stretch_the_hello_interval) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  auto interval = caf::timespan{net.at(0).cfg.hello_interval};
  auto late = lax_slack(interval / 4);
  ASSERT_GT(late, interval / 40);
  auto run = hellos_over_20_intervals(net, late);
  EXPECT_EQ(run.hellos, 20u);
  EXPECT_TRUE(net.route(0, id_of(1)));
}

// Between hellos the tick runs only when something is due (a neighbour
// about to be lost, a route about to expire, the address allocator): an
// idle module with a live neighbour ticks once or twice per hello
// interval, not four times. (Here the second: both modules say hello at
// the same instant, so at its hello tick a module still has the
// neighbour's hello of an interval ago, which would expire before its next
// hello; the check a quarter later finds it refreshed.)
TEST_F(routing_sim, an_idle_module_ticks_at_most_twice_per_hello_interval) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  net.advance(3s); // addresses claimed, routes learned
  auto run = hellos_over_20_intervals(net, caf::timespan{0});
  EXPECT_EQ(run.hellos, 20u);
  // Two modules, 20 intervals: 40 hello ticks and at most 40 checks
  // between them; quarter ticks would be 160.
  EXPECT_LE(run.timers, 80u);
  EXPECT_TRUE(net.route(0, id_of(1)));
}

// The tick runs only at hellos and deadlines now, yet a silently failed
// link is still noticed within 1.75 hello intervals of the last hello (plus
// the tick's slack), whenever in the interval it fails and with every timer
// firing its slack late. The route through the link goes with it.
TEST_F(routing_sim, a_silent_neighbour_is_lost_within_1_75_intervals_with_late_ticks) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  auto interval = caf::timespan{net.at(0).cfg.hello_interval};
  auto late = lax_slack(interval / 4);
  auto step = interval / 40;
  /// Fires timers late, a step at a time, until the route from module 0 to
  /// module 1 is `up` or `most` passed; returns how long it took.
  auto until_route = [&](bool up, caf::timespan most) {
    caf::timespan waited{0};
    while (net.route(0, id_of(1)).has_value() != up && waited < most) {
      fire_timers_late(net, step, late);
      waited += step;
    }
    return waited;
  };
  fire_timers_late(net, 3 * interval, late);
  // Failing k/8 of an interval after the route came back: k = 0..7 covers
  // every eighth of the hello interval (the route comes back in steps).
  for (int k = 0; k < 8; ++k) {
    SCOPED_TRACE("failure " + std::to_string(k));
    ASSERT_TRUE(net.route(0, id_of(1)));
    fire_timers_late(net, interval + interval * k / 8, late);
    net.silence(0);
    auto waited = until_route(false, 3 * interval);
    // The loss follows the last hello, which came before the failure, by
    // at most 1.75 intervals plus the tick's slack.
    EXPECT_FALSE(net.route(0, id_of(1)));
    EXPECT_LE(waited, interval * 7 / 4 + late + step);
    net.restore(0);
    until_route(true, 10 * interval);
  }
}

// A module that leaves cleanly says goodbye: its neighbours drop it and the
// modules beyond them lose their routes to it at once, in zero simulated
// time, instead of after 1.5 silent hello intervals.
TEST_F(routing_sim, a_goodbye_withdraws_a_module_at_once) {
  topology t{3, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}}};
  auto net = build(t);
  net.advance(1s);
  ASSERT_TRUE(net.route(0, id_of(2)));
  ASSERT_TRUE(net.route(1, id_of(2)));
  auto done = call<>(net.at(2).agent, atom::close_v);
  ASSERT_TRUE(done);
  run(); // no time passes
  EXPECT_FALSE(net.route(1, id_of(2)));
  EXPECT_FALSE(net.route(0, id_of(2)));
  EXPECT_TRUE(net.route(0, id_of(1)));
  EXPECT_EQ(net.stats(1).rx_goodbyes, 1u);
  // It sends no more hellos: it stays gone.
  net.advance(1s);
  EXPECT_FALSE(net.route(0, id_of(2)));
}

// A goodbye names an instance: one from a previous life of a module that
// already restarted is ignored.
TEST_F(routing_sim, a_goodbye_from_another_instance_is_ignored) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  net.advance(500ms);
  hello bye{id_of(1), 12345, 0, 0};
  byte_buffer bytes;
  encode(bye, bytes);
  auto ch = net.route(0, id_of(1))->channel;
  caf::anon_send(net.at(0).agent, packet_received{ch, 2, bytes});
  run();
  EXPECT_TRUE(net.route(0, id_of(1)));
  EXPECT_EQ(net.stats(0).rx_goodbyes, 0u);
}

// The joiner's hellos are five times as frequent as its neighbour's. It
// hears the neighbour's update first, and the neighbour's next hello comes
// up to 500 ms later: held for the joiner's own interval (150 ms at its
// hello loss), the neighbour would be lost before that hello and come back
// with it, and every binding through it with it (seen as proxies ending in
// board_hermd). So it is held for its first hello.
TEST_F(routing_sim, a_neighbour_met_by_its_update_is_held_until_its_slower_hello) {
  sim_network net{*this, test_prefix()}; // hellos every 100 ms
  auto slow = net.add_module(id_of(0));
  auto fast = net.add_module(id_of(1));
  net.at(slow).cfg.hello_interval = 500ms;
  net.connect({slow, fast}, "ethernet");
  net.start_module(slow);
  net.advance(250ms); // slow's first hello went out to nobody
  net.start_module(fast);
  net.advance(20ms);
  ASSERT_TRUE(net.route(fast, id_of(0))) << "met by its update";
  // Until slow's next hello (at 500 ms) and beyond, the route stays.
  for (int i = 0; i < 30; ++i) {
    net.advance(20ms);
    ASSERT_TRUE(net.route(fast, id_of(0))) << "lost after " << 20 * (i + 2)
                                           << " ms";
  }
}

// An update heard before any hello makes its sender a neighbour, but not
// once the sender said goodbye in that life: an update it sent before its
// goodbye and that arrives after it (another priority lane) is dropped as
// from a stranger. A hello of a new life brings it back.
TEST_F(routing_sim, an_update_after_its_senders_goodbye_does_not_bring_it_back) {
  topology t{2, {{{0, 1}, "ethernet"}}};
  auto net = build(t);
  net.advance(500ms);
  auto ch = net.route(0, id_of(1))->channel;
  const link_addr stranger = 77;
  auto inject = [&](auto packet) {
    byte_buffer bytes;
    encode(packet, bytes);
    caf::anon_send(net.at(0).agent, packet_received{ch, stranger, bytes});
    run();
  };
  auto holds_stranger = [&] {
    auto res = call<std::vector<neighbour_info>>(net.at(0).agent, atom::get_v,
                                                 atom::neighbors_v);
    if (!res)
      return false;
    for (auto& n : std::get<0>(*res))
      if (n.id == 0x77 && n.instance != 0)
        return true;
    return false;
  };
  update early{0x77, 5, {}};
  inject(early);
  EXPECT_TRUE(holds_stranger()) << "an update is a sign of the link";
  inject(hello{0x77, 5, 0, 0}); // goodbye
  EXPECT_FALSE(holds_stranger());
  auto unknown = net.stats(0).rx_unknown_neighbour;
  inject(early); // overtaken by the goodbye
  EXPECT_FALSE(holds_stranger());
  EXPECT_EQ(net.stats(0).rx_unknown_neighbour, unknown + 1);
  inject(update{0x77, 6, {}}); // restarted: a new life
  EXPECT_TRUE(holds_stranger());
}

// The tracer sees a packet leave, cross the router (re-fragmented for the
// smaller MTU) and arrive, with link kinds, next hops and the route's cost.
TEST_F(routing_sim, the_tracer_follows_a_packet_hop_by_hop) {
  sim_network net{*this, test_prefix()};
  std::vector<packet_trace> seen;
  for (size_t i = 0; i < 3; ++i) {
    net.add_module(id_of(i));
    net.at(i).cfg.tracer = [&seen](const packet_trace& t) { seen.push_back(t); };
  }
  net.connect({0, 1}, "ethernet");
  net.connect({1, 2}, "can2.0");
  net.start();
  net.advance(1s);
  seen.clear();
  net.send(0, id_of(2), 40);
  ASSERT_EQ(seen.size(), 3u);
  EXPECT_EQ(seen[0].what, packet_trace::originated);
  EXPECT_EQ(seen[0].self, id_of(0));
  EXPECT_EQ(seen[0].out_link, "ethernet");
  EXPECT_EQ(seen[0].next, id_of(1));
  EXPECT_EQ(seen[0].forwarding, "Ethernet-CAN2.0");
  EXPECT_EQ(seen[1].what, packet_trace::forwarded);
  EXPECT_EQ(seen[1].in_link, "ethernet");
  EXPECT_EQ(seen[1].out_link, "can2.0");
  EXPECT_EQ(seen[1].out_mtu, 8u);
  EXPECT_EQ(seen[1].next, id_of(2));
  EXPECT_EQ(seen[1].forwarding, "CAN2.0");
  EXPECT_EQ(seen[2].what, packet_trace::delivered);
  EXPECT_EQ(seen[2].self, id_of(2));
  EXPECT_EQ(seen[2].in_link, "can2.0");
  EXPECT_EQ(seen[2].src, id_of(0));
  EXPECT_GT(seen[0].cost, seen[1].cost);
  EXPECT_EQ(seen[0].bytes, seen[2].bytes);
}
