// The routing agent in a keyed network (routing_config::auth), under CAF's
// test_coordinator: keyed modules converge and sign what they send; a module
// without the key (or with another key) cannot inject routes, cannot take an
// address already in use and is not heard in discovery; replays are dropped;
// a recording from a sender index never heard is challenged (RFC 8967) and
// not acted on, while a restarted module passes the challenge and is a
// neighbour again one round trip later. Every refusal is counted in the
// agent's stats. A "tap" is a keyed station the test drives by hand on a
// link of the network: it records what it hears and sends what the test
// signs.

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

/// `bytes` signed by `tx` for an Ethernet link.
template <class T>
byte_buffer signed_by(authenticator& tx, const T& packet) {
  byte_buffer b;
  encode(packet, b);
  tx.sign(b, static_cast<uint8_t>(link_code::ethernet));
  return b;
}

/// A station on a link of the network, driven by the test (see the file
/// comment).
struct tap {
  channel_actor ch;
  std::shared_ptr<probe_log> log;
};

/// The packets of type `t` the tap heard from `src`, trailer included.
std::vector<byte_buffer> heard(const tap& t, link_addr src, packet_type type) {
  std::vector<byte_buffer> out;
  for (auto& p : t.log->packets)
    if (p.src == src && !p.bytes.empty()
        && (p.bytes[0] & 0x0F) == static_cast<uint8_t>(type))
      out.push_back(p.bytes);
  return out;
}

/// The nonce of a signed challenge request or reply (trailer of 21 bytes).
challenge_nonce nonce_of(const byte_buffer& signed_packet) {
  challenge_nonce n{};
  EXPECT_EQ(signed_packet.size(), 9u + 21u);
  if (signed_packet.size() >= 9)
    std::copy(signed_packet.begin() + 1, signed_packet.begin() + 9, n.begin());
  return n;
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

  /// Opens a station on link `li` of `net` (before or after it starts).
  tap open_tap(sim_network& net, size_t li, link_addr station) {
    tap t;
    auto io = track(spawn_io_manager(sys()));
    device_config dev{"tap", "inproc", net.link_at(li).segment,
                      {{"profile", net.link_at(li).profile},
                       {"station", std::to_string(station)}}};
    auto added = call<device_info>(io, atom::add_v, dev);
    EXPECT_TRUE(added);
    auto opened = call<channel_actor, channel_info>(io, atom::open_v,
                                                    channel_request{"tap"});
    EXPECT_TRUE(opened);
    if (!opened)
      return t;
    t.ch = std::get<0>(*opened);
    auto [probe, log] = spawn_probe();
    t.log = log;
    auto sub = call<channel_info>(t.ch, atom::subscribe_v,
                                  caf::actor_cast<channel_reader_actor>(probe));
    EXPECT_TRUE(sub);
    return t;
  }

  /// Sends `bytes` from the tap to station `dst` and runs every actor.
  void send(const tap& t, link_addr dst, byte_buffer bytes) {
    caf::anon_send(t.ch, write_packet{dst, prio_control, std::move(bytes)});
    run();
  }

  /// Makes the module at station `dst` know `signer`'s index as a keyed
  /// module would: the tap sends it a challenge request signed by `signer`;
  /// the module answers and challenges back (it does not know `signer`);
  /// the tap answers the module's latest challenge (one sent within the
  /// last 300 ms is not repeated). True when the answer was accepted.
  bool introduce(sim_network& net, size_t module, const tap& t, link_addr dst,
                 authenticator& signer) {
    auto before = net.stats(module);
    send(t, dst, signed_by(signer, challenge_request{{0xEE}}));
    auto got = heard(t, dst, packet_type::challenge_request);
    if (got.empty())
      return false;
    send(t, dst, signed_by(signer, challenge_reply{nonce_of(got.back())}));
    auto after = net.stats(module);
    return after.rx_challenge_failed == before.rx_challenge_failed
           && after.rx_auth_table_full == before.rx_auth_table_full;
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
  auto spy = open_tap(net, 0, 9);
  net.start();
  net.advance(1s);
  auto [ch, b_addr] = channel_to(net, a, 0x20);
  ASSERT_NE(ch, 0u);
  // A hello b sent, as an attacker on the link recorded it.
  auto recorded = heard(spy, b_addr, packet_type::hello);
  ASSERT_FALSE(recorded.empty());
  auto before = net.stats(a);
  // Replayed from the attacker's own station and as if from b's.
  send(spy, 1, recorded.front());
  send(spy, 1, recorded.back());
  caf::anon_send(net.at(a).agent, packet_received{ch, b_addr, recorded.back()});
  net.run();
  auto after = net.stats(a);
  EXPECT_EQ(after.rx_replayed - before.rx_replayed, 3u);
  EXPECT_EQ(after.rx_auth_challenged, before.rx_auth_challenged);
  EXPECT_EQ(neighbours(net, a), 1u);
  // A forged hello (one bit of the sender changed) is no better.
  auto forged = recorded.back();
  forged[1] ^= 0x01;
  send(spy, 1, forged);
  EXPECT_EQ(net.stats(a).rx_auth_failed, before.rx_auth_failed + 1);
  EXPECT_EQ(neighbours(net, a), 1u);
}

TEST_F(auth_sim, a_recording_from_an_unknown_index_is_challenged_and_not_acted_on) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  net.connect({a, b}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  auto spy = open_tap(net, 0, 9);
  net.start();
  net.advance(1s);
  ASSERT_EQ(neighbours(net, a), 1u);
  // What keyed module 0x77 signed in a previous life (index 0x7777), and
  // its reply to a challenge of that life: recorded, replayed now.
  authenticator old_life{keyed(), 0x7777};
  auto hello_77 = signed_by(old_life, hello{0x77, 0x7700, 1, 100});
  auto update_77 = signed_by(old_life, update{0x77, 0x7700, {}});
  auto reply_77 = signed_by(old_life, challenge_reply{{1, 2, 3, 4, 5, 6, 7, 8}});
  auto before = net.stats(a);
  send(spy, 1, hello_77);
  auto st = net.stats(a);
  EXPECT_EQ(st.rx_auth_challenged, before.rx_auth_challenged + 1);
  EXPECT_EQ(st.tx_challenges, before.tx_challenges + 1);
  EXPECT_EQ(neighbours(net, a), 1u);
  // The challenge went to the station the hello came from, signed.
  auto asked = heard(spy, 1, packet_type::challenge_request);
  ASSERT_EQ(asked.size(), 1u);
  authenticator keyholder{keyed(), 0x9999};
  auth_trailer t;
  EXPECT_EQ(keyholder.verify(asked[0].data(), asked[0].size(),
                             static_cast<uint8_t>(link_code::ethernet),
                             authenticator::time_point{}, t),
            auth_result::unknown_index);
  // Replayed again and again within 300 ms: dropped and counted, one
  // challenge (the rate limit).
  for (int i = 0; i < 5; ++i) {
    send(spy, 1, hello_77);
    send(spy, 1, update_77);
  }
  st = net.stats(a);
  EXPECT_EQ(st.rx_auth_challenged, before.rx_auth_challenged + 11);
  EXPECT_EQ(st.tx_challenges, before.tx_challenges + 1);
  EXPECT_EQ(heard(spy, 1, packet_type::challenge_request).size(), 1u);
  // The recorded reply echoes a stale nonce: it fails.
  send(spy, 1, reply_77);
  EXPECT_EQ(net.stats(a).rx_challenge_failed, before.rx_challenge_failed + 1);
  net.advance(1s);
  EXPECT_EQ(neighbours(net, a), 1u);
  EXPECT_FALSE(net.route(a, 0x77));
  EXPECT_EQ(net.stats(a).rx_refused_routes, 0u);
  EXPECT_EQ(net.stats(a).rx_unknown_neighbour, 0u);
}

TEST_F(auth_sim, a_restarted_module_passes_the_challenge_and_is_a_neighbour_within_a_round_trip) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  net.connect({a, b}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  net.start();
  net.advance(1s);
  ASSERT_TRUE(net.route(a, 0x20));
  // Power cut: a forgets b after 1.5 silent hello intervals.
  net.kill(b);
  net.advance(1s);
  ASSERT_EQ(neighbours(net, a), 0u);
  auto before = net.stats(a);
  // b comes back with a new random index and its counter at 1: a
  // challenges it; b answers, then sends its hello straight away.
  net.start_module(b);
  auto started = now();
  ASSERT_TRUE(advance_until(1s, [&] {
    return neighbours(net, a) == 1 && neighbours(net, b) == 1;
  }));
  // Measured: both sides have their neighbour with no simulated time
  // passed, a challenge round trip on each side, not a hello interval.
  EXPECT_EQ(now() - started, caf::timespan{0});
  EXPECT_TRUE(net.route(a, 0x20));
  EXPECT_TRUE(net.route(b, 0x10));
  auto st = net.stats(a);
  EXPECT_GE(st.rx_auth_challenged, before.rx_auth_challenged + 1);
  EXPECT_EQ(st.tx_challenges, before.tx_challenges + 1);
  EXPECT_EQ(st.tx_challenge_replies, before.tx_challenge_replies + 1);
  EXPECT_EQ(st.rx_challenge_failed, 0u);
  auto sb = net.stats(b);
  EXPECT_EQ(sb.tx_challenges, 1u);
  EXPECT_EQ(sb.tx_challenge_replies, 1u);
  EXPECT_EQ(sb.rx_auth_failed, 0u);
  // And data flows both ways.
  net.send(a, 0x20, 100);
  net.send(b, 0x10, 4);
  EXPECT_EQ(net.at(b).received->size(), 1u);
  EXPECT_EQ(net.at(a).received->size(), 1u);
}

TEST_F(auth_sim, an_expired_challenge_fails_and_a_fresh_one_passes) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  net.connect({a, b}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  auto tap9 = open_tap(net, 0, 9);
  net.start();
  net.advance(1s);
  // The tap plays keyed module 0x55, slow to answer.
  authenticator m55{keyed(), 0x5555};
  send(tap9, 1, signed_by(m55, hello{0x55, 0x5500, 1, 100}));
  auto asked = heard(tap9, 1, packet_type::challenge_request);
  ASSERT_EQ(asked.size(), 1u);
  net.advance(30s + 100ms);
  send(tap9, 1, signed_by(m55, challenge_reply{nonce_of(asked[0])}));
  EXPECT_EQ(net.stats(a).rx_challenge_failed, 1u);
  EXPECT_EQ(neighbours(net, a), 1u);
  // In time: the index is known, and 0x55's next hello makes it a
  // neighbour.
  send(tap9, 1, signed_by(m55, hello{0x55, 0x5500, 2, 100}));
  asked = heard(tap9, 1, packet_type::challenge_request);
  ASSERT_EQ(asked.size(), 2u);
  send(tap9, 1, signed_by(m55, challenge_reply{nonce_of(asked[1])}));
  send(tap9, 1, signed_by(m55, hello{0x55, 0x5500, 3, 100}));
  EXPECT_EQ(net.stats(a).rx_challenge_failed, 1u);
  EXPECT_EQ(neighbours(net, a), 2u);
}

TEST_F(auth_sim, challenge_requests_are_answered_signed_rate_limited_and_followed_by_a_hello) {
  sim_network net{*this, test_prefix()};
  auto a = net.add_module(0x10);
  auto b = net.add_module(0x20);
  net.connect({a, b}, "ethernet");
  give(net, a, intruder::none);
  give(net, b, intruder::none);
  auto tap9 = open_tap(net, 0, 9);
  net.start();
  net.advance(1s);
  auto before = net.stats(a);
  // A keyed module a has never heard asks: a answers although it does not
  // know the index (and challenges it in turn).
  authenticator asker{keyed(), 0x4444};
  auto hellos = heard(tap9, 1, packet_type::hello).size();
  send(tap9, 1, signed_by(asker, challenge_request{{1, 2, 3, 4, 5, 6, 7, 8}}));
  auto replies = heard(tap9, 1, packet_type::challenge_reply);
  ASSERT_EQ(replies.size(), 1u);
  EXPECT_EQ(nonce_of(replies[0]), (challenge_nonce{1, 2, 3, 4, 5, 6, 7, 8}));
  authenticator keyholder{keyed(), 0x9999};
  auth_trailer t;
  EXPECT_EQ(keyholder.verify(replies[0].data(), replies[0].size(),
                             static_cast<uint8_t>(link_code::ethernet),
                             authenticator::time_point{}, t),
            auth_result::unknown_index);
  // Right after the reply, a's hello to the asker.
  EXPECT_EQ(heard(tap9, 1, packet_type::hello).size(), hellos + 1);
  EXPECT_EQ(heard(tap9, 1, packet_type::challenge_request).size(), 1u);
  // More requests within 300 ms (a replayed one, fresh ones): no reply.
  for (uint8_t i = 0; i < 5; ++i)
    send(tap9, 1, signed_by(asker, challenge_request{{i}}));
  auto st = net.stats(a);
  EXPECT_EQ(st.tx_challenge_replies, before.tx_challenge_replies + 1);
  EXPECT_EQ(heard(tap9, 1, packet_type::challenge_reply).size(), 1u);
  // 300 ms later, one more.
  net.advance(300ms);
  send(tap9, 1, signed_by(asker, challenge_request{{9}}));
  EXPECT_EQ(heard(tap9, 1, packet_type::challenge_reply).size(), 2u);
  // A request without the key gets nothing.
  authenticator forger{keyed(7), 0x4444};
  net.advance(300ms);
  send(tap9, 1, signed_by(forger, challenge_request{{10}}));
  EXPECT_EQ(heard(tap9, 1, packet_type::challenge_reply).size(), 2u);
  EXPECT_EQ(net.stats(a).rx_auth_failed, before.rx_auth_failed + 1);
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
  auto tap9 = open_tap(net, 0, 9);
  authenticator tx{keyed(), 0x1234};
  auto answer_packet = [&tx](bool sign) {
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
    if (sign)
      tx.sign(pkt, eth);
    return pkt;
  };
  auto before = asl_stats(net, a);
  // Unsigned, as a module without the key sends it: dropped.
  caf::anon_send(net.at(a).agent, packet_received{ch, 99, answer_packet(false)});
  net.run();
  EXPECT_EQ(net.stats(a).rx_unsigned, 1u);
  EXPECT_EQ(asl_stats(net, a).answers_received, before.answers_received);
  EXPECT_EQ(asl_stats(net, a).known_remote_apos, before.known_remote_apos);
  // Signed with another key: dropped.
  {
    auto p = answer_packet(false);
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
  // Signed with the network's key by an index a does not know: challenged,
  // not heard.
  auto challenged = net.stats(a).rx_auth_challenged;
  send(tap9, 1, answer_packet(true));
  EXPECT_EQ(net.stats(a).rx_auth_challenged, challenged + 1);
  EXPECT_EQ(asl_stats(net, a).answers_received, before.answers_received);
  // Control: once the signer has passed a's challenge, the same answer
  // signed with the network's key is heard.
  ASSERT_TRUE(introduce(net, a, tap9, 1, tx));
  send(tap9, 1, answer_packet(true));
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
