// Fuzz target: the C client's authentication receive path
// (apps/mcu/client/hermc_auth.h; docs/protocol.md, "Authentication"),
// judged against the C++ reference (routing/auth.hpp).
//
// The input is a script: a settings byte (tag length, link code, data
// policy), a count of mutations, the mutations (position, kind, value) and
// then a packet body. Properties checked for every input:
// - hermc_auth_receive never crashes and never reads out of bounds (ASan),
//   whatever the bytes; it passes on at most the bytes it got, only data
//   packets without flag A that the policy leaves unsigned (a receiver that
//   knows no index accepts nothing signed), and what it sends back is a
//   whole signed challenge (9 bytes plus the trailer) or nothing;
// - the raw input's tag is right neither for the C verifier nor for the C++
//   one under a key that signs nothing, and both give the same result;
// - a packet the C side signs is unknown_index for a fresh C and C++
//   receiver alike, with the trailer's index, counter and body length;
// - a mutated copy (bits flipped, bytes changed, cut short, bytes added)
//   gets the same result from the C and the C++ verifier, and never a right
//   tag when it differs from the signed packet;
// - every verification is counted exactly once.

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "hermc_auth.h"
#include "routing/auth.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

std::vector<uint8_t> key(uint8_t seed) {
  std::vector<uint8_t> k(32);
  for (size_t i = 0; i < k.size(); ++i)
    k[i] = static_cast<uint8_t>(seed ^ i);
  return k;
}

/// Key 0xA5 signs below (the fuzzer sees its tags); key 0x5A never signs.
void c_init(hermc_auth& a, uint8_t tag, uint32_t index, uint8_t seed = 0xA5) {
  auto k = key(seed);
  HERM_FUZZ_CHECK(hermc_auth_init(&a, k.data(), k.size(), tag, index, 7) == 0);
}

auth_config cpp_config(uint8_t tag, uint8_t seed = 0xA5) {
  auth_config c;
  c.key = key(seed);
  c.tag_bytes = tag;
  return c;
}

uint32_t total(const hermc_auth_counters& s) {
  return s.accepted + s.truncated + s.wrong_key_id + s.bad_tag + s.replayed
         + s.table_full + s.unknown_index;
}

bool right_tag(int r) {
  return r == HERMC_AUTH_OK || r == HERMC_AUTH_REPLAYED
         || r == HERMC_AUTH_TABLE_FULL || r == HERMC_AUTH_UNKNOWN_INDEX;
}

const authenticator::time_point t0{};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::reader in{data, size};
  auto settings = in.u8();
  uint8_t tag = (settings & 1) != 0 ? 16 : 8;
  auto link = static_cast<uint8_t>(settings >> 1 & 0x07);
  bool all = (settings & 0x10) != 0;
  size_t mutations = in.u8() % 8;
  fuzz::mutation ms[8];
  for (size_t i = 0; i < mutations; ++i)
    ms[i] = fuzz::mutation::read(in);
  size_t n = in.size;
  auto* body = in.take(n);
  // The raw input through the whole receive path, twice (state may change).
  {
    hermc_auth a;
    c_init(a, tag, 1);
    a.data_all = all ? 1 : 0;
    for (uint32_t now : {0u, 1000u}) {
      hermc_auth_out out;
      size_t got = 0;
      int pass = hermc_auth_receive(&a, data, size, link, now, &got, &out);
      HERM_FUZZ_CHECK(pass == 0 || pass == 1);
      HERM_FUZZ_CHECK(got <= size && (pass == 1 || got == 0));
      if (pass == 1) {
        HERM_FUZZ_CHECK(got == size && size >= 8 && data[0] == 0x10
                        && (data[6] & HERMC_AUTH_FLAG_A) == 0);
        HERM_FUZZ_CHECK(hermc_auth_must_sign(&a, data, size) == 0);
      }
      for (auto len : {out.challenge_len, out.reply_len})
        HERM_FUZZ_CHECK(len == 0 || len == 9 + HERMC_AUTH_HEAD_SIZE + tag);
    }
  }
  // The raw input has no right tag under a key that never signs.
  {
    hermc_auth a;
    c_init(a, tag, 1, 0x5A);
    authenticator cpp{cpp_config(tag, 0x5A), 1};
    hermc_auth_trailer ct{};
    auth_trailer t;
    auto c = hermc_auth_verify(&a, data, size, link, 0, 1, &ct);
    auto want = cpp.verify(data, size, link, t0, t);
    HERM_FUZZ_CHECK(!right_tag(c));
    HERM_FUZZ_CHECK(static_cast<int>(c) == static_cast<int>(want));
    HERM_FUZZ_CHECK(total(a.counters) == 1);
  }
  // The C side signs the body; fresh receivers on both sides agree.
  hermc_auth tx;
  c_init(tx, tag, 0x12345678);
  std::vector<uint8_t> pkt(body, body + n);
  pkt.resize(n + HERMC_AUTH_TRAILER_MAX);
  auto len = hermc_auth_sign(&tx, pkt.data(), n, pkt.size(), link);
  HERM_FUZZ_CHECK(len == n + HERMC_AUTH_HEAD_SIZE + tag);
  pkt.resize(len);
  {
    hermc_auth rx;
    c_init(rx, tag, 2);
    authenticator cpp{cpp_config(tag), 3};
    hermc_auth_trailer ct{};
    auth_trailer t;
    HERM_FUZZ_CHECK(hermc_auth_verify(&rx, pkt.data(), pkt.size(), link, 0, 0, &ct)
                    == HERMC_AUTH_UNKNOWN_INDEX);
    HERM_FUZZ_CHECK(cpp.verify(pkt.data(), pkt.size(), link, t0, t, 0)
                    == auth_result::unknown_index);
    HERM_FUZZ_CHECK(ct.index == 0x12345678 && ct.counter == 1 && ct.body_len == n);
    HERM_FUZZ_CHECK(t.index == ct.index && t.counter == ct.counter
                    && t.body_size == ct.body_len);
  }
  auto copy = pkt;
  for (size_t i = 0; i < mutations; ++i)
    ms[i].apply(copy);
  hermc_auth rx;
  c_init(rx, tag, 4);
  authenticator cpp{cpp_config(tag), 5};
  hermc_auth_trailer ct{};
  auth_trailer t;
  auto c = hermc_auth_verify(&rx, copy.data(), copy.size(), link, 0, 0, &ct);
  auto want = cpp.verify(copy.data(), copy.size(), link, t0, t, 0);
  HERM_FUZZ_CHECK(static_cast<int>(c) == static_cast<int>(want));
  if (copy != pkt)
    HERM_FUZZ_CHECK(!right_tag(c));
  else
    HERM_FUZZ_CHECK(c == HERMC_AUTH_UNKNOWN_INDEX);
  HERM_FUZZ_CHECK(total(rx.counters) == 1);
  return 0;
}
