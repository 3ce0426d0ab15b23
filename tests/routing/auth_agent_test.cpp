// The routing agent in a keyed network (routing_config::auth), under CAF's
// test_coordinator: keyed modules converge and sign what they send; a module
// without the key (or with another key) cannot inject routes, cannot take an
// address already in use and is not heard in discovery; replays are dropped.
// Every refusal is counted in the agent's stats.

#include "tests/support/actor_fixture.hpp"
#include "actors/asl_wire.hpp"
#include "actors/testing/sim_apps.hpp"
#include "actors/testing/sim_network.hpp"
#include "routing/auth.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

std::vector<uint8_t> key_of(uint8_t seed) {
  std::vector<uint8_t> k(32);
  for (size_t i = 0; i < k.size(); ++i)
    k[i] = static_cast<uint8_t>(seed * 31 + i);
  return k;
}

auth_config keyed(uint8_t seed = 1, auth_data data = auth_data::discovery) {
  auth_config c;
  c.key = key_of(seed);
  c.data = data;
  return c;
}

/// What a module is given: the network's key, none, or another key.
enum class intruder { none, no_key, other_key };

std::string test_prefix() {
  auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string{info->test_suite_name()} + "-" + info->name();
  std::replace(name.begin(), name.end(), '/', '-');
  return name;
}

class auth_sim : public actor_fixture {
public:
  static void give(sim_network& net, size_t i, intruder kind) {
    switch (kind) {
      case intruder::none:
        net.at(i).cfg.auth = keyed();
        break;
      case intruder::no_key:
        net.at(i).cfg.auth = auth_config{};
        break;
      case intruder::other_key:
        net.at(i).cfg.auth = keyed(2);
        break;
    }
  }

  /// The channel module i hears neighbour `id` on, and that neighbour's
  /// link address.
  std::pair<channel_id, link_addr> channel_to(sim_network& net, size_t i,
                                              module_id id) {
    auto res = call<std::vector<neighbour_info>>(net.at(i).agent, atom::get_v,
                                                 atom::neighbors_v);
    EXPECT_TRUE(res);
    if (res)
      for (auto& n : std::get<0>(*res))
        if (n.id == id)
          return {n.channel, std::stoull(n.link_address)};
    ADD_FAILURE() << "module " << i << " has no neighbour " << to_hex(id);
    return {0, 0};
  }

  size_t neighbours(sim_network& net, size_t i) {
    auto res = call<std::vector<neighbour_info>>(net.at(i).agent, atom::get_v,
                                                 atom::neighbors_v);
    return res ? std::get<0>(*res).size() : 0;
  }

  app_support_stats asl_stats(sim_network& net, size_t i) {
    auto res = call<app_support_stats>(apps_of(net, i), atom::get_v,
                                       atom::stats_v);
    EXPECT_TRUE(res);
    return res ? std::get<0>(*res) : app_support_stats{};
  }
};

const uint8_t eth = static_cast<uint8_t>(link_code::ethernet);

} // namespace

TEST_F(auth_sim, keyed_modules_converge_and_sign_what_they_send) {
  for (auto mode : {auth_data::discovery, auth_data::all}) {
    SCOPED_TRACE(mode == auth_data::all ? "data: all" : "data: discovery");
    sim_network net{*this, test_prefix() + std::to_string(int(mode))};
    auto a = net.add_module(0x10);
    auto b = net.add_module(0x20);
    auto c = net.add_module(0x30);
    net.connect({a, b}, "ethernet");
    net.connect({b, c}, "can2.0");
    for (size_t i = 0; i < 3; ++i)
      net.at(i).cfg.auth = keyed(1, mode);
    net.start();
    net.advance(1s);
    auto r = net.route(a, 0x30);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->hops, 2u);
    // Data across two hops (re-signed by b), unicast and flooded.
    net.send(a, 0x30, 100);
    net.send(c, 0x10, 4);
    net.send(a, broadcast_module, 10);
    EXPECT_EQ(net.at(c).received->size(), 2u);
    EXPECT_EQ(net.at(a).received->size(), 1u);
    EXPECT_EQ(net.at(b).received->size(), 1u);
    for (size_t i = 0; i < 3; ++i) {
      auto st = net.stats(i);
      EXPECT_GT(st.tx_signed, 0u) << i;
      EXPECT_EQ(st.rx_auth_failed, 0u) << i;
      EXPECT_EQ(st.rx_replayed, 0u) << i;
      EXPECT_EQ(st.rx_unsigned, 0u) << i;
      EXPECT_EQ(st.rx_malformed, 0u) << i;
    }
    // With data: all, unicast data is signed too: more signatures at b,
    // which forwarded it.
    net.run();
  }
}

TEST_F(auth_sim, a_module_without_the_key_cannot_inject_routes) {
  for (auto kind : {intruder::no_key, intruder::other_key}) {
    SCOPED_TRACE(kind == intruder::no_key ? "no key" : "other key");
    sim_network net{*this, test_prefix() + std::to_string(int(kind))};
    auto a = net.add_module(0x10);
    auto b = net.add_module(0x20);
    auto x = net.add_module(0x66);  // the intruder
    auto y = net.add_module(0x67);  // behind it, with its key (if any)
    net.connect({a, b, x}, "ethernet");
    net.connect({x, y}, "ethernet");
    give(net, a, intruder::none);
    give(net, b, intruder::none);
    give(net, x, kind);
    give(net, y, kind);
    net.start();
    net.advance(2s);
    EXPECT_TRUE(net.route(a, 0x20));
    EXPECT_FALSE(net.route(a, 0x66));
    EXPECT_FALSE(net.route(a, 0x67));
    EXPECT_FALSE(net.route(b, 0x67));
    EXPECT_EQ(neighbours(net, a), 1u);
    auto st = net.stats(a);
    EXPECT_GT(st.rx_auth_failed, 0u);
    EXPECT_EQ(st.rx_refused_routes, 0u);
    // The intruder's own packets still work among its own kind.
    EXPECT_TRUE(net.route(x, 0x67));
    // a's flooded broadcasts reach b, never the intruder (signed: it cannot
    // check the trailer, nor tell where the payload ends).
    net.send(a, broadcast_module, 10);
    EXPECT_EQ(net.at(b).received->size(), 1u);
    EXPECT_EQ(net.at(x).received->size(), 0u);
    EXPECT_GT(net.stats(x).rx_auth_failed, 0u);
  }
}

TEST_F(auth_sim, a_module_without_the_key_cannot_take_an_address_in_use) {
  // Control run without keys: the intruder, static and with the lowest
  // instance, wins the id and the dynamic holder renumbers. With keys, its
  // claims and hellos are dropped and the holder keeps its id.
  for (bool keys : {false, true}) {
    SCOPED_TRACE(keys ? "keyed network" : "no keys (control)");
    sim_network net{*this, test_prefix() + (keys ? "k" : "n")};
    auto a = net.add_module(no_module, 4242);
    auto b = net.add_module(0x20);
    auto x = net.add_module(0x66);
    net.connect({a, b, x}, "ethernet");
    if (keys) {
      give(net, a, intruder::none);
      give(net, b, intruder::none);
    }
    net.start_module(a);
    net.start_module(b);
    net.advance(3s);
    auto before = net.stats(a);
    ASSERT_TRUE(before.assigned);
    auto taken = before.self;
    // The intruder wants that id.
    net.at(x).cfg.id = taken;
    net.at(x).cfg.instance = 1;
    net.start_module(x);
    net.advance(5s);
    auto after = net.stats(a);
    if (keys) {
      EXPECT_EQ(after.self, taken);
      EXPECT_EQ(after.renumberings, 0u);
      EXPECT_GT(after.rx_auth_failed, 0u);
    } else {
      EXPECT_NE(after.self, taken);
      EXPECT_GT(after.renumberings, 0u);
    }
  }
}

TEST_F(auth_sim, a_replayed_hello_is_dropped_and_counted) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  net.connect({a, b}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  net.start();
  net.advance(1s);
  auto [ch, b_addr] = channel_to(net, a, 0x20);
  ASSERT_NE(ch, 0u);
  // A hello as a keyed module 0x77 at link address 99 would send it.
  authenticator sender{keyed(), 0x7777};
  byte_buffer pkt;
  encode(hello{0x77, 0x7700, 1, 100}, pkt);
  sender.sign(pkt, eth);
  caf::anon_send(net.at(a).agent, packet_received{ch, 99, pkt});
  net.run();
  EXPECT_EQ(neighbours(net, a), 2u);
  EXPECT_EQ(net.stats(a).rx_replayed, 0u);
  // The same bytes again, as an attacker who recorded them would send.
  caf::anon_send(net.at(a).agent, packet_received{ch, 99, pkt});
  caf::anon_send(net.at(a).agent, packet_received{ch, b_addr, pkt});
  net.run();
  EXPECT_EQ(net.stats(a).rx_replayed, 2u);
  // A forged hello (one bit of the sender changed) is no better.
  auto forged = pkt;
  forged[1] ^= 0x01;
  caf::anon_send(net.at(a).agent, packet_received{ch, 98, forged});
  net.run();
  EXPECT_EQ(net.stats(a).rx_auth_failed, 1u);
  EXPECT_EQ(neighbours(net, a), 2u);
}

TEST_F(auth_sim, discovery_answers_from_a_module_without_the_key_are_ignored) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  net.connect({a, b}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  add_app_support(*this, net);
  net.start();
  net.advance(1s);
  auto [ch, b_addr] = channel_to(net, a, 0x20);
  ASSERT_NE(ch, 0u);
  auto answer_packet = [](bool sign, uint32_t index) {
    byte_buffer payload;
    encode(asl_message{asl_answer{1, {asl_entry{5, "evil", "herm.fake"}}}},
           payload);
    data_header h;
    h.src = 0x66;
    h.dst = 0x10;
    h.protocol = asl_protocol;
    h.authenticated = sign;
    byte_buffer pkt;
    encode(h, pkt);
    pkt.insert(pkt.end(), payload.begin(), payload.end());
    if (sign) {
      authenticator tx{keyed(), index};
      tx.sign(pkt, eth);
    }
    return pkt;
  };
  auto before = asl_stats(net, a);
  // Unsigned, as a module without the key sends it: dropped.
  caf::anon_send(net.at(a).agent, packet_received{ch, 99, answer_packet(false, 0)});
  net.run();
  EXPECT_EQ(net.stats(a).rx_unsigned, 1u);
  EXPECT_EQ(asl_stats(net, a).answers_received, before.answers_received);
  EXPECT_EQ(asl_stats(net, a).known_remote_apos, before.known_remote_apos);
  // Signed with another key: dropped.
  {
    auto p = answer_packet(false, 0);
    auto d = decode_data_header(p.data(), p.size());
    ASSERT_TRUE(d);
    set_authenticated(p.data(), true);
    authenticator other{keyed(2), 5};
    other.sign(p, eth);
    caf::anon_send(net.at(a).agent, packet_received{ch, 99, p});
    net.run();
    EXPECT_EQ(net.stats(a).rx_auth_failed, 1u);
    EXPECT_EQ(asl_stats(net, a).answers_received, before.answers_received);
  }
  // Control: the same answer signed with the network's key is heard.
  caf::anon_send(net.at(a).agent,
                 packet_received{ch, 99, answer_packet(true, 0x1234)});
  net.run();
  EXPECT_EQ(asl_stats(net, a).answers_received, before.answers_received + 1);
  EXPECT_EQ(asl_stats(net, a).known_remote_apos, before.known_remote_apos + 1);
  (void) b_addr;
}

TEST_F(auth_sim, discovery_finds_keyed_apos_and_not_the_intruders) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  auto x = net.add_module(0x66);
  net.connect({a, b, x}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  give(net, x, intruder::other_key);
  add_app_support(*this, net);
  net.start();
  net.advance(1s);
  auto dummy = [](caf::event_based_actor*) -> caf::behavior {
    return {[](int v) { return v; }};
  };
  spawn_apo(net, b, "lidar", "herm.test", dummy);
  spawn_apo(net, x, "sonar", "herm.test", dummy);
  net.advance(500ms);
  bind_request lidar{query_by::name, "lidar", 300};
  bind_request sonar{query_by::name, "sonar", 300};
  EXPECT_TRUE(bind_apo(net, a, lidar));
  auto res = bind_apo(net, a, sonar);
  EXPECT_FALSE(res);
  EXPECT_GT(net.stats(a).rx_auth_failed, 0u);
  EXPECT_GT(net.stats(x).rx_auth_failed, 0u);
}
