// Fuzz target: packet authentication (routing/auth.hpp; docs/protocol.md,
// "Authentication").
//
// The input is a script: a settings byte (tag length, link code), a count of
// mutations, the mutations (position, kind, value) and then the packet body.
// Properties checked for every input:
// - verify never crashes and never reads out of bounds (ASan), whatever
//   the bytes; the raw input's tag is never right under a key that signs
//   nothing (the fuzzer sees the tags of the key that signs, and may replay
//   them: replays of what a sender signed are the counter's business);
// - with the challenge (the default), a packet signed with the key is not
//   accepted from an index never heard (unknown_index, with the trailer's
//   index, counter and the body's size); a reply echoing a nonce the input
//   altered never passes and leaves the challenge live; the reply with the
//   nonce passes, after which the first packet is a replay (its counter is
//   below the reply's);
// - with the challenge off, the packet verifies once and is refused as a
//   replay the second time;
// - a mutated copy (bits flipped, bytes changed, cut short, bytes added)
//   that differs from the signed packet never has a right tag, for a
//   receiver that has never heard the sender (no replay state to help it);
// - every verification is counted exactly once.

#include <cstddef>
#include <cstdint>

#include "routing/auth.hpp"
#include "routing/wire.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

/// Key 0xA5 signs below, so the fuzzer sees its tags (libFuzzer learns the
/// bytes of compared buffers and can replay them); key 0x5A never signs.
auth_config config(uint8_t tag, uint8_t seed = 0xA5, bool challenge = true) {
  auth_config c;
  c.challenge = challenge;
  c.key.assign(32, 0);
  for (size_t i = 0; i < c.key.size(); ++i)
    c.key[i] = static_cast<uint8_t>(seed ^ i);
  c.tag_bytes = tag;
  return c;
}

uint64_t total(const auth_stats& s) {
  return s.accepted + s.truncated + s.wrong_key_id + s.bad_tag + s.replayed
         + s.table_full + s.unknown_index;
}

/// Whether verify found the tag right.
bool right_tag(auth_result r) {
  return r == auth_result::ok || r == auth_result::replayed
         || r == auth_result::table_full || r == auth_result::unknown_index;
}

/// Nonces 1, 2, ... (no property depends on their values).
bool counting(uint8_t* out, size_t n) {
  static uint64_t next = 0;
  ++next;
  for (size_t i = 0; i < n; ++i)
    out[i] = static_cast<uint8_t>(i < 8 ? next >> (8 * i) : 0);
  return true;
}

const authenticator::time_point t0{};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::reader in{data, size};
  auto settings = in.u8();
  uint8_t tag = (settings & 1) != 0 ? 16 : 8;
  auto link = static_cast<uint8_t>(settings >> 1 & 0x07);
  size_t mutations = in.u8() % 8;
  fuzz::mutation ms[8];
  for (size_t i = 0; i < mutations; ++i)
    ms[i] = fuzz::mutation::read(in);
  size_t n = in.size;
  auto* body = in.take(n);
  // The raw input is not signed with a key that never signs anything.
  {
    authenticator rx{config(tag, 0x5A), 1};
    auth_trailer t;
    HERM_FUZZ_CHECK(!right_tag(rx.verify(data, size, link, t0, t)));
    HERM_FUZZ_CHECK(total(rx.stats()) == 1);
  }
  authenticator tx{config(tag), 0x12345678};
  byte_buffer pkt(body, body + n);
  tx.sign(pkt, link);
  HERM_FUZZ_CHECK(pkt.size() == n + auth_head_size + tag);
  // With the challenge: not accepted until the sender echoes the nonce.
  {
    authenticator rx{config(tag), 2, counting};
    auth_trailer t;
    HERM_FUZZ_CHECK(rx.verify(pkt.data(), pkt.size(), link, t0, t, 0)
                    == auth_result::unknown_index);
    HERM_FUZZ_CHECK(t.index == 0x12345678 && t.counter == 1 && t.body_size == n);
    HERM_FUZZ_CHECK(rx.senders() == 0);
    challenge_nonce nonce;
    HERM_FUZZ_CHECK(rx.challenge(t.index, t0, nonce));
    byte_buffer reply;
    encode(challenge_reply{nonce}, reply);
    tx.sign(reply, link);
    auth_trailer r;
    HERM_FUZZ_CHECK(rx.verify(reply.data(), reply.size(), link, t0, r)
                    == auth_result::unknown_index);
    auto echoed = decode_challenge_reply(reply.data(), r.body_size);
    HERM_FUZZ_CHECK(echoed && echoed->nonce == nonce);
    // A nonce the input altered never passes, and leaves the challenge.
    auto altered = nonce;
    if (mutations > 0)
      altered[ms[0].pos % altered.size()] ^= ms[0].value;
    if (altered != nonce) {
      HERM_FUZZ_CHECK(rx.accept_reply(r, altered, t0)
                      == auth_result::challenge_failed);
      HERM_FUZZ_CHECK(rx.challenges() == 1 && rx.senders() == 0);
    }
    HERM_FUZZ_CHECK(rx.accept_reply(r, nonce, t0) == auth_result::ok);
    HERM_FUZZ_CHECK(rx.senders() == 1 && rx.challenges() == 0);
    HERM_FUZZ_CHECK(rx.verify(pkt.data(), pkt.size(), link, t0, t, 0)
                    == auth_result::replayed);
    HERM_FUZZ_CHECK(total(rx.stats()) == 3);
  }
  // Without it: accepted once, then a replay.
  {
    authenticator rx{config(tag, 0xA5, false), 2};
    size_t got = 0;
    HERM_FUZZ_CHECK(rx.verify(pkt.data(), pkt.size(), link, t0, got, 0)
                    == auth_result::ok);
    HERM_FUZZ_CHECK(got == n);
    HERM_FUZZ_CHECK(rx.verify(pkt.data(), pkt.size(), link, t0, got, 0)
                    == auth_result::replayed);
    HERM_FUZZ_CHECK(total(rx.stats()) == 2);
  }
  auto copy = pkt;
  for (size_t i = 0; i < mutations; ++i)
    ms[i].apply(copy);
  authenticator rx{config(tag), 3};
  auth_trailer t;
  auto res = rx.verify(copy.data(), copy.size(), link, t0, t, 0);
  if (copy != pkt)
    HERM_FUZZ_CHECK(!right_tag(res));
  else
    HERM_FUZZ_CHECK(res == auth_result::unknown_index);
  // Another link kind (the pseudo-header) never verifies.
  authenticator other{config(tag), 4};
  HERM_FUZZ_CHECK(!right_tag(other.verify(pkt.data(), pkt.size(),
                                          static_cast<uint8_t>(link ^ 1), t0,
                                          t, 0)));
  return 0;
}
