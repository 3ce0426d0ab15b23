// Specification of the C client's module in a keyed network (HERMC_AUTH=1,
// hermc_set_key; docs/protocol.md "Authentication"): what it signs, what it
// refuses, and RFC 8967's challenges both ways. The test plays the
// neighbour with its own struct hermc_auth holding the same key (and, where
// said, another key): it signs what it delivers and checks what the module
// sends. Built against hermc_auth only (tests/mcu/CMakeLists.txt); the
// module's other behaviour in that build, unkeyed, is module_test.cpp's
// (hermc_module_auth_test). The real neighbour, a keyed hermd, is
// board_keyed_test.cpp's.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "apps/mcu/client/hermc.h"
#include "tests/mcu/mcu_bytes.hpp"
#include "tests/mcu/mcu_packets.hpp"

using namespace mcu_test;

namespace {

static_assert(HERMC_AUTH == 1, "module_keyed_test needs the hermc_auth build");

constexpr uint16_t self_id = 0x0042;
constexpr uint16_t peer_id = 0x0010;
constexpr uint64_t self_instance = 0x1122334455667788ull;
constexpr uint32_t self_index = 0x0B0A0B0Au;
constexpr uint32_t peer_index = 0x5EED0001u;
constexpr uint8_t link_code = HERMC_LINK_RS232C;

const bytes key = hex("00 11 22 33 44 55 66 77 88 99 AA BB CC DD EE FF "
                      "0F 1E 2D 3C 4B 5A 69 78 87 96 A5 B4 C3 D2 E1 F0");
const bytes other_key = hex("FF EE DD CC BB AA 99 88 77 66 55 44 33 22 11 00 "
                            "F0 E1 D2 C3 B4 A5 96 87 78 69 5A 4B 3C 2D 1E 0F");

/// The echo APO: answers with the request's payload; a request of the one
/// byte FF fills all the room it is given.
uint8_t echo(void* ctx, const uint8_t* req, size_t n, uint8_t* resp,
             size_t cap, size_t* len) {
  ++*static_cast<int*>(ctx);
  if (n == 1 && req[0] == 0xFF) {
    for (size_t i = 0; i < cap; ++i)
      resp[i] = 0xFF;
    *len = cap;
    return 0;
  }
  if (n > cap)
    return HERMC_EC_QUEUE_FULL;
  for (size_t i = 0; i < n; ++i)
    resp[i] = req[i];
  *len = n;
  return 0;
}

hermc_packet_type type_of(const bytes& p) {
  hermc_packet_type t{};
  EXPECT_EQ(hermc_peek_type(p.data(), p.size(), &t), HERMC_NET_OK);
  return t;
}

class hermc_module_keyed_test : public ::testing::Test {
protected:
  void SetUp() override {
    hermc_config cfg;
    hermc_config_default(&cfg, self_id, self_instance);
    ASSERT_EQ(hermc_init(&m, &cfg), HERMC_OK);
    ASSERT_EQ(hermc_register_apo(&m, "sonar", "herm.srf04", echo, &calls), 1);
    ASSERT_EQ(hermc_set_key(&m, key.data(), key.size(), 1, 8, 0, self_index),
              HERMC_OK);
    ASSERT_EQ(hermc_auth_init(&peer, key.data(), key.size(), 8, peer_index, 99),
              0);
    hermc_link_tx_init(&to_module, false);
    hermc_link_rx_init(&from_module, false);
  }

  /// Frames `pkt` as the neighbour would and feeds the wire bytes.
  void deliver(const bytes& pkt) {
    ASSERT_EQ(hermc_link_tx_packet(&to_module, pkt.data(), pkt.size()),
              HERMC_OK);
    uint8_t buf[64];
    size_t n;
    while ((n = hermc_link_tx_pop(&to_module, buf, sizeof buf)) > 0)
      hermc_feed(&m, buf, n);
  }

  /// `pkt` signed by the neighbour (`a`: with its key and index).
  bytes sign(bytes pkt, hermc_auth* a = nullptr) {
    size_t n = pkt.size();
    pkt.resize(n + HERMC_AUTH_TRAILER_MAX);
    n = hermc_auth_sign(a ? a : &peer, pkt.data(), n, pkt.size(), link_code);
    EXPECT_GT(n, 0u);
    pkt.resize(n);
    return pkt;
  }

  /// Every packet the module sent since the last call, as on the wire.
  std::vector<bytes> drain() {
    packets.clear();
    uint8_t buf[64];
    size_t n;
    while ((n = hermc_poll_tx(&m, buf, sizeof buf)) > 0)
      hermc_link_rx_feed(&from_module, buf, n, collect, this);
    return packets;
  }

  static void collect(void* ctx, uint8_t, const uint8_t* p, size_t n) {
    static_cast<hermc_module_keyed_test*>(ctx)->packets.push_back(take(p, n));
  }

  /// The neighbour receives `pkt` as routing/agent_auth does: its body when
  /// it passes, empty when dropped; its challenge and reply to the module
  /// (and after a reply its signed hello) are delivered at once.
  bytes peer_receives(const bytes& pkt) {
    size_t body = 0;
    hermc_auth_out out{};
    int pass = hermc_auth_receive(&peer, pkt.data(), pkt.size(), link_code, now,
                                  &body, &out);
    if (out.challenge_len > 0)
      deliver(take(out.challenge, out.challenge_len));
    if (out.reply_len > 0) {
      deliver(take(out.reply, out.reply_len));
      deliver(sign(hello(peer_id, 0xAB, 1000)));
    }
    return pass ? take(pkt.data(), body) : bytes{};
  }

  /// The neighbour's side of every packet the module sends, until both are
  /// quiet; returns the bodies the neighbour accepted.
  std::vector<bytes> converse() {
    std::vector<bytes> accepted;
    for (int round = 0; round < 8; ++round) {
      auto out = drain();
      if (out.empty())
        break;
      for (auto& p : out) {
        auto body = peer_receives(p);
        if (!body.empty())
          accepted.push_back(body);
      }
    }
    return accepted;
  }

  /// Starts the module and meets the neighbour through the challenges of
  /// both sides (as a keyed hermd would).
  void start() {
    hermc_tick(&m, now);
    converse();
    deliver(sign(hello(peer_id, 0xAB, 1000)));
    converse();
    ASSERT_EQ(m.neighbour, peer_id);
  }

  hermc_module m{};
  hermc_auth peer{};
  hermc_link_tx to_module{};
  hermc_link_rx from_module{};
  std::vector<bytes> packets;
  int calls = 0;
  uint32_t now = 1000;
};

} // namespace

TEST_F(hermc_module_keyed_test, set_key_refuses_what_the_network_cannot_use) {
  hermc_module fresh{};
  hermc_config cfg;
  hermc_config_default(&cfg, self_id, self_instance);
  ASSERT_EQ(hermc_init(&fresh, &cfg), HERMC_OK);
  EXPECT_EQ(hermc_set_key(&fresh, key.data(), 15, 1, 8, 0, 1), HERMC_ERR_ARG);
  bytes long_key(65, 0x5A);
  EXPECT_EQ(hermc_set_key(&fresh, long_key.data(), 65, 1, 8, 0, 1),
            HERMC_ERR_ARG);
  EXPECT_EQ(hermc_set_key(&fresh, nullptr, 32, 1, 8, 0, 1), HERMC_ERR_ARG);
  EXPECT_EQ(hermc_set_key(&fresh, key.data(), key.size(), 1, 12, 0, 1),
            HERMC_ERR_ARG);
  EXPECT_EQ(fresh.keyed, 0);
  // Unkeyed, the first tick's hello carries no trailer.
  hermc_tick(&fresh, now);
  uint8_t buf[64];
  hermc_link_rx rx{};
  hermc_link_rx_init(&rx, false);
  packets.clear();
  size_t n;
  while ((n = hermc_poll_tx(&fresh, buf, sizeof buf)) > 0)
    hermc_link_rx_feed(&rx, buf, n, collect, this);
  ASSERT_FALSE(packets.empty());
  EXPECT_EQ(packets[0].size(), 15u);
}

TEST_F(hermc_module_keyed_test, its_hellos_and_update_are_signed_with_the_key) {
  hermc_tick(&m, now);
  auto out = drain();
  ASSERT_EQ(out.size(), 2u);
  hermc_auth stranger{};
  ASSERT_EQ(hermc_auth_init(&stranger, other_key.data(), other_key.size(), 8, 7, 7),
            0);
  uint64_t counter = 0;
  for (auto& p : out) {
    hermc_auth_trailer t{};
    // A right tag from an index the neighbour does not know yet.
    ASSERT_EQ(hermc_auth_verify(&peer, p.data(), p.size(), link_code, now, 1, &t),
              HERMC_AUTH_UNKNOWN_INDEX);
    EXPECT_EQ(t.index, self_index);
    EXPECT_GT(t.counter, counter); // 1, 2, ...
    counter = t.counter;
    EXPECT_EQ(p.size(), t.body_len + 21u);
    EXPECT_EQ(hermc_auth_verify(&stranger, p.data(), p.size(), link_code, now, 1, &t),
              HERMC_AUTH_BAD_TAG);
  }
  hermc_hello h{};
  EXPECT_EQ(hermc_hello_decode(out[0].data(), 15, &h), HERMC_NET_OK);
  EXPECT_EQ(h.sender, self_id);
  EXPECT_EQ(type_of(out[1]), HERMC_PT_UPDATE);
  EXPECT_EQ(m.auth.counters.signed_packets, 2u);
}

TEST_F(hermc_module_keyed_test, unsigned_or_wrongly_keyed_hellos_are_dropped_and_counted) {
  hermc_tick(&m, now);
  drain();
  deliver(hello(peer_id, 0xAB, 1000)); // 15 bytes: no room for a trailer
  hermc_auth stranger{};
  ASSERT_EQ(hermc_auth_init(&stranger, other_key.data(), other_key.size(), 8,
                            peer_index, 7),
            0);
  deliver(sign(hello(peer_id, 0xAB, 1000), &stranger));
  auto other_id = sign(hello(peer_id, 0xAB, 1000));
  other_id[15] = 9; // key id 9: not the network's
  deliver(other_id);
  EXPECT_EQ(m.neighbour, HERMC_NO_MODULE);
  EXPECT_EQ(m.auth.counters.truncated, 1u);
  EXPECT_EQ(m.auth.counters.bad_tag, 1u);
  EXPECT_EQ(m.auth.counters.wrong_key_id, 1u);
  // None of them prompts a challenge or anything else.
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.auth.counters.challenges_sent, 0u);
}

TEST_F(hermc_module_keyed_test, a_right_tag_from_an_unknown_index_is_challenged_not_taken) {
  hermc_tick(&m, now);
  drain();
  deliver(sign(hello(peer_id, 0xAB, 1000)));
  EXPECT_EQ(m.neighbour, HERMC_NO_MODULE);
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(type_of(out[0]), HERMC_PT_CHALLENGE_REQUEST);
  EXPECT_EQ(out[0].size(), 9u + 21u);
  EXPECT_EQ(m.auth.counters.unknown_index, 1u);
  // Another packet of that index within 300 ms: no second challenge.
  deliver(sign(hello(peer_id, 0xAB, 1000)));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.auth.counters.challenges_limited, 1u);
}

TEST_F(hermc_module_keyed_test, the_challenges_of_both_sides_make_a_neighbour) {
  start();
  EXPECT_EQ(m.auth.counters.challenges_passed, 1u); // we took the peer
  EXPECT_EQ(peer.counters.challenges_passed, 1u);   // the peer took us
  EXPECT_EQ(m.counters.neighbour_changes, 1u);
  // From now on the peer's hellos are accepted, ours verified by the peer.
  deliver(sign(hello(peer_id, 0xAB, 1000)));
  EXPECT_GE(m.auth.counters.accepted, 1u);
  now += 1000;
  hermc_tick(&m, now);
  auto accepted = converse();
  ASSERT_EQ(accepted.size(), 1u);
  EXPECT_EQ(type_of(accepted[0]), HERMC_PT_HELLO);
  EXPECT_EQ(accepted[0].size(), 15u); // the trailer cut off
}

TEST_F(hermc_module_keyed_test, a_challenge_request_is_answered_with_a_reply_then_a_hello) {
  hermc_tick(&m, now);
  drain();
  // The neighbour heard our hello and challenges our index.
  uint8_t nonce[HERMC_AUTH_NONCE_SIZE];
  ASSERT_EQ(hermc_auth_challenge(&peer, self_index, now, nonce), 1);
  bytes req{0x16};
  req.insert(req.end(), nonce, nonce + sizeof nonce);
  deliver(sign(req));
  auto out = drain();
  // Our challenge of its index (not known to us), our reply, our hello.
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(type_of(out[0]), HERMC_PT_CHALLENGE_REQUEST);
  EXPECT_EQ(type_of(out[1]), HERMC_PT_CHALLENGE_REPLY);
  EXPECT_EQ(bytes(out[1].begin() + 1, out[1].begin() + 9),
            bytes(nonce, nonce + 8));
  EXPECT_EQ(type_of(out[2]), HERMC_PT_HELLO);
  EXPECT_EQ(m.auth.counters.replies, 1u);
  // The reply passes the neighbour's challenge; then our hello is taken.
  peer_receives(out[1]);
  EXPECT_EQ(peer.counters.challenges_passed, 1u);
  EXPECT_EQ(peer_receives(out[2]).size(), 15u);
}

TEST_F(hermc_module_keyed_test, a_replayed_packet_is_refused) {
  start();
  auto h = sign(hello(peer_id, 0xAB, 1000));
  deliver(h);
  auto accepted = m.auth.counters.accepted;
  deliver(h);
  EXPECT_EQ(m.auth.counters.accepted, accepted);
  EXPECT_EQ(m.auth.counters.replayed, 1u);
}

TEST_F(hermc_module_keyed_test, discovery_must_be_signed_and_is_answered_signed) {
  start();
  deliver(data(peer_id, 0xFFFF, query(9, HERMC_BY_NAME, "sonar"), 77));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.auth.counters.rx_unsigned, 1u);
  deliver(sign(data(peer_id, 0xFFFF, query(9, HERMC_BY_NAME, "sonar"), 78)));
  auto accepted = converse();
  ASSERT_EQ(accepted.size(), 1u); // the answer, verified by the neighbour
  hermc_data_header h{};
  size_t at = 0;
  ASSERT_EQ(hermc_data_header_decode(accepted[0].data(), accepted[0].size(), &h,
                                     &at),
            HERMC_NET_OK);
  EXPECT_TRUE(h.authenticated);
  EXPECT_EQ(h.dst, peer_id);
  hermc_asl_msg a{};
  ASSERT_EQ(hermc_asl_decode(accepted[0].data() + at, accepted[0].size() - at, &a),
            HERMC_ASL_OK);
  EXPECT_EQ(a.kind, HERMC_ASL_ANSWER);
  EXPECT_EQ(m.counters.queries_answered, 1u);
}

TEST_F(hermc_module_keyed_test, unicast_requests_need_no_signature_unless_data_all) {
  start();
  // data: discovery: a plain request is served, its response unsigned.
  deliver(data(peer_id, self_id, request(5, 1, {1, 2, 3})));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  hermc_data_header h{};
  size_t at = 0;
  ASSERT_EQ(hermc_data_header_decode(out[0].data(), out[0].size(), &h, &at),
            HERMC_NET_OK);
  EXPECT_FALSE(h.authenticated);
  // A signed request (flag A) is verified, served and not taken for one
  // this module cannot read.
  deliver(sign(data(peer_id, self_id, request(6, 1, {4}))));
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(m.counters.rx_auth_unsupported, 0u);
  drain();
  // data: all: a plain request is refused; a signed one's response signed.
  m.auth.data_all = 1;
  peer.data_all = 1;
  deliver(data(peer_id, self_id, request(7, 1, {5})));
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(m.auth.counters.rx_unsigned, 1u);
  deliver(sign(data(peer_id, self_id, request(8, 1, {6}))));
  EXPECT_EQ(calls, 3);
  auto accepted = converse();
  ASSERT_EQ(accepted.size(), 1u);
  ASSERT_EQ(hermc_data_header_decode(accepted[0].data(), accepted[0].size(), &h,
                                     &at),
            HERMC_NET_OK);
  EXPECT_TRUE(h.authenticated);
}

TEST_F(hermc_module_keyed_test, without_a_key_flag_a_is_counted_as_unsupported) {
  hermc_module plain{};
  hermc_config cfg;
  hermc_config_default(&cfg, self_id, self_instance);
  ASSERT_EQ(hermc_init(&plain, &cfg), HERMC_OK);
  ASSERT_EQ(hermc_register_apo(&plain, "sonar", "t", echo, &calls), 1);
  auto pkt = sign(data(peer_id, self_id, request(6, 1, {4})));
  hermc_handle_packet(&plain, pkt.data(), pkt.size());
  EXPECT_EQ(plain.counters.rx_auth_unsupported, 1u);
  EXPECT_EQ(calls, 0);
}

TEST_F(hermc_module_keyed_test, the_largest_signed_request_gets_its_signed_response) {
  start();
  m.auth.data_all = 1;
  peer.data_all = 1;
  // The largest request the module receives: header 8, request 14, trailer
  // 21. Its response (header 8, response 11, trailer 21) fits too: the
  // handler's room leaves space for the trailer.
  size_t room = HERMC_MAX_PACKET - 8u - 14u - 21u;
  deliver(sign(data(peer_id, self_id, request(9, 1, bytes(room, 0x33)))));
  EXPECT_EQ(calls, 1);
  auto accepted = converse();
  ASSERT_EQ(accepted.size(), 1u);
  EXPECT_EQ(accepted[0].size(), 8u + 11u + room);
  // A handler that fills all its room: the signed response is exactly
  // HERMC_MAX_PACKET, sent, not dropped.
  deliver(sign(data(peer_id, self_id, request(10, 1, {0xFF}))));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].size(), size_t{HERMC_MAX_PACKET});
  EXPECT_EQ(peer_receives(out[0]).size(), HERMC_MAX_PACKET - 21u);
  EXPECT_EQ(m.counters.tx_dropped, 0u);
}
