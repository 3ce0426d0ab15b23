// The routing agent against hostile or broken neighbours, under CAF's
// test_coordinator: every piece of its state that grows with what
// neighbours send has a bound (routing_config), the excess is refused or
// forgotten and counted in routing_stats, and real neighbours keep being
// served. Route listeners learn each change of a selected route from one
// event that says everything about it, coalesced per burst, and a late
// listener gets the current state, never a history. A "tap" is a station
// the test drives by hand on a link of the network (no key: a fake
// neighbour on an open network).

#include "tests/support/actor_fixture.hpp"
#include "actors/testing/sim_network.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

template <class T>
byte_buffer encoded(const T& packet) {
  byte_buffer b;
  encode(packet, b);
  return b;
}

/// `origin` advertised with the same metric in every class, reached through
/// `path` behind the advertising neighbour.
advertised entry(module_id origin, seqno_t seqno, metric m,
                 std::vector<link_code> path = {}) {
  advertised a;
  a.origin = origin;
  a.seqno = seqno;
  a.metrics.fill(m);
  for (size_t k = 0; k < size_classes; ++k) {
    a.hops[k] = static_cast<uint8_t>(path.size());
    a.path[k] = path;
  }
  return a;
}

/// Update packets advertising origins first .. first + count - 1.
std::vector<byte_buffer> updates(module_id sender, module_id first,
                                 size_t count, seqno_t seqno, metric m) {
  std::vector<byte_buffer> out;
  update u{sender, 0x1234, {}};
  for (size_t i = 0; i < count; ++i) {
    u.entries.push_back(entry(static_cast<module_id>(first + i), seqno, m));
    if (u.entries.size() == max_update_entries || i + 1 == count) {
      out.push_back(encoded(u));
      u.entries.clear();
    }
  }
  return out;
}

byte_buffer hello_from(module_id id) {
  return encoded(hello{id, 0x1234, 1, 100});
}

using event_log = std::vector<reachability>;

class bounds_sim : public actor_fixture {
public:
  struct tap {
    channel_actor ch;
    std::shared_ptr<probe_log> log;
  };

  /// Opens a station on link `li` of `net` (before or after it starts).
  tap open_tap(sim_network& net, size_t li, link_addr station) {
    tap t;
    auto io = track(spawn_io_manager(sys()));
    device_config dev{"tap", "inproc", net.link_at(li).segment,
                      {{"profile", net.link_at(li).profile},
                       {"station", std::to_string(station)}}};
    EXPECT_TRUE(call<device_info>(io, atom::add_v, dev));
    auto opened = call<channel_actor, channel_info>(io, atom::open_v,
                                                    channel_request{"tap"});
    EXPECT_TRUE(opened);
    if (!opened)
      return t;
    t.ch = std::get<0>(*opened);
    auto [probe, log] = spawn_probe();
    t.log = log;
    EXPECT_TRUE(call<channel_info>(t.ch, atom::subscribe_v,
                                   caf::actor_cast<channel_reader_actor>(probe)));
    return t;
  }

  /// Broadcasts `bytes` from the tap on its link and runs every actor.
  void send(const tap& t, byte_buffer bytes) {
    caf::anon_send(t.ch, write_packet{broadcast_addr, prio_control,
                                      std::move(bytes)});
    run();
  }

  void send(const tap& t, const std::vector<byte_buffer>& packets) {
    for (auto& p : packets)
      send(t, p);
  }

  /// A route listener recording every event into the returned log.
  std::shared_ptr<event_log> listen(routing_agent_actor agent) {
    auto log = std::make_shared<event_log>();
    auto l = track(sys().spawn(
      [log](route_listener_actor::pointer) -> route_listener_actor::behavior_type {
        return {[log](reachability& x) { log->push_back(x); }};
      }));
    caf::anon_send(agent, atom::subscribe_v, atom::routes_v, l);
    run();
    return log;
  }

  size_t neighbours(sim_network& net, size_t i) {
    auto res = call<std::vector<neighbour_info>>(net.at(i).agent, atom::get_v,
                                                 atom::neighbors_v);
    return res ? std::get<0>(*res).size() : 0;
  }
};

/// Module a (0x10) between b (0x20, link 0) and c (0x30, link 1), both
/// Ethernet, and alone on link 2 (Ethernet) with whatever taps a test adds
/// there (a is station 1 on every link).
struct three {
  sim_network net;
  size_t a, b, c;

  three(bounds_sim& fx, const std::function<void(routing_config&)>& set = {},
        const std::string& suffix = {})
    : net(fx, test_prefix() + suffix) {
    a = net.add_module(0x10);
    b = net.add_module(0x20);
    c = net.add_module(0x30);
    net.connect({a, b}, "ethernet");
    net.connect({a, c}, "ethernet");
    net.connect({a}, "ethernet");
    if (set)
      set(net.at(a).cfg);
  }
};

} // namespace

// -- destinations -----------------------------------------------------------------

TEST_F(bounds_sim, a_neighbour_advertising_past_the_bounds_is_refused_and_real_routes_keep_working) {
  three x{*this, [](routing_config& cfg) { cfg.limits = route_limits{64, 32, 256}; }};
  auto& net = x.net;
  net.start();
  net.advance(1s);
  ASSERT_TRUE(net.route(x.a, 0x20));
  ASSERT_TRUE(net.route(x.a, 0x30));
  auto events = listen(net.at(x.a).agent);
  EXPECT_EQ(events->size(), 2u);
  // One fake neighbour: 200 destinations, 32 taken (its share).
  auto f1 = open_tap(net, 2, 9);
  send(f1, hello_from(0x66));
  send(f1, updates(0x66, 0x1000, 200, 1, 10));
  // (b and c echo what a advertises back to a: routes via them, within
  // their shares too, so counters may count more than the fake's excess.)
  auto st = net.stats(x.a);
  EXPECT_GE(st.rx_routes_over_share, 200u - 32u);
  EXPECT_EQ(st.rx_routes_over_limit, st.rx_routes_over_share);
  EXPECT_EQ(st.destinations, 2u + 32u);
  // A second one: the table fills up (64), the rest is refused.
  auto f2 = open_tap(net, 2, 10);
  send(f2, hello_from(0x67));
  // Refused by the total, not by a share (b's and c's echoes are).
  auto by_total = [](const routing_stats& s) {
    return s.rx_routes_over_limit - s.rx_routes_over_share;
  };
  auto before = by_total(net.stats(x.a));
  send(f2, updates(0x67, 0x2000, 200, 1, 10));
  st = net.stats(x.a);
  EXPECT_EQ(st.destinations, 64u);
  EXPECT_EQ(by_total(st) - before, 200u - 30u);
  EXPECT_LE(st.routes, 4 * 32u); // each neighbour's share
  // Listeners heard of what the table holds, not of what it refused.
  EXPECT_EQ(events->size(), 64u);
  // Sent again (periodic updates): refused again, nothing grows.
  send(f2, updates(0x67, 0x2000, 200, 1, 10));
  EXPECT_EQ(net.stats(x.a).destinations, 64u);
  EXPECT_EQ(by_total(net.stats(x.a)), by_total(st) + 170u);
  EXPECT_EQ(events->size(), 64u);
  // Real neighbours keep their routes, refreshed past the hold, and traffic.
  net.advance(3s);
  EXPECT_TRUE(net.route(x.a, 0x20));
  EXPECT_TRUE(net.route(x.a, 0x30));
  net.send(x.a, 0x20);
  net.send(x.a, 0x30);
  EXPECT_EQ(net.at(x.b).received->size(), 1u);
  EXPECT_EQ(net.at(x.c).received->size(), 1u);
  // The fakes fell silent: their routes went, and the room is back (also
  // the routes b and c echoed, which they and a kept retracting to each
  // other).
  st = net.stats(x.a);
  EXPECT_EQ(st.destinations, 2u);
  EXPECT_EQ(st.neighbours, 2u);
}

// -- neighbours -------------------------------------------------------------------

TEST_F(bounds_sim, hellos_of_new_neighbours_past_the_bounds_are_refused) {
  struct {
    const char* name;
    size_t per_channel;
    size_t total;
    /// Fake neighbours saying hello on link 1 (with c) and on link 2.
    size_t fakes0;
    size_t fakes1;
    size_t neighbours;
    size_t refused;
  } cases[] = {
    // b and c are neighbours already (c on link 1).
    {"per channel", 3, 100, 0, 5, 2 + 3, 2},
    {"per channel, two channels", 3, 100, 4, 4, 2 + 2 + 3, 2 + 1},
    {"in total", 100, 4, 3, 3, 4, 4},
  };
  size_t n = 0;
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    three x{*this,
            [&](routing_config& cfg) {
              cfg.max_neighbours_per_channel = c.per_channel;
              cfg.max_neighbours = c.total;
            },
            std::to_string(n++)};
    auto& net = x.net;
    net.start();
    net.advance(1s);
    ASSERT_EQ(neighbours(net, x.a), 2u);
    module_id id = 0x100;
    std::vector<tap> taps;
    for (size_t li : {1, 2})
      for (size_t i = 0; i < (li == 1 ? c.fakes0 : c.fakes1); ++i) {
        taps.push_back(open_tap(net, li, 100 + id));
        send(taps.back(), hello_from(id++));
      }
    EXPECT_EQ(neighbours(net, x.a), c.neighbours);
    EXPECT_EQ(net.stats(x.a).neighbours, c.neighbours);
    EXPECT_EQ(net.stats(x.a).rx_neighbours_over_limit, c.refused);
    // The real ones stay; once the fakes are lost, new ones fit again.
    net.advance(1s);
    EXPECT_TRUE(net.route(x.a, 0x20));
    EXPECT_TRUE(net.route(x.a, 0x30));
    EXPECT_EQ(neighbours(net, x.a), 2u);
    send(taps.back(), hello_from(0x1FF));
    EXPECT_EQ(neighbours(net, x.a), 3u);
  }
}

// -- seqno requests -------------------------------------------------------------------

TEST_F(bounds_sim, seqno_requests_per_hello_interval_are_bounded) {
  three x{*this, [](routing_config& cfg) { cfg.max_seqno_requests = 4; }};
  auto& net = x.net;
  net.start();
  net.advance(1s);
  auto f = open_tap(net, 2, 9);
  send(f, hello_from(0x66));
  send(f, updates(0x66, 0x1000, 10, 5, 10));
  ASSERT_TRUE(net.route(x.a, 0x1009));
  auto before = net.stats(x.a);
  // The same seqno with a worse metric: unfeasible, so all ten starve at
  // once and each wants a seqno request (RFC 8966 3.8.2.1).
  send(f, updates(0x66, 0x1000, 10, 5, 500));
  EXPECT_FALSE(net.route(x.a, 0x1009));
  auto after = net.stats(x.a);
  EXPECT_EQ(after.tx_seqno_requests - before.tx_seqno_requests, 4u);
  EXPECT_GE(after.seqno_requests_over_limit, 6u);
  // The next interval has room again.
  net.advance(200ms);
  send(f, hello_from(0x66));
  send(f, updates(0x66, 0x1000, 10, 5, 500));
  EXPECT_GT(net.stats(x.a).tx_seqno_requests, after.tx_seqno_requests);
}

// -- flood memories -------------------------------------------------------------------

TEST_F(bounds_sim, distinct_floods_past_the_memory_forget_the_oldest_and_count_it) {
  three x{*this, [](routing_config& cfg) { cfg.max_floods = 8; }};
  auto& net = x.net;
  net.start();
  net.advance(1s);
  auto f = open_tap(net, 2, 9);
  auto request = [&](module_id origin) {
    send(f, encoded(seqno_request{0x66, origin, 1, 1}));
  };
  for (module_id i = 0; i < 20; ++i)
    request(static_cast<module_id>(0x3000 + i));
  EXPECT_EQ(net.stats(x.a).floods_evicted, 12u);
  // The newest are remembered (a duplicate is suppressed, nothing moves);
  // the oldest were forgotten (taken as new, pushing out another).
  request(0x3000 + 19);
  EXPECT_EQ(net.stats(x.a).floods_evicted, 12u);
  request(0x3000);
  EXPECT_EQ(net.stats(x.a).floods_evicted, 13u);
}

TEST_F(bounds_sim, distinct_broadcasts_past_the_memory_forget_the_oldest_and_count_it) {
  three x{*this, [](routing_config& cfg) { cfg.max_floods = 8; }};
  auto& net = x.net;
  net.start();
  net.advance(1s);
  auto f = open_tap(net, 2, 9);
  auto broadcast = [&](uint32_t flood_id) {
    data_header h;
    h.src = 0x66;
    h.dst = broadcast_module;
    h.flood_id = flood_id;
    auto b = encoded(h);
    b.resize(b.size() + 16);
    send(f, b);
  };
  for (uint32_t i = 1; i <= 20; ++i)
    broadcast(i);
  EXPECT_EQ(net.at(x.a).received->size(), 20u);
  EXPECT_EQ(net.stats(x.a).flood_ids_evicted, 12u);
  auto dups = net.stats(x.a).dropped_duplicate;
  broadcast(20); // remembered: a duplicate
  EXPECT_EQ(net.stats(x.a).dropped_duplicate, dups + 1);
  EXPECT_EQ(net.at(x.a).received->size(), 20u);
  broadcast(1); // forgotten: delivered again
  EXPECT_EQ(net.at(x.a).received->size(), 21u);
  EXPECT_EQ(net.stats(x.a).flood_ids_evicted, 13u);
}

// -- route events ---------------------------------------------------------------------

TEST_F(bounds_sim, route_listeners_get_one_complete_event_per_change_and_burst) {
  three x{*this};
  auto& net = x.net;
  net.start();
  net.advance(1s);
  auto f = open_tap(net, 2, 9);
  send(f, hello_from(0x66));
  auto events = listen(net.at(x.a).agent);
  ASSERT_EQ(events->size(), 2u); // b and c, as they are now
  events->clear();
  constexpr module_id dest = 0x4242;
  send(f, encoded(update{0x66, 0x1234, {entry(dest, 1, 10)}}));
  ASSERT_EQ(events->size(), 1u);
  auto first = events->back();
  EXPECT_EQ(first.id, dest);
  EXPECT_TRUE(first.reachable);
  EXPECT_FALSE(first.was_reachable);
  EXPECT_EQ(first.hops, 1u);
  EXPECT_EQ(first.next, 0x66);
  EXPECT_EQ(first.neighbour, 9u);
  EXPECT_EQ(first.path, to_string(link_code::ethernet));
  auto link_cost = first.cost - 10;
  // Three changes about one destination in one burst: one event.
  send(f, encoded(update{0x66, 0x1234,
                         {entry(dest, 2, 20), entry(dest, 3, 30),
                          entry(dest, 4, 40)}}));
  ASSERT_EQ(events->size(), 2u);
  EXPECT_TRUE(events->back().was_reachable);
  EXPECT_EQ(events->back().old_cost, 10 + link_cost);
  EXPECT_EQ(events->back().cost, 40 + link_cost);
  // A refresh that changes nothing is no event; a path that changes at
  // the same cost is one.
  send(f, encoded(update{0x66, 0x1234, {entry(dest, 4, 40)}}));
  EXPECT_EQ(events->size(), 2u);
  send(f, encoded(update{0x66, 0x1234,
                         {entry(dest, 5, 40, {link_code::can20})}}));
  ASSERT_EQ(events->size(), 3u);
  EXPECT_EQ(events->back().cost, 40 + link_cost);
  EXPECT_EQ(events->back().old_cost, 40 + link_cost);
  EXPECT_EQ(events->back().hops, 2u);
  EXPECT_EQ(events->back().path, std::string{to_string(link_code::ethernet)}
                                   + "-" + to_string(link_code::can20));
  // A late listener gets the state now: one event per destination.
  auto late = listen(net.at(x.a).agent);
  ASSERT_EQ(late->size(), 3u);
  for (auto& e : *late) {
    if (e.id == dest) {
      EXPECT_EQ(e.cost, 40 + link_cost);
    }
  }
  // A withdrawal reaches both.
  send(f, encoded(update{0x66, 0x1234, {entry(dest, 6, infinite_metric)}}));
  ASSERT_EQ(events->size(), 4u);
  ASSERT_EQ(late->size(), 4u);
  EXPECT_FALSE(events->back().reachable);
  EXPECT_TRUE(events->back().was_reachable);
  EXPECT_EQ(events->back().old_cost, 40 + link_cost);
  EXPECT_EQ(late->back(), events->back());
}
