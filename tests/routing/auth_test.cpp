// The authentication core (routing/auth.hpp): signing and verifying with
// truncated HMAC-SHA256, replay protection by per-sender counters, RFC
// 8967's challenge of unknown sender indexes (nonces, replies, timeouts,
// rate limits), the bounded tables, key files and their permissions, and
// the data header's authenticated flag.

#include <fstream>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "actors/asl_wire.hpp"
#include "actors/runtime/error.hpp"
#include "routing/auth.hpp"
#include "routing/metric.hpp"
#include "routing/wire.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = authenticator::time_point;

const time_point t0{};

std::vector<uint8_t> key_of(uint8_t seed, size_t n = 32) {
  std::vector<uint8_t> k(n);
  for (size_t i = 0; i < n; ++i)
    k[i] = static_cast<uint8_t>(seed + i * 7);
  return k;
}

auth_config config(uint8_t seed = 1, uint8_t tag = 8) {
  auth_config c;
  c.key = key_of(seed);
  c.tag_bytes = tag;
  return c;
}

byte_buffer hello_packet() {
  byte_buffer b;
  encode(hello{0x42, 0x1122334455667788, 7, 1000}, b);
  return b;
}

const uint8_t eth = static_cast<uint8_t>(link_code::ethernet);

/// Nonces start + 1, start + 2, ... (little endian): deterministic
/// challenges.
random_source counting_nonces(uint64_t start = 0) {
  auto next = std::make_shared<uint64_t>(start);
  return [next](uint8_t* out, size_t n) {
    ++*next;
    for (size_t i = 0; i < n; ++i)
      out[i] = static_cast<uint8_t>(i < 8 ? *next >> (8 * i) : 0);
    return true;
  };
}

/// `tx`'s signed reply to `nonce`.
byte_buffer reply_from(authenticator& tx, const challenge_nonce& nonce,
                       uint8_t link = eth) {
  byte_buffer p;
  encode(challenge_reply{nonce}, p);
  tx.sign(p, link);
  return p;
}

/// What `rx` makes of a reply from `tx` to `nonce` at `now`: the tag is
/// right and the index not known yet, then accept_reply decides.
auth_result deliver_reply(authenticator& tx, authenticator& rx,
                          const challenge_nonce& nonce, time_point now) {
  auto p = reply_from(tx, nonce);
  auth_trailer t;
  auto res = rx.verify(p.data(), p.size(), eth, now, t);
  if (res != auth_result::unknown_index)
    return res;
  EXPECT_EQ(t.index, tx.index());
  EXPECT_EQ(t.body_size, 9u);
  auto d = decode_challenge_reply(p.data(), t.body_size);
  EXPECT_TRUE(d);
  return rx.accept_reply(t, d ? d->nonce : challenge_nonce{}, now);
}

/// Makes `rx` know `tx`'s index the way the network does: `rx` challenges,
/// `tx` answers with a signed reply, `rx` accepts it. Uses one of `tx`'s
/// counter values.
void introduce(authenticator& tx, authenticator& rx, time_point now = t0) {
  challenge_nonce n;
  ASSERT_TRUE(rx.challenge(tx.index(), now, n));
  ASSERT_EQ(deliver_reply(tx, rx, n, now), auth_result::ok);
}

} // namespace

// -- signing and verifying ----------------------------------------------------------

TEST(auth, a_signed_packet_verifies_and_the_trailer_is_stripped) {
  for (uint8_t tag : {8, 16}) {
    SCOPED_TRACE(int{tag});
    authenticator tx{config(1, tag), 0xA1B2C3D4};
    authenticator rx{config(1, tag), 0x01};
    auto p = hello_packet();
    auto body = p.size();
    tx.sign(p, eth);
    EXPECT_EQ(p.size(), body + auth_head_size + tag);
    // Key id, index (little endian), counter 1.
    EXPECT_EQ(p[body], 1);
    EXPECT_EQ(p[body + 1], 0xD4);
    EXPECT_EQ(p[body + 4], 0xA1);
    EXPECT_EQ(p[body + 5], 1);
    // Once rx knows the index (counter 2, the reply), counter 3 verifies.
    introduce(tx, rx);
    auto q = hello_packet();
    tx.sign(q, eth);
    size_t got = 0;
    EXPECT_EQ(rx.verify(q.data(), q.size(), eth, t0, got), auth_result::ok);
    EXPECT_EQ(got, body);
    EXPECT_EQ(rx.stats().accepted, 1u);
    EXPECT_EQ(tx.stats().signed_packets, 3u);
    EXPECT_EQ(tx.counter(), 4u);
  }
}

TEST(auth, one_flipped_bit_anywhere_is_refused) {
  authenticator tx{config(), 9};
  auto p = hello_packet();
  tx.sign(p, eth);
  for (uint8_t tag : {8}) {
    authenticator rx{config(1, tag), 1};
    for (size_t i = 0; i < p.size(); ++i)
      for (int bit = 0; bit < 8; ++bit) {
        auto b = p;
        b[i] = static_cast<uint8_t>(b[i] ^ (1 << bit));
        size_t got = 0;
        auto r = rx.verify(b.data(), b.size(), eth, t0, got);
        EXPECT_NE(r, auth_result::ok) << "byte " << i << " bit " << bit;
        // The key id byte says wrong key id; every other byte breaks the tag.
        EXPECT_EQ(r, i == hello_packet().size() ? auth_result::wrong_key_id
                                                 : auth_result::bad_tag)
          << "byte " << i << " bit " << bit;
      }
    EXPECT_EQ(rx.stats().accepted, 0u);
    EXPECT_EQ(rx.senders(), 0u);
    EXPECT_EQ(rx.challenges(), 0u);
    // The unchanged packet's tag is still right (its index unknown):
    // refusals left no state.
    size_t got = 0;
    EXPECT_EQ(rx.verify(p.data(), p.size(), eth, t0, got),
              auth_result::unknown_index);
  }
}

TEST(auth, refusals_are_table_driven_and_counted) {
  struct row {
    const char* name;
    std::function<byte_buffer(authenticator& tx)> make;
    auth_config rx_cfg;
    uint8_t link;
    auth_result expected;
  };
  auto signed_hello = [](authenticator& tx) {
    auto p = hello_packet();
    tx.sign(p, eth);
    return p;
  };
  auto other_key_id = config();
  other_key_id.key_id = 2;
  auto no_challenge = config();
  no_challenge.challenge = false;
  std::vector<row> rows{
    // A right tag from an index never heard: challenged, not accepted.
    {"good", signed_hello, config(), eth, auth_result::unknown_index},
    {"good, challenge off", signed_hello, no_challenge, eth, auth_result::ok},
    {"wrong key", signed_hello, config(99), eth, auth_result::bad_tag},
    {"other key id", signed_hello, other_key_id, eth,
     auth_result::wrong_key_id},
    {"other link kind (pseudo-header)", signed_hello, config(),
     static_cast<uint8_t>(link_code::can20), auth_result::bad_tag},
    // The next three read the trailer from the wrong place: its key id
    // byte is a byte of the hello or of the index.
    {"other tag length", signed_hello, config(1, 16), eth,
     auth_result::wrong_key_id},
    {"unsigned", [](authenticator&) { return hello_packet(); }, config(), eth,
     auth_result::truncated},
    {"empty", [](authenticator&) { return byte_buffer{}; }, config(), eth,
     auth_result::truncated},
    {"trailer only",
     [](authenticator& tx) {
       byte_buffer p;
       tx.sign(p, eth);
       return p;
     },
     config(), eth, auth_result::truncated},
    {"tag cut short",
     [&](authenticator& tx) {
       auto p = signed_hello(tx);
       p.pop_back();
       return p;
     },
     config(), eth, auth_result::wrong_key_id},
    {"byte appended",
     [&](authenticator& tx) {
       auto p = signed_hello(tx);
       p.push_back(0);
       return p;
     },
     config(), eth, auth_result::wrong_key_id},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    authenticator tx{config(), 5};
    authenticator rx{r.rx_cfg, 6};
    auto p = r.make(tx);
    size_t got = 0;
    auto res = rx.verify(p.data(), p.size(), r.link, t0, got);
    EXPECT_EQ(res, r.expected) << to_string(res);
    auto& s = rx.stats();
    EXPECT_EQ(s.accepted + s.truncated + s.wrong_key_id + s.bad_tag
                + s.replayed + s.table_full + s.unknown_index,
              1u);
  }
}

TEST(auth, every_truncation_of_a_signed_packet_is_refused) {
  authenticator tx{config(), 5};
  authenticator rx{config(), 6};
  auto p = hello_packet();
  tx.sign(p, eth);
  for (size_t n = 0; n < p.size(); ++n) {
    size_t got = 0;
    EXPECT_NE(rx.verify(p.data(), n, eth, t0, got), auth_result::ok) << n;
  }
  // min_body: a packet needs its own header before the trailer.
  byte_buffer empty_body;
  tx.sign(empty_body, eth);
  size_t got = 0;
  EXPECT_EQ(rx.verify(empty_body.data(), empty_body.size(), eth, t0, got, 1),
            auth_result::truncated);
}

// -- replay protection -------------------------------------------------------------

TEST(auth, a_replayed_packet_is_refused) {
  authenticator tx{config(), 5};
  authenticator rx{config(), 6};
  introduce(tx, rx);
  auto p = hello_packet();
  tx.sign(p, eth);
  size_t got = 0;
  EXPECT_EQ(rx.verify(p.data(), p.size(), eth, t0, got), auth_result::ok);
  EXPECT_EQ(rx.verify(p.data(), p.size(), eth, t0 + 1s, got),
            auth_result::replayed);
  EXPECT_EQ(rx.stats().replayed, 1u);
}

TEST(auth, a_counter_going_backwards_is_refused_but_gaps_are_fine) {
  authenticator tx{config(), 5};
  authenticator rx{config(), 6};
  introduce(tx, rx);
  std::vector<byte_buffer> ps(4, hello_packet());
  for (auto& p : ps)
    tx.sign(p, eth);
  size_t got = 0;
  // 2, then 1 (backwards), then 4 (a gap: packets get lost), then 3.
  EXPECT_EQ(rx.verify(ps[1].data(), ps[1].size(), eth, t0, got), auth_result::ok);
  EXPECT_EQ(rx.verify(ps[0].data(), ps[0].size(), eth, t0, got),
            auth_result::replayed);
  EXPECT_EQ(rx.verify(ps[3].data(), ps[3].size(), eth, t0, got), auth_result::ok);
  EXPECT_EQ(rx.verify(ps[2].data(), ps[2].size(), eth, t0, got),
            auth_result::replayed);
}

TEST(auth, a_restarted_sender_with_a_new_index_is_accepted_after_its_challenge) {
  authenticator rx{config(), 6};
  authenticator before{config(), 100};
  introduce(before, rx);
  auto p = hello_packet();
  before.sign(p, eth);
  size_t got = 0;
  EXPECT_EQ(rx.verify(p.data(), p.size(), eth, t0, got), auth_result::ok);
  // After a restart: another index, the counter from 1 again. Its first
  // packet is challenged (a recording would look the same), its reply
  // makes it known, and what it signs next is accepted.
  authenticator after{config(), 200};
  auto q = hello_packet();
  after.sign(q, eth);
  auth_trailer t;
  EXPECT_EQ(rx.verify(q.data(), q.size(), eth, t0 + 1s, t),
            auth_result::unknown_index);
  EXPECT_EQ(t.index, 200u);
  EXPECT_EQ(t.counter, 1u);
  EXPECT_EQ(t.body_size, hello_packet().size());
  introduce(after, rx, t0 + 1s);
  EXPECT_EQ(rx.senders(), 2u);
  // The packet that prompted the challenge stays refused: its counter (1)
  // is below the reply's (2).
  EXPECT_EQ(rx.verify(q.data(), q.size(), eth, t0 + 1s, got),
            auth_result::replayed);
  auto r = hello_packet();
  after.sign(r, eth);
  EXPECT_EQ(rx.verify(r.data(), r.size(), eth, t0 + 1s, got), auth_result::ok);
}

TEST(auth, the_sender_table_is_bounded_and_forgets_only_silent_senders) {
  // The table fills on accepted challenges (and, with the challenge off,
  // on first packets): the same bound either way.
  for (bool challenge : {true, false}) {
    SCOPED_TRACE(challenge ? "challenge" : "challenge off");
    auto cfg = config();
    cfg.max_senders = 2;
    cfg.forget_after = 10s;
    cfg.challenge = challenge;
    authenticator rx{cfg, 6};
    authenticator s1{config(), 1}, s2{config(), 2}, s3{config(), 3};
    auto meet = [&](authenticator& tx, time_point now) {
      if (!challenge) {
        auto p = hello_packet();
        tx.sign(p, eth);
        size_t got = 0;
        return rx.verify(p.data(), p.size(), eth, now, got);
      }
      challenge_nonce n;
      EXPECT_TRUE(rx.challenge(tx.index(), now, n));
      return deliver_reply(tx, rx, n, now);
    };
    EXPECT_EQ(meet(s1, t0), auth_result::ok);
    EXPECT_EQ(meet(s2, t0 + 5s), auth_result::ok);
    EXPECT_EQ(meet(s3, t0 + 9s), auth_result::table_full);
    EXPECT_EQ(rx.senders(), 2u);
    // Sender 1 has been silent for 10 s: it makes room (the oldest goes).
    EXPECT_EQ(meet(s3, t0 + 10s), auth_result::ok);
    EXPECT_EQ(rx.senders(), 2u);
    // Sender 2 is still known: a packet it signed long ago is a replay.
    authenticator s2_again{config(), 2};
    auto old = hello_packet();
    s2_again.sign(old, eth);
    size_t got = 0;
    EXPECT_EQ(rx.verify(old.data(), old.size(), eth, t0 + 10s, got),
              auth_result::replayed);
  }
}

TEST(auth, a_packet_without_the_key_never_enters_the_sender_table) {
  auto cfg = config();
  cfg.max_senders = 1;
  authenticator rx{cfg, 6};
  for (uint32_t i = 0; i < 100; ++i) {
    authenticator forger{config(50), i};
    auto p = hello_packet();
    forger.sign(p, eth);
    size_t got = 0;
    EXPECT_EQ(rx.verify(p.data(), p.size(), eth, t0, got), auth_result::bad_tag);
    // Nor can its reply to a challenge make an index known.
    challenge_nonce n;
    ASSERT_TRUE(rx.challenge(i, t0 + std::chrono::seconds(i), n));
    EXPECT_EQ(deliver_reply(forger, rx, n, t0 + std::chrono::seconds(i)),
              auth_result::bad_tag);
  }
  EXPECT_EQ(rx.senders(), 0u);
  EXPECT_EQ(rx.stats().challenges_passed, 0u);
}

// -- RFC 8967 challenges ------------------------------------------------------------

TEST(auth, a_new_index_is_not_accepted_until_it_echoes_a_fresh_nonce) {
  authenticator tx{config(), 0x77};
  authenticator rx{config(), 6, counting_nonces()};
  auto p = hello_packet();
  tx.sign(p, eth);
  auth_trailer t;
  ASSERT_EQ(rx.verify(p.data(), p.size(), eth, t0, t), auth_result::unknown_index);
  EXPECT_EQ(t.index, 0x77u);
  EXPECT_EQ(rx.senders(), 0u);
  // Again: still not accepted, however often (a recording replayed).
  ASSERT_EQ(rx.verify(p.data(), p.size(), eth, t0, t), auth_result::unknown_index);
  challenge_nonce n;
  ASSERT_TRUE(rx.challenge(t.index, t0, n));
  EXPECT_EQ(n, (challenge_nonce{1, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(rx.challenges(), 1u);
  EXPECT_EQ(deliver_reply(tx, rx, n, t0 + 10ms), auth_result::ok);
  EXPECT_EQ(rx.challenges(), 0u);
  EXPECT_EQ(rx.senders(), 1u);
  auto q = hello_packet();
  tx.sign(q, eth);
  size_t got = 0;
  EXPECT_EQ(rx.verify(q.data(), q.size(), eth, t0 + 20ms, got), auth_result::ok);
  auto& s = rx.stats();
  EXPECT_EQ(s.unknown_index, 3u); // the hello twice, the reply
  EXPECT_EQ(s.challenges_sent, 1u);
  EXPECT_EQ(s.challenges_passed, 1u);
  EXPECT_EQ(s.accepted, 1u);
}

TEST(auth, challenge_replies_are_accepted_only_with_the_live_nonce_in_time) {
  // Each row: what rx challenged (and when), then which reply arrives.
  struct row {
    const char* name;
    std::function<auth_result(authenticator& tx, authenticator& rx)> run;
    auth_result expected;
    /// Challenges rx remembers afterwards.
    size_t live;
  };
  auto challenge = [](authenticator& rx, uint32_t index, time_point at) {
    challenge_nonce n{};
    EXPECT_TRUE(rx.challenge(index, at, n));
    return n;
  };
  std::vector<row> rows{
    {"the live nonce",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index(), t0);
       return deliver_reply(tx, rx, n, t0 + 1s);
     },
     auth_result::ok, 0},
    {"at the timeout exactly",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index(), t0);
       return deliver_reply(tx, rx, n, t0 + 30s);
     },
     auth_result::ok, 0},
    {"after the timeout (expired)",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index(), t0);
       return deliver_reply(tx, rx, n, t0 + 30s + 1ms);
     },
     auth_result::challenge_failed, 0},
    {"no challenge was sent",
     [&](authenticator& tx, authenticator& rx) {
       return deliver_reply(tx, rx, challenge_nonce{1}, t0);
     },
     auth_result::challenge_failed, 0},
    {"a stale nonce: the reply to an earlier challenge, replaced",
     [&](authenticator& tx, authenticator& rx) {
       auto old = challenge(rx, tx.index(), t0);
       challenge(rx, tx.index(), t0 + 300ms);
       return deliver_reply(tx, rx, old, t0 + 400ms);
     },
     auth_result::challenge_failed, 1},
    {"a recorded reply replayed to a new challenge",
     [&](authenticator& tx, authenticator& rx) {
       // Recorded when another receiver challenged tx; rx never sent it.
       authenticator elsewhere{config(), 9, counting_nonces(1000)};
       auto n = challenge(elsewhere, tx.index(), t0);
       auto recorded = reply_from(tx, n);
       challenge(rx, tx.index(), t0 + 1s);
       auth_trailer t;
       EXPECT_EQ(rx.verify(recorded.data(), recorded.size(), eth, t0 + 1s, t),
                 auth_result::unknown_index);
       return rx.accept_reply(t, n, t0 + 1s);
     },
     auth_result::challenge_failed, 1},
    {"one bit of the nonce flipped",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index(), t0);
       n[7] ^= 0x80;
       return deliver_reply(tx, rx, n, t0);
     },
     auth_result::challenge_failed, 1},
    {"another index's nonce",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index() + 1, t0);
       return deliver_reply(tx, rx, n, t0);
     },
     auth_result::challenge_failed, 1},
    {"the live nonce after a wrong one",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index(), t0);
       auto wrong = n;
       wrong[0] ^= 1;
       EXPECT_EQ(deliver_reply(tx, rx, wrong, t0), auth_result::challenge_failed);
       return deliver_reply(tx, rx, n, t0);
     },
     auth_result::ok, 0},
    {"the same reply twice",
     [&](authenticator& tx, authenticator& rx) {
       auto n = challenge(rx, tx.index(), t0);
       auto p = reply_from(tx, n);
       auth_trailer t;
       EXPECT_EQ(rx.verify(p.data(), p.size(), eth, t0, t),
                 auth_result::unknown_index);
       EXPECT_EQ(rx.accept_reply(t, n, t0), auth_result::ok);
       // Known now, and its counter is not above itself.
       return rx.verify(p.data(), p.size(), eth, t0, t);
     },
     auth_result::replayed, 0},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    authenticator tx{config(), 0x5000};
    authenticator rx{config(), 6, counting_nonces()};
    EXPECT_EQ(r.run(tx, rx), r.expected);
    EXPECT_EQ(rx.senders(), r.expected == auth_result::challenge_failed ? 0u : 1u);
    EXPECT_EQ(rx.challenges(), r.live);
  }
}

TEST(auth, challenges_are_rate_limited_per_index) {
  authenticator rx{config(), 6, counting_nonces()};
  challenge_nonce n{}, m{};
  EXPECT_TRUE(rx.challenge(1, t0, n));
  // A recording replayed fast: one request per index per 300 ms.
  EXPECT_FALSE(rx.challenge(1, t0 + 1ms, m));
  EXPECT_FALSE(rx.challenge(1, t0 + 299ms, m));
  EXPECT_EQ(m, challenge_nonce{});
  // Other indexes are not held back.
  EXPECT_TRUE(rx.challenge(2, t0 + 1ms, m));
  // After the interval: a new nonce, which replaces the old one.
  EXPECT_TRUE(rx.challenge(1, t0 + 300ms, m));
  EXPECT_NE(m, n);
  EXPECT_EQ(rx.challenges(), 2u);
  EXPECT_EQ(rx.stats().challenges_sent, 3u);
  EXPECT_EQ(rx.stats().challenges_limited, 2u);
}

TEST(auth, challenge_replies_are_rate_limited_per_requesting_index) {
  auto cfg = config();
  cfg.max_senders = 2;
  authenticator tx{cfg, 6};
  EXPECT_TRUE(tx.may_reply(1, t0));
  EXPECT_FALSE(tx.may_reply(1, t0 + 299ms));
  EXPECT_TRUE(tx.may_reply(2, t0 + 1ms));
  // Two requesters answered within the interval fill the table: a third
  // waits (a flood of replayed requests costs at most 2 replies / 300 ms).
  EXPECT_FALSE(tx.may_reply(3, t0 + 2ms));
  EXPECT_TRUE(tx.may_reply(1, t0 + 300ms));
  EXPECT_TRUE(tx.may_reply(3, t0 + 301ms));
  EXPECT_EQ(tx.stats().replies, 4u);
  EXPECT_EQ(tx.stats().replies_limited, 2u);
}

TEST(auth, the_challenge_table_is_bounded_and_the_oldest_challenge_goes) {
  auto cfg = config();
  cfg.max_senders = 2;
  authenticator rx{cfg, 6, counting_nonces()};
  authenticator s1{config(), 1}, s2{config(), 2}, s3{config(), 3};
  challenge_nonce n1, n2, n3;
  ASSERT_TRUE(rx.challenge(1, t0, n1));
  ASSERT_TRUE(rx.challenge(2, t0 + 1ms, n2));
  ASSERT_TRUE(rx.challenge(3, t0 + 2ms, n3));
  EXPECT_EQ(rx.challenges(), 2u);
  EXPECT_EQ(deliver_reply(s1, rx, n1, t0 + 3ms), auth_result::challenge_failed);
  EXPECT_EQ(deliver_reply(s3, rx, n3, t0 + 3ms), auth_result::ok);
  EXPECT_EQ(deliver_reply(s2, rx, n2, t0 + 3ms), auth_result::ok);
  // Expired challenges make room before live ones are dropped.
  ASSERT_TRUE(rx.challenge(4, t0, n1));
  ASSERT_TRUE(rx.challenge(5, t0 + 40s, n2));
  ASSERT_TRUE(rx.challenge(6, t0 + 40s, n3));
  EXPECT_EQ(rx.challenges(), 2u);
}

TEST(auth, no_challenge_without_random_bytes) {
  authenticator rx{config(), 6, [](uint8_t*, size_t) { return false; }};
  challenge_nonce n{};
  EXPECT_FALSE(rx.challenge(1, t0, n));
  EXPECT_EQ(rx.challenges(), 0u);
  // The default source (RAND_bytes) gives different nonces.
  authenticator real{config(), 7};
  challenge_nonce a{}, b{};
  ASSERT_TRUE(real.challenge(1, t0, a));
  ASSERT_TRUE(real.challenge(2, t0, b));
  EXPECT_NE(a, b);
}

TEST(auth, the_trailer_is_read_whenever_the_tag_is_right) {
  // A challenge request is answered whatever its index and counter, so
  // verify says who signed it on every result with a right tag.
  authenticator tx{config(), 0xABCD};
  authenticator rx{config(), 6};
  byte_buffer req;
  encode(challenge_request{{1, 2, 3, 4, 5, 6, 7, 8}}, req);
  tx.sign(req, eth);
  auth_trailer t;
  EXPECT_EQ(rx.verify(req.data(), req.size(), eth, t0, t),
            auth_result::unknown_index);
  EXPECT_EQ(t.index, 0xABCDu);
  EXPECT_EQ(t.counter, 1u);
  EXPECT_EQ(t.body_size, 9u);
  introduce(tx, rx);
  auth_trailer again;
  EXPECT_EQ(rx.verify(req.data(), req.size(), eth, t0, again),
            auth_result::replayed);
  EXPECT_EQ(again.index, 0xABCDu);
  EXPECT_EQ(again.body_size, 9u);
  auth_trailer none;
  req[0] ^= 1;
  EXPECT_EQ(rx.verify(req.data(), req.size(), eth, t0, none), auth_result::bad_tag);
  EXPECT_EQ(none.index, 0u);
  EXPECT_EQ(none.body_size, 0u);
}

// -- which data packets are signed ----------------------------------------------------

TEST(auth, discovery_constants_agree_with_the_asl_wire_format) {
  static_assert(discovery_protocol == asl_protocol);
  static_assert(discovery_answer_kind == static_cast<uint8_t>(asl_kind::answer));
  byte_buffer answer;
  encode(asl_message{asl_answer{7, {}}}, answer);
  ASSERT_GE(answer.size(), 2u);
  EXPECT_EQ(answer[1], discovery_answer_kind);
}

TEST(auth, the_data_policy_signs_broadcasts_and_discovery_answers_or_all) {
  struct row {
    auth_data mode;
    module_id dst;
    uint8_t protocol;
    byte_buffer payload;
    bool expected;
  };
  byte_buffer answer{asl_wire_version, 2, 0, 0};
  byte_buffer request{asl_wire_version, 3, 0, 0};
  std::vector<row> rows{
    {auth_data::discovery, broadcast_module, 0, {}, true},
    {auth_data::discovery, broadcast_module, 1, request, true},
    {auth_data::discovery, 0x10, 1, answer, true},
    {auth_data::discovery, 0x10, 1, request, false},
    {auth_data::discovery, 0x10, 0, answer, false},
    {auth_data::discovery, 0x10, 1, {asl_wire_version}, false},
    {auth_data::all, 0x10, 0, {}, true},
    {auth_data::all, 0x10, 1, request, true},
  };
  for (auto& r : rows) {
    auto cfg = config();
    cfg.data = r.mode;
    EXPECT_EQ(data_needs_auth(cfg, r.dst, r.protocol, r.payload.data(),
                              r.payload.size()),
              r.expected)
      << "mode " << int(r.mode) << " dst " << r.dst << " protocol "
      << int(r.protocol);
  }
  EXPECT_FALSE(data_needs_auth(auth_config{}, broadcast_module, 1, nullptr, 0));
}

TEST(auth_layout, the_authenticated_flag_is_data_header_bit_5) {
  data_header h{0x004E, 0x1042, 17, 2, 3, 1};
  h.authenticated = true;
  byte_buffer b;
  encode(h, b);
  EXPECT_EQ(b, byte_buffer({0x10, 0x4E, 0x00, 0x42, 0x10, 17, 0x2E, 0x01}));
  auto d = decode_data_header(b.data(), b.size());
  ASSERT_TRUE(d);
  EXPECT_TRUE(d->authenticated);
  set_authenticated(b.data(), false);
  EXPECT_EQ(b[6], 0x0E);
  EXPECT_FALSE(decode_data_header(b.data(), b.size())->authenticated);
}

TEST(auth_layout, a_signed_challenge_request_is_9_plus_13_plus_tag_bytes) {
  // The example of docs/protocol.md, "Authentication": nonce 01..08,
  // signed by index 0x0A0B0C0D with counter 7.
  authenticator tx{config(), 0x0A0B0C0D};
  for (int i = 0; i < 6; ++i) {
    byte_buffer skip;
    tx.sign(skip, eth);
  }
  byte_buffer p;
  encode(challenge_request{{1, 2, 3, 4, 5, 6, 7, 8}}, p);
  tx.sign(p, eth);
  EXPECT_EQ(p.size(), 9u + 13u + 8u);
  EXPECT_EQ(byte_buffer(p.begin(), p.begin() + 22),
            byte_buffer({0x16, 1, 2, 3, 4, 5, 6, 7, 8, 0x01, 0x0D, 0x0C, 0x0B,
                         0x0A, 7, 0, 0, 0, 0, 0, 0, 0}));
}

TEST(auth_layout, a_signed_hello_is_15_plus_13_plus_tag_bytes) {
  // The example of docs/protocol.md, "Authentication".
  authenticator tx{config(), 0x01020304};
  byte_buffer p;
  encode(hello{0x004E, 0x0807060504030201, 0xABCD, 1000}, p);
  EXPECT_EQ(p, byte_buffer({0x11, 0x4E, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05,
                            0x06, 0x07, 0x08, 0xCD, 0xAB, 0xE8, 0x03}));
  tx.sign(p, eth);
  EXPECT_EQ(p.size(), 15u + 13u + 8u);
  EXPECT_EQ(byte_buffer(p.begin() + 15, p.begin() + 28),
            byte_buffer({0x01, 0x04, 0x03, 0x02, 0x01, 1, 0, 0, 0, 0, 0, 0, 0}));
}

// -- key files ----------------------------------------------------------------------

namespace {

class auth_key_file : public ::testing::Test {
protected:
  std::string dir;

  void SetUp() override {
    char tmpl[] = "/tmp/herm-auth-test-XXXXXX";
    ASSERT_NE(::mkdtemp(tmpl), nullptr);
    dir = tmpl;
  }

  void TearDown() override {
    std::string cmd = "rm -rf '" + dir + "'";
    EXPECT_EQ(std::system(cmd.c_str()), 0);
  }

  std::string write(const std::string& name, const std::string& text,
                    mode_t mode = 0600) {
    auto path = dir + "/" + name;
    std::ofstream{path} << text;
    EXPECT_EQ(::chmod(path.c_str(), mode), 0);
    return path;
  }

  static std::string error_of(const caf::expected<std::vector<uint8_t>>& x) {
    return x ? std::string{"(no error)"} : render(x.error());
  }
};

const std::string hex64 = "00112233445566778899aabbccddeeff"
                          "00112233445566778899AABBCCDDEEFF";

} // namespace

TEST_F(auth_key_file, a_hex_key_with_mode_0600_or_0400_loads) {
  for (mode_t mode : {0600, 0400}) {
    auto path = write("k" + std::to_string(mode), hex64 + "\n", mode);
    auto k = load_key(path);
    ASSERT_TRUE(k) << error_of(k);
    ASSERT_EQ(k->size(), 32u);
    EXPECT_EQ((*k)[0], 0x00);
    EXPECT_EQ((*k)[1], 0x11);
    EXPECT_EQ((*k)[31], 0xFF);
  }
}

TEST_F(auth_key_file, bad_key_files_are_refused_naming_the_file_and_the_reason) {
  struct row {
    const char* name;
    std::string text;
    mode_t mode;
    std::string expected;
  };
  std::vector<row> rows{
    {"group-readable", hex64, 0640, "has mode 0640"},
    {"world-readable", hex64, 0604, "has mode 0604"},
    {"too-short", hex64.substr(0, 30), 0600, "holds a key of 15 bytes"},
    {"too-long", hex64 + hex64 + "00", 0600, "holds a key of 65 bytes"},
    {"odd", hex64 + "0", 0600, "odd number of hex digits"},
    {"not-hex", "correct horse battery staple and more", 0600,
     "must hold hex digits only"},
    {"empty", "", 0600, "holds a key of 0 bytes"},
    {"huge", std::string(2000, 'a'), 0600, "is 2000 bytes, at most 1024"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    auto path = write(r.name, r.text, r.mode);
    auto err = error_of(load_key(path));
    EXPECT_NE(err.find(path), std::string::npos) << err;
    EXPECT_NE(err.find(r.expected), std::string::npos) << err;
  }
}

TEST_F(auth_key_file, a_missing_file_a_directory_and_a_symlink_are_refused) {
  auto missing = error_of(load_key(dir + "/nope"));
  EXPECT_NE(missing.find(dir + "/nope: key file cannot be opened: No such file"),
            std::string::npos)
    << missing;
  auto d = error_of(load_key(dir));
  EXPECT_NE(d.find("is not a regular file"), std::string::npos) << d;
  auto target = write("target", hex64);
  auto link = dir + "/link";
  ASSERT_EQ(::symlink(target.c_str(), link.c_str()), 0);
  auto l = error_of(load_key(link));
  EXPECT_NE(l.find("is a symbolic link"), std::string::npos) << l;
}

TEST_F(auth_key_file, a_file_owned_by_another_user_is_refused) {
  auto path = write("theirs", hex64);
  if (::geteuid() != 0)
    GTEST_SKIP() << "needs root to give a file to another user (uid 65534)";
  ASSERT_EQ(::chown(path.c_str(), 65534, 65534), 0);
  auto err = error_of(load_key(path));
  EXPECT_NE(err.find("is owned by uid 65534, not by this user (uid 0)"),
            std::string::npos)
    << err;
}
