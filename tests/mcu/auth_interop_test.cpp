// The C client's authentication (apps/mcu/client/hermc_auth.h) against the
// C++ reference (routing/auth.hpp, the routing agent's use of it in
// routing/agent_auth.cpp): the trailers are byte for byte the same, each
// side verifies what the other signed once the RFC 8967 challenge has made
// the sender's index known, and replayed or tampered packets are refused by
// both alike. Then the C core's own rules: nonces, timeouts, rate limits,
// the bounded tables and what it refuses.

#include <chrono>
#include <cstring>

#include <gtest/gtest.h>

#include "hermc_auth.h"
#include "routing/auth.hpp"
#include "routing/metric.hpp"
#include "routing/wire.hpp"
#include "tests/mcu/mcu_bytes.hpp"

using namespace herm;
using namespace std::chrono_literals;
using mcu_test::bytes;
using mcu_test::hex;

namespace {

using time_point = authenticator::time_point;
const time_point t0{};
const uint8_t serial = static_cast<uint8_t>(link_code::rs232c);

bytes key_of(uint8_t seed, size_t n = 32) {
  bytes k(n);
  for (size_t i = 0; i < n; ++i)
    k[i] = static_cast<uint8_t>(seed + i * 7);
  return k;
}

auth_config cpp_config(uint8_t tag = 8, uint8_t seed = 1) {
  auth_config c;
  c.key = key_of(seed);
  c.tag_bytes = tag;
  return c;
}

/// Nonces 1, 2, ... from the C++ side (deterministic challenges).
random_source counting_nonces() {
  auto next = std::make_shared<uint64_t>(0);
  return [next](uint8_t* out, size_t n) {
    ++*next;
    for (size_t i = 0; i < n; ++i)
      out[i] = static_cast<uint8_t>(i < 8 ? *next >> (8 * i) : 0);
    return true;
  };
}

/// The C side: one hermc_auth with the key of `seed`.
struct c_side {
  hermc_auth a;

  explicit c_side(uint32_t index, uint8_t tag = 8, uint8_t seed = 1,
                  uint64_t salt = 0x1122334455667788) {
    auto k = key_of(seed);
    EXPECT_EQ(hermc_auth_init(&a, k.data(), k.size(), tag, index, salt), 0);
  }

  /// `body` signed for `link`.
  bytes sign(bytes body, uint8_t link = serial) {
    auto n = body.size();
    body.resize(n + HERMC_AUTH_TRAILER_MAX);
    auto len = hermc_auth_sign(&a, body.data(), n, body.size(), link);
    EXPECT_EQ(len, n + hermc_auth_trailer_size(&a));
    body.resize(len);
    return body;
  }

  hermc_auth_result verify(const bytes& p, uint32_t now_ms = 0,
                           size_t min_body = 1, uint8_t link = serial) {
    hermc_auth_trailer t{};
    return hermc_auth_verify(&a, p.data(), p.size(), link, now_ms, min_body,
                             &t);
  }

  /// hermc_auth_receive: whether the packet goes on, its body length and
  /// what goes back.
  struct received {
    bool pass = false;
    size_t body = 0;
    bytes challenge, reply;
  };

  received receive(const bytes& p, uint32_t now_ms = 0, uint8_t link = serial) {
    hermc_auth_out out;
    received r;
    r.pass = hermc_auth_receive(&a, p.data(), p.size(), link, now_ms, &r.body,
                                &out)
             == 1;
    r.challenge = bytes(out.challenge, out.challenge + out.challenge_len);
    r.reply = bytes(out.reply, out.reply + out.reply_len);
    return r;
  }
};

bytes hello_bytes(uint16_t sender = 0x004E) {
  byte_buffer b;
  encode(hello{sender, 0x0807060504030201, 0xABCD, 1000}, b);
  return b;
}

bytes challenge_bytes(uint8_t type, const challenge_nonce& n) {
  bytes b{static_cast<uint8_t>(0x10 | type)};
  b.insert(b.end(), n.begin(), n.end());
  return b;
}

challenge_nonce nonce_of(const bytes& p) {
  challenge_nonce n{};
  std::memcpy(n.data(), p.data() + 1, n.size());
  return n;
}

/// The C++ receiver `rx` challenges the C sender and takes its signed
/// reply: afterwards rx knows the C side's index.
void introduce_c_to_cpp(c_side& c, authenticator& rx, time_point now = t0) {
  challenge_nonce n;
  ASSERT_TRUE(rx.challenge(c.a.index, now, n));
  auto reply = c.sign(challenge_bytes(7, n));
  auth_trailer t;
  ASSERT_EQ(rx.verify(reply.data(), reply.size(), serial, now, t),
            auth_result::unknown_index);
  ASSERT_EQ(rx.accept_reply(t, n, now), auth_result::ok);
}

/// The C receiver challenges the C++ sender `tx` and takes its reply.
void introduce_cpp_to_c(authenticator& tx, c_side& c, uint32_t now_ms = 0) {
  uint8_t n[HERMC_AUTH_NONCE_SIZE];
  ASSERT_EQ(hermc_auth_challenge(&c.a, tx.index(), now_ms, n), 1);
  challenge_nonce cn;
  std::memcpy(cn.data(), n, cn.size());
  byte_buffer reply = challenge_bytes(7, cn);
  tx.sign(reply, serial);
  auto r = c.receive(reply, now_ms);
  ASSERT_FALSE(r.pass);
  ASSERT_EQ(c.a.counters.challenges_passed, 1u);
}

int as_int(hermc_auth_result r) {
  return static_cast<int>(r);
}

int as_int(auth_result r) {
  return static_cast<int>(r);
}

} // namespace

// -- the same bytes -----------------------------------------------------------------

TEST(hermc_auth_interop, a_signed_hello_is_the_protocols_example_byte_for_byte) {
  for (uint8_t tag : {8, 16})
    for (uint8_t link = 1; link <= 7; ++link) {
      SCOPED_TRACE(testing::Message() << "tag " << int{tag} << " link " << int{link});
      c_side c{0x01020304, tag};
      authenticator cpp{cpp_config(tag), 0x01020304};
      auto p = c.sign(hello_bytes(), link);
      byte_buffer q = hello_bytes();
      cpp.sign(q, link);
      EXPECT_EQ(p, q);
      EXPECT_EQ(p.size(), 15u + 13u + tag);
      EXPECT_EQ(bytes(p.begin() + 15, p.begin() + 28),
                hex("01 04 03 02 01 01 00 00 00 00 00 00 00"));
    }
}

TEST(hermc_auth_interop, a_signed_challenge_request_is_the_protocols_example) {
  c_side c{0x0A0B0C0D};
  authenticator cpp{cpp_config(), 0x0A0B0C0D};
  challenge_nonce n{1, 2, 3, 4, 5, 6, 7, 8};
  for (int i = 0; i < 6; ++i) { // counters 1..6 used on both sides
    c.sign(hello_bytes());
    byte_buffer h = hello_bytes();
    cpp.sign(h, serial);
  }
  auto p = c.sign(challenge_bytes(6, n));
  EXPECT_EQ(bytes(p.begin(), p.begin() + 22),
            hex("16 01 02 03 04 05 06 07 08 01 0D 0C 0B 0A 07 00 00 00 00 00 00 00"));
  EXPECT_EQ(p.size(), 30u);
  byte_buffer q = challenge_bytes(6, n);
  cpp.sign(q, serial);
  EXPECT_EQ(p, q);
}

TEST(hermc_auth_interop, signing_a_data_packet_sets_flag_a_as_the_cpp_header_does) {
  c_side c{0x77};
  authenticator cpp{cpp_config(), 0x77};
  data_header h{0x004E, 0x1042, 17, 2, 3, 1};
  byte_buffer body;
  encode(h, body);
  body.insert(body.end(), {1, 2, 3});
  auto p = c.sign(body);
  EXPECT_EQ(bytes(p.begin(), p.begin() + 8), hex("10 4E 00 42 10 11 2E 01"));
  auto d = decode_data_header(p.data(), p.size());
  ASSERT_TRUE(d);
  EXPECT_TRUE(d->authenticated);
  h.authenticated = true;
  byte_buffer q;
  encode(h, q);
  q.insert(q.end(), {1, 2, 3});
  cpp.sign(q, serial);
  EXPECT_EQ(p, q);
}

// -- each verifies the other -----------------------------------------------------

TEST(hermc_auth_interop, the_cpp_side_verifies_what_the_c_side_signed_once_challenged) {
  for (uint8_t tag : {8, 16}) {
    SCOPED_TRACE(int{tag});
    c_side c{0xC0FFEE, tag};
    authenticator rx{cpp_config(tag), 0x5EED, counting_nonces()};
    auto first = c.sign(hello_bytes());
    auth_trailer t;
    EXPECT_EQ(rx.verify(first.data(), first.size(), serial, t0, t),
              auth_result::unknown_index);
    EXPECT_EQ(t.index, 0xC0FFEEu);
    EXPECT_EQ(t.counter, 1u);
    introduce_c_to_cpp(c, rx);
    auto next = c.sign(hello_bytes());
    size_t body = 0;
    EXPECT_EQ(rx.verify(next.data(), next.size(), serial, t0 + 1s, body),
              auth_result::ok);
    EXPECT_EQ(body, 15u);
    EXPECT_EQ(rx.verify(next.data(), next.size(), serial, t0 + 1s, body),
              auth_result::replayed);
    // Signed before the reply: a replay from now on.
    EXPECT_EQ(rx.verify(first.data(), first.size(), serial, t0 + 1s, body),
              auth_result::replayed);
    // Another link kind fails the tag.
    auto other = c.sign(hello_bytes(), static_cast<uint8_t>(link_code::can20));
    EXPECT_EQ(rx.verify(other.data(), other.size(), serial, t0 + 1s, body),
              auth_result::bad_tag);
  }
}

TEST(hermc_auth_interop, the_c_side_verifies_what_the_cpp_side_signed_once_challenged) {
  for (uint8_t tag : {8, 16}) {
    SCOPED_TRACE(int{tag});
    authenticator tx{cpp_config(tag), 0xABCD0123};
    c_side c{0x42, tag};
    byte_buffer first = hello_bytes(0x1001);
    tx.sign(first, serial);
    // Unknown index: dropped, and challenged.
    auto r = c.receive(first);
    EXPECT_FALSE(r.pass);
    ASSERT_EQ(r.challenge.size(), 9u + 13u + tag);
    EXPECT_EQ(c.a.counters.unknown_index, 1u);
    EXPECT_EQ(c.a.counters.challenges_sent, 1u);
    // The C++ side answers the C challenge (its tag is right, the C index
    // unknown there): the reply echoes the nonce.
    auth_trailer t;
    ASSERT_EQ(tx.verify(r.challenge.data(), r.challenge.size(), serial, t0, t),
              auth_result::unknown_index);
    EXPECT_EQ(t.index, 0x42u);
    ASSERT_TRUE(tx.may_reply(t.index, t0));
    byte_buffer reply = challenge_bytes(7, nonce_of(r.challenge));
    tx.sign(reply, serial);
    r = c.receive(reply, 10);
    EXPECT_FALSE(r.pass); // a reply is consumed, never handled further
    EXPECT_TRUE(r.challenge.empty());
    EXPECT_EQ(c.a.counters.challenges_passed, 1u);
    byte_buffer next = hello_bytes(0x1001);
    tx.sign(next, serial);
    r = c.receive(next, 20);
    EXPECT_TRUE(r.pass);
    EXPECT_EQ(r.body, 15u);
    EXPECT_EQ(bytes(next.begin(), next.begin() + 15), hello_bytes(0x1001));
    r = c.receive(next, 30);
    EXPECT_FALSE(r.pass);
    EXPECT_EQ(c.a.counters.replayed, 1u);
    r = c.receive(first, 40);
    EXPECT_FALSE(r.pass);
    EXPECT_EQ(c.a.counters.replayed, 2u);
  }
}

TEST(hermc_auth_interop, a_challenge_round_trip_both_ways_takes_one_exchange) {
  // The C++ side starts: its hello reaches the C side, which challenges;
  // the C++ side, not knowing the C index, challenges back and replies; the
  // C side replies to that. Afterwards each knows the other.
  authenticator cpp{cpp_config(), 0x600D, counting_nonces()};
  c_side c{0xB0A2D};
  byte_buffer hello = hello_bytes(0x1001);
  cpp.sign(hello, serial);
  auto r = c.receive(hello);
  ASSERT_FALSE(r.challenge.empty());
  // The C++ agent's order: challenge the unknown sender, then answer.
  auth_trailer t;
  ASSERT_EQ(cpp.verify(r.challenge.data(), r.challenge.size(), serial, t0, t),
            auth_result::unknown_index);
  challenge_nonce mine;
  ASSERT_TRUE(cpp.challenge(t.index, t0, mine));
  byte_buffer req = challenge_bytes(6, mine);
  cpp.sign(req, serial);
  ASSERT_TRUE(cpp.may_reply(t.index, t0));
  byte_buffer rep = challenge_bytes(7, nonce_of(r.challenge));
  cpp.sign(rep, serial);
  // The C side gets the request: it is challenged (already, rate-limited)
  // and replies; then the reply: the C++ index is known.
  auto rq = c.receive(req, 1);
  EXPECT_FALSE(rq.pass);
  EXPECT_TRUE(rq.challenge.empty()); // one challenge per index per 300 ms
  ASSERT_EQ(rq.reply.size(), 30u);
  EXPECT_EQ(nonce_of(rq.reply), mine);
  auto rp = c.receive(rep, 2);
  EXPECT_FALSE(rp.pass);
  EXPECT_EQ(c.a.counters.challenges_passed, 1u);
  // The C reply passes the C++ challenge.
  ASSERT_EQ(cpp.verify(rq.reply.data(), rq.reply.size(), serial, t0, t),
            auth_result::unknown_index);
  EXPECT_EQ(cpp.accept_reply(t, nonce_of(rq.reply), t0), auth_result::ok);
  // Both now accept each other's next hello.
  auto from_c = c.sign(hello_bytes());
  size_t body = 0;
  EXPECT_EQ(cpp.verify(from_c.data(), from_c.size(), serial, t0, body),
            auth_result::ok);
  byte_buffer from_cpp = hello_bytes(0x1001);
  cpp.sign(from_cpp, serial);
  EXPECT_TRUE(c.receive(from_cpp, 3).pass);
}

TEST(hermc_auth_interop, tampered_and_replayed_packets_are_refused_alike) {
  authenticator tx{cpp_config(), 9};
  byte_buffer p = hello_bytes();
  tx.sign(p, serial);
  // Fresh receivers on both sides, and receivers that know index 9.
  for (bool known : {false, true})
    for (size_t i = 0; i <= p.size(); ++i)
      for (int bit = 0; bit < 8; ++bit) {
        bytes b = p;
        if (i == p.size())
          b.push_back(static_cast<uint8_t>(1 << bit)); // a byte added
        else
          b[i] = static_cast<uint8_t>(b[i] ^ (1 << bit));
        authenticator cpp_rx{cpp_config(), 1};
        c_side c{2};
        if (known) {
          // Both learn index 9 with counter 0, as from a passed challenge.
          challenge_nonce n;
          ASSERT_TRUE(cpp_rx.challenge(9, t0, n));
          auth_trailer t{9, 0, 0};
          ASSERT_EQ(cpp_rx.accept_reply(t, n, t0), auth_result::ok);
          uint8_t cn[8];
          ASSERT_EQ(hermc_auth_challenge(&c.a, 9, 0, cn), 1);
          hermc_auth_trailer ct{0, 9, 0};
          ASSERT_EQ(hermc_auth_accept_reply(&c.a, &ct, cn, 0), HERMC_AUTH_OK);
        }
        auth_trailer t;
        auto want = cpp_rx.verify(b.data(), b.size(), serial, t0, t);
        auto got = c.verify(b);
        EXPECT_NE(got, HERMC_AUTH_OK) << i << " " << bit;
        EXPECT_EQ(as_int(got), as_int(want)) << "byte " << i << " bit " << bit;
      }
  // The untouched packet, replayed to receivers that accepted it once.
  authenticator cpp_rx{cpp_config(), 1};
  c_side c{2};
  introduce_cpp_to_c(tx, c);
  challenge_nonce n;
  ASSERT_TRUE(cpp_rx.challenge(9, t0, n));
  byte_buffer reply = challenge_bytes(7, n);
  authenticator tx_again{cpp_config(), 9}; // counter 1 again: its reply
  tx_again.sign(reply, serial);
  auth_trailer t;
  ASSERT_EQ(cpp_rx.verify(reply.data(), reply.size(), serial, t0, t),
            auth_result::unknown_index);
  ASSERT_EQ(cpp_rx.accept_reply(t, n, t0), auth_result::ok);
  byte_buffer later = hello_bytes();
  tx.sign(later, serial); // counter 3
  for (int i = 0; i < 2; ++i) {
    auto want = cpp_rx.verify(later.data(), later.size(), serial, t0, t);
    auto got = c.verify(later);
    EXPECT_EQ(as_int(got), as_int(want));
    EXPECT_EQ(got, i == 0 ? HERMC_AUTH_OK : HERMC_AUTH_REPLAYED);
  }
}

TEST(hermc_auth_interop, the_data_policy_agrees_with_data_needs_auth) {
  struct row {
    uint16_t dst;
    uint8_t protocol;
    bytes payload;
    bool all;
  };
  const bytes answer{1, 2, 0}, request{1, 3, 0};
  const row rows[] = {
    {0x10, 1, answer, false},  {0x10, 1, request, false},
    {0x10, 0, answer, false},  {0x10, 1, {1}, false},
    {0x10, 1, {}, false},      {0xFFFF, 1, request, false},
    {0xFFFF, 0, {}, false},    {0x10, 0, {}, true},
    {0x10, 1, request, true},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(testing::Message() << r.dst << " " << int{r.protocol} << " "
                                    << r.payload.size() << " " << r.all);
    auto cfg = cpp_config();
    cfg.data = r.all ? auth_data::all : auth_data::discovery;
    c_side c{1};
    c.a.data_all = r.all ? 1 : 0;
    for (bool flooded : {false, true}) {
      if (flooded && r.dst != 0xFFFF)
        continue;
      data_header h{0x4E, r.dst, 32, 0, 2, r.protocol};
      h.flood_id = flooded ? 5 : 0;
      byte_buffer p;
      encode(h, p);
      auto at = p.size();
      p.insert(p.end(), r.payload.begin(), r.payload.end());
      bool want = data_needs_auth(cfg, r.dst, r.protocol, p.data() + at,
                                  p.size() - at);
      EXPECT_EQ(hermc_auth_must_sign(&c.a, p.data(), p.size()), want ? 1 : 0);
      // Received unsigned: dropped exactly when it must be signed.
      auto got = c.receive(p);
      EXPECT_EQ(got.pass, !want);
      EXPECT_EQ(got.body, want ? 0u : p.size());
    }
  }
  // Every control packet is signed; no network packet is not judged.
  c_side c{1};
  EXPECT_EQ(hermc_auth_must_sign(&c.a, hello_bytes().data(), 15), 1);
  const uint8_t junk[] = {0x28, 0x00};
  EXPECT_EQ(hermc_auth_must_sign(&c.a, junk, 2), 0);
  EXPECT_EQ(hermc_auth_must_sign(&c.a, nullptr, 0), 0);
}

// -- the C core's rules -------------------------------------------------------------

namespace {

/// `c` challenges `index` at `at` and returns the nonce.
bytes challenge(c_side& c, uint32_t index, uint32_t at) {
  bytes n(HERMC_AUTH_NONCE_SIZE);
  EXPECT_EQ(hermc_auth_challenge(&c.a, index, at, n.data()), 1);
  return n;
}

hermc_auth_result reply(c_side& c, uint32_t index, const bytes& nonce,
                        uint32_t at, uint64_t counter = 5) {
  hermc_auth_trailer t{counter, index, 9};
  return hermc_auth_accept_reply(&c.a, &t, nonce.data(), at);
}

} // namespace

TEST(hermc_auth, replies_count_only_with_the_live_nonce_in_time) {
  const uint32_t timeout = HERMC_AUTH_CHALLENGE_TIMEOUT_MS;
  struct row {
    const char* name;
    std::function<hermc_auth_result(c_side&)> run;
    hermc_auth_result expected;
  };
  const row rows[] = {
    {"the live nonce", [](c_side& c) { return reply(c, 7, challenge(c, 7, 0), 1000); },
     HERMC_AUTH_OK},
    {"at the timeout exactly",
     [&](c_side& c) { return reply(c, 7, challenge(c, 7, 100), 100 + timeout); },
     HERMC_AUTH_OK},
    {"after the timeout",
     [&](c_side& c) {
       auto n = challenge(c, 7, 100);
       auto r = reply(c, 7, n, 101 + timeout);
       EXPECT_EQ(reply(c, 7, n, 102 + timeout), HERMC_AUTH_CHALLENGE_FAILED)
         << "an expired challenge is gone";
       return r;
     },
     HERMC_AUTH_CHALLENGE_FAILED},
    {"no challenge", [](c_side& c) { return reply(c, 7, bytes(8, 1), 0); },
     HERMC_AUTH_CHALLENGE_FAILED},
    {"another index's nonce",
     [](c_side& c) { return reply(c, 8, challenge(c, 7, 0), 0); },
     HERMC_AUTH_CHALLENGE_FAILED},
    {"a replaced (stale) nonce",
     [](c_side& c) {
       auto old = challenge(c, 7, 0);
       auto fresh = challenge(c, 7, HERMC_AUTH_CHALLENGE_INTERVAL_MS);
       EXPECT_NE(old, fresh);
       return reply(c, 7, old, 400);
     },
     HERMC_AUTH_CHALLENGE_FAILED},
    {"a wrong nonce leaves the challenge live",
     [](c_side& c) {
       auto n = challenge(c, 7, 0);
       auto wrong = n;
       wrong[7] ^= 0x80;
       EXPECT_EQ(reply(c, 7, wrong, 10), HERMC_AUTH_CHALLENGE_FAILED);
       return reply(c, 7, n, 20);
     },
     HERMC_AUTH_OK},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    c_side c{1};
    EXPECT_EQ(r.run(c), r.expected);
  }
}

TEST(hermc_auth, a_passed_challenge_makes_the_index_known_with_the_replys_counter) {
  c_side tx{0x77}, rx{0x88};
  auto first = tx.sign(hello_bytes()); // counter 1
  EXPECT_EQ(rx.verify(first), HERMC_AUTH_UNKNOWN_INDEX);
  auto n = challenge(rx, 0x77, 0);
  challenge_nonce cn;
  std::memcpy(cn.data(), n.data(), 8);
  auto rep = tx.sign(challenge_bytes(7, cn)); // counter 2
  EXPECT_FALSE(rx.receive(rep, 5).pass);
  EXPECT_EQ(rx.a.counters.challenges_passed, 1u);
  EXPECT_EQ(rx.verify(first, 6), HERMC_AUTH_REPLAYED);
  EXPECT_EQ(rx.verify(tx.sign(hello_bytes()), 7), HERMC_AUTH_OK);
  // A gap in the counter is fine; going back is not.
  tx.a.counter += 100;
  auto later = tx.sign(hello_bytes());
  EXPECT_EQ(rx.verify(later, 8), HERMC_AUTH_OK);
  EXPECT_EQ(rx.verify(later, 9), HERMC_AUTH_REPLAYED);
}

TEST(hermc_auth, challenges_and_replies_are_rate_limited_per_index) {
  const uint32_t every = HERMC_AUTH_CHALLENGE_INTERVAL_MS;
  c_side c{1};
  uint8_t n[8];
  EXPECT_EQ(hermc_auth_challenge(&c.a, 5, 1000, n), 1);
  EXPECT_EQ(hermc_auth_challenge(&c.a, 5, 1000 + every - 1, n), 0);
  EXPECT_EQ(hermc_auth_challenge(&c.a, 6, 1000, n), 1); // another index
  EXPECT_EQ(hermc_auth_challenge(&c.a, 5, 1000 + every, n), 1);
  EXPECT_EQ(c.a.counters.challenges_sent, 3u);
  EXPECT_EQ(c.a.counters.challenges_limited, 1u);
  EXPECT_EQ(hermc_auth_may_reply(&c.a, 5, 0), 1);
  EXPECT_EQ(hermc_auth_may_reply(&c.a, 5, every - 1), 0);
  EXPECT_EQ(hermc_auth_may_reply(&c.a, 5, every), 1);
  // The requester table holds HERMC_AUTH_REQUESTERS indexes answered within
  // the interval; one more gets no reply until one of them is old enough.
  c_side d{1};
  for (uint32_t i = 0; i < HERMC_AUTH_REQUESTERS; ++i)
    EXPECT_EQ(hermc_auth_may_reply(&d.a, 100 + i, 0), 1);
  EXPECT_EQ(hermc_auth_may_reply(&d.a, 99, every - 1), 0);
  EXPECT_EQ(hermc_auth_may_reply(&d.a, 99, every), 1);
  EXPECT_EQ(d.a.counters.replies_limited, 1u);
}

TEST(hermc_auth, a_challenge_request_is_answered_whatever_its_index_once_per_interval) {
  c_side tx{0x31}, rx{0x32};
  challenge_nonce n{9, 8, 7, 6, 5, 4, 3, 2};
  auto req = tx.sign(challenge_bytes(6, n));
  auto r = rx.receive(req, 0);
  EXPECT_FALSE(r.pass);
  // Unknown index: our challenge first, then the reply with its nonce.
  ASSERT_EQ(r.challenge.size(), 30u);
  EXPECT_EQ(r.challenge[0], 0x16);
  ASSERT_EQ(r.reply.size(), 30u);
  EXPECT_EQ(bytes(r.reply.begin(), r.reply.begin() + 9), challenge_bytes(7, n));
  // The reply's tag is right at the requester (our index still unknown).
  EXPECT_EQ(tx.verify(r.reply), HERMC_AUTH_UNKNOWN_INDEX);
  // The same request again (a replay): neither goes out within 300 ms.
  r = rx.receive(req, 100);
  EXPECT_TRUE(r.challenge.empty());
  EXPECT_TRUE(r.reply.empty());
  EXPECT_EQ(rx.a.counters.replies, 1u);
  EXPECT_EQ(rx.a.counters.replies_limited, 1u);
}

TEST(hermc_auth, the_sender_table_is_bounded_and_forgets_only_silent_senders) {
  const uint32_t forget = HERMC_AUTH_FORGET_MS;
  c_side c{1};
  for (uint32_t i = 0; i < HERMC_AUTH_PEERS; ++i)
    EXPECT_EQ(reply(c, 100 + i, challenge(c, 100 + i, 0), 0), HERMC_AUTH_OK);
  // Full of senders heard just now: a new one is refused.
  EXPECT_EQ(reply(c, 200, challenge(c, 200, 10), 10), HERMC_AUTH_TABLE_FULL);
  EXPECT_EQ(c.a.counters.challenges_failed, 1u);
  // Once the one silent the longest has been silent FORGET_MS, it goes.
  EXPECT_EQ(reply(c, 201, challenge(c, 201, forget), forget), HERMC_AUTH_OK);
  EXPECT_EQ(c.a.counters.challenges_passed, HERMC_AUTH_PEERS + 1u);
  int known = 0;
  for (auto& p : c.a.peers)
    known += p.used && p.index == 201;
  EXPECT_EQ(known, 1);
}

TEST(hermc_auth, the_challenge_table_is_bounded_and_the_oldest_goes) {
  c_side c{1};
  std::vector<bytes> nonces;
  for (uint32_t i = 0; i <= HERMC_AUTH_CHALLENGES; ++i)
    nonces.push_back(challenge(c, 300 + i, i));
  // The first (oldest) was replaced; the others still pass.
  EXPECT_EQ(reply(c, 300, nonces[0], 50), HERMC_AUTH_CHALLENGE_FAILED);
  for (uint32_t i = 1; i <= HERMC_AUTH_CHALLENGES; ++i)
    EXPECT_EQ(reply(c, 300 + i, nonces[i], 50),
              i <= HERMC_AUTH_PEERS ? HERMC_AUTH_OK : HERMC_AUTH_TABLE_FULL);
}

TEST(hermc_auth, nonces_are_fresh_per_challenge_and_per_boot) {
  c_side a{1, 8, 1, 111}, b{1, 8, 1, 222}, a_again{1, 8, 1, 111};
  auto a1 = challenge(a, 5, 0), a2 = challenge(a, 6, 0);
  auto b1 = challenge(b, 5, 0), again = challenge(a_again, 5, 0);
  EXPECT_NE(a1, a2);
  EXPECT_NE(a1, b1);   // another salt (boot): another nonce
  EXPECT_EQ(a1, again); // derived: the same salt and count repeat it
}

TEST(hermc_auth, init_refuses_bad_keys_and_tag_lengths) {
  hermc_auth a;
  auto k = key_of(1, 64);
  EXPECT_EQ(hermc_auth_init(&a, k.data(), 16, 8, 1, 1), 0);
  EXPECT_EQ(hermc_auth_init(&a, k.data(), 64, 16, 1, 1), 0);
  EXPECT_EQ(hermc_auth_init(&a, k.data(), 15, 8, 1, 1), HERMC_AUTH_ERR_ARG);
  EXPECT_EQ(hermc_auth_init(&a, k.data(), 65, 8, 1, 1), HERMC_AUTH_ERR_ARG);
  EXPECT_EQ(hermc_auth_init(&a, nullptr, 32, 8, 1, 1), HERMC_AUTH_ERR_ARG);
  EXPECT_EQ(hermc_auth_init(&a, k.data(), 32, 12, 1, 1), HERMC_AUTH_ERR_ARG);
  // A 64-byte key signs as the C++ side does with it.
  EXPECT_EQ(hermc_auth_init(&a, k.data(), 64, 16, 3, 1), 0);
  auth_config cfg = cpp_config(16);
  cfg.key = k;
  authenticator cpp{cfg, 3};
  bytes p = hello_bytes();
  p.resize(15 + 29);
  ASSERT_EQ(hermc_auth_sign(&a, p.data(), 15, p.size(), serial), 44u);
  byte_buffer q = hello_bytes();
  cpp.sign(q, serial);
  EXPECT_EQ(p, q);
}

TEST(hermc_auth, sign_without_room_changes_nothing) {
  c_side c{1};
  bytes p = hello_bytes();
  p.resize(15 + 20);
  EXPECT_EQ(hermc_auth_sign(&c.a, p.data(), 15, p.size(), serial), 0u);
  EXPECT_EQ(c.a.counter, 1u);
  EXPECT_EQ(c.a.counters.signed_packets, 0u);
  EXPECT_EQ(bytes(p.begin() + 15, p.end()), bytes(20, 0));
  // A data packet that does not fit keeps its flags too.
  data_header h{0x4E, 0xFFFF, 32, 0, 2, 1};
  byte_buffer d;
  encode(h, d);
  d.resize(20);
  EXPECT_EQ(hermc_auth_sign(&c.a, d.data(), 8, d.size(), serial), 0u);
  EXPECT_EQ(d[6] & HERMC_AUTH_FLAG_A, 0);
}

TEST(hermc_auth, truncations_and_malformed_packets_are_dropped_and_counted) {
  c_side tx{5}, rx{6};
  auto p = tx.sign(hello_bytes());
  for (size_t n = 0; n < p.size(); ++n)
    EXPECT_NE(rx.verify(bytes(p.begin(), p.begin() + static_cast<long>(n))),
              HERMC_AUTH_OK)
      << n;
  // A trailer and nothing before it: no body.
  auto empty = tx.sign({});
  EXPECT_EQ(rx.verify(empty, 0, 1), HERMC_AUTH_TRUNCATED);
  // A signed data packet needs its header before the trailer.
  c_side c{7};
  auto before = c.a.counters;
  EXPECT_FALSE(c.receive({}).pass);
  EXPECT_FALSE(c.receive(hex("20")).pass);           // version 2
  EXPECT_FALSE(c.receive(hex("18")).pass);           // type 8
  EXPECT_FALSE(c.receive(hex("10 4E 00")).pass);     // short data header
  EXPECT_FALSE(c.receive(hex("10 4E 00 42 10 11 4E 01")).pass); // reserved flag
  EXPECT_FALSE(c.receive(hex("10 4E 00 42 10 11 1E 01 01 00 00 00")).pass); // flood to one
  EXPECT_EQ(c.a.counters.rx_malformed, before.rx_malformed + 6);
  // A challenge request with a right tag but 10 bytes: challenged (its
  // index is unknown), not answered, counted malformed.
  auto odd = tx.sign(hex("16 01 02 03 04 05 06 07 08 09"));
  auto r = c.receive(odd, 0);
  EXPECT_FALSE(r.pass);
  EXPECT_FALSE(r.challenge.empty());
  EXPECT_TRUE(r.reply.empty());
  EXPECT_EQ(c.a.counters.rx_malformed, before.rx_malformed + 7);
  // Every verification was counted once.
  auto& s = rx.a.counters;
  EXPECT_EQ(s.accepted + s.truncated + s.wrong_key_id + s.bad_tag + s.replayed
              + s.table_full + s.unknown_index,
            p.size() + 1);
}
