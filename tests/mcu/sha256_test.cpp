// The C client's SHA-256 and HMAC-SHA256 (apps/mcu/client/hermc_sha256.h):
// the FIPS 180-4 examples, RFC 4231's HMAC test cases, and random messages,
// keys and chunkings against OpenSSL's SHA256 and HMAC.

#include <cstring>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/sha.h>

#include "hermc_sha256.h"
#include "tests/mcu/mcu_bytes.hpp"

using mcu_test::bytes;
using mcu_test::hex;

namespace {

bytes of(const std::string& s) {
  return bytes(s.begin(), s.end());
}

/// hermc's digest of `m`, fed in chunks of `chunk` bytes (0: at once).
bytes sha(const bytes& m, size_t chunk = 0) {
  hermc_sha256 c;
  hermc_sha256_init(&c);
  size_t step = chunk == 0 ? m.size() : chunk;
  for (size_t at = 0; at < m.size(); at += step)
    hermc_sha256_update(&c, m.data() + at, std::min(step, m.size() - at));
  bytes out(32);
  hermc_sha256_final(&c, out.data());
  return out;
}

bytes hmac(const bytes& key, const bytes& m, size_t chunk = 0) {
  hermc_hmac_key k;
  hermc_hmac_sha256_key(&k, key.data(), key.size());
  hermc_sha256 c;
  hermc_hmac_sha256_begin(&c, &k);
  size_t step = chunk == 0 ? m.size() : chunk;
  for (size_t at = 0; at < m.size(); at += step)
    hermc_sha256_update(&c, m.data() + at, std::min(step, m.size() - at));
  bytes out(32);
  hermc_hmac_sha256_end(&c, &k, out.data());
  return out;
}

bytes openssl_sha(const bytes& m) {
  bytes out(32);
  SHA256(m.data(), m.size(), out.data());
  return out;
}

bytes openssl_hmac(const bytes& key, const bytes& m) {
  bytes out(32);
  unsigned len = 0;
  HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()), m.data(),
       m.size(), out.data(), &len);
  EXPECT_EQ(len, 32u);
  return out;
}

} // namespace

TEST(hermc_sha256, fips_180_4_examples) {
  struct row {
    std::string message;
    const char* digest;
  };
  const row rows[] = {
    {"", "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"},
    {"abc", "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"},
    {"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq",
     "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1"},
    {"abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmnoijklmnop"
     "jklmnopqklmnopqrlmnopqrsmnopqrstnopqrstu",
     "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.message);
    EXPECT_EQ(sha(of(r.message)), hex(r.digest));
    EXPECT_EQ(sha(of(r.message), 1), hex(r.digest));
    EXPECT_EQ(sha(of(r.message), 7), hex(r.digest));
  }
}

TEST(hermc_sha256, a_million_as_in_chunks_of_any_size) {
  bytes m(1000000, 'a');
  auto want = hex("cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
  EXPECT_EQ(sha(m), want);
  EXPECT_EQ(sha(m, 63), want);
  EXPECT_EQ(sha(m, 4096), want);
}

TEST(hermc_sha256, rfc_4231_hmac_test_cases) {
  struct row {
    const char* name;
    bytes key;
    bytes data;
    const char* tag; // case 5: the 128-bit truncation
  };
  const row rows[] = {
    {"1", bytes(20, 0x0b), of("Hi There"),
     "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7"},
    {"2", of("Jefe"), of("what do ya want for nothing?"),
     "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"},
    {"3", bytes(20, 0xaa), bytes(50, 0xdd),
     "773ea91e36800e46854db8ebd09181a72959098b3ef8c122d9635514ced565fe"},
    {"4", hex("0102030405060708090a0b0c0d0e0f10111213141516171819"),
     bytes(50, 0xcd),
     "82558a389a443c0ea4cc819899f2083a85f0faa3e578f8077a2e3ff46729665b"},
    {"5", bytes(20, 0x0c), of("Test With Truncation"),
     "a3b6167473100ee06e0c796c2955552b"},
    {"6", bytes(131, 0xaa),
     of("Test Using Larger Than Block-Size Key - Hash Key First"),
     "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54"},
    {"7", bytes(131, 0xaa),
     of("This is a test using a larger than block-size key and a larger than "
        "block-size data. The key needs to be hashed before being used by the "
        "HMAC algorithm."),
     "9b09ffa71b942fcb27635fbcd5b0e944bfdc63644f0713938a7f51535c3a35e2"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    auto want = hex(r.tag);
    auto got = hmac(r.key, r.data);
    EXPECT_EQ(bytes(got.begin(), got.begin() + static_cast<long>(want.size())),
              want);
    EXPECT_EQ(hmac(r.key, r.data, 3), got);
  }
}

TEST(hermc_sha256, every_length_around_the_block_boundaries_agrees_with_openssl) {
  std::mt19937 rng(17);
  for (size_t n = 0; n <= 300; ++n) {
    bytes m(n);
    for (auto& b : m)
      b = static_cast<uint8_t>(rng());
    SCOPED_TRACE(n);
    auto want = openssl_sha(m);
    EXPECT_EQ(sha(m), want);
    EXPECT_EQ(sha(m, 1 + rng() % 70), want);
  }
}

TEST(hermc_sha256, random_keys_and_messages_agree_with_openssl_hmac) {
  std::mt19937 rng(4231);
  for (int i = 0; i < 500; ++i) {
    // Keys of 0..150 bytes: shorter than, equal to and longer than a block.
    bytes key(rng() % 151), m(rng() % 400);
    for (auto& b : key)
      b = static_cast<uint8_t>(rng());
    for (auto& b : m)
      b = static_cast<uint8_t>(rng());
    SCOPED_TRACE(testing::Message() << "key " << key.size() << " message "
                                    << m.size());
    auto want = openssl_hmac(key, m);
    EXPECT_EQ(hmac(key, m), want);
    EXPECT_EQ(hmac(key, m, 1 + rng() % 80), want);
  }
}

TEST(hermc_sha256, a_prepared_key_serves_many_messages) {
  bytes key = hex("000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f");
  hermc_hmac_key k;
  hermc_hmac_sha256_key(&k, key.data(), key.size());
  for (size_t n : {0u, 9u, 64u, 100u}) {
    bytes m(n, static_cast<uint8_t>(n));
    hermc_sha256 c;
    hermc_hmac_sha256_begin(&c, &k);
    hermc_sha256_update(&c, m.data(), m.size());
    bytes out(32);
    hermc_hmac_sha256_end(&c, &k, out.data());
    EXPECT_EQ(out, openssl_hmac(key, m)) << n;
  }
}

TEST(hermc_sha256, the_constant_time_compare_finds_every_difference) {
  bytes a(16, 0x5a);
  EXPECT_EQ(hermc_equal_ct(a.data(), a.data(), 0), 1);
  EXPECT_EQ(hermc_equal_ct(a.data(), bytes(a).data(), a.size()), 1);
  for (size_t i = 0; i < a.size(); ++i)
    for (int bit = 0; bit < 8; ++bit) {
      auto b = a;
      b[i] = static_cast<uint8_t>(b[i] ^ (1 << bit));
      EXPECT_EQ(hermc_equal_ct(a.data(), b.data(), a.size()), 0) << i << " " << bit;
      // Only the first n bytes count.
      EXPECT_EQ(hermc_equal_ct(a.data(), b.data(), i), 1);
    }
}
