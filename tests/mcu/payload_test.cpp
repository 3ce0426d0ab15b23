// Specification of the C client's APO payloads (apps/mcu/client/
// hermc_payload.h): the golden payload of docs/protocol.md ("Worked
// example"), which tests/actors/marshal_test.cpp pins for the C++ codec,
// the SRF04 reading, and what the reader refuses.

#include <gtest/gtest.h>

#include <string>

#include "apps/mcu/client/hermc_payload.h"
#include "tests/mcu/mcu_bytes.hpp"

using namespace mcu_test;

namespace {

const char* golden = "01 02"
                     "04 40 75 31 36 02 01"
                     "12 68 65 72 6D 3A 3A 77 72 69 74 65 5F 70 61 63 6B 65 74"
                     "07 00 00 00 00 00 00 00 01 02 DE AD";

TEST(hermc_payload_layout, writes_the_golden_payload) {
  uint8_t buf[64];
  const uint8_t dead[] = {0xDE, 0xAD};
  hermc_pw w;
  hermc_pw_begin(&w, buf, sizeof buf, 2);
  hermc_pw_element(&w, "@u16");
  hermc_pw_u16(&w, 0x0102);
  hermc_pw_element(&w, "herm::write_packet");
  hermc_pw_u64(&w, 7);
  hermc_pw_u8(&w, 1);
  hermc_pw_bytes(&w, dead, 2);
  auto n = hermc_pw_finish(&w);
  EXPECT_EQ(n, 40u);
  EXPECT_EQ(take(buf, n), hex(golden));
}

TEST(hermc_payload_layout, reads_the_golden_payload) {
  auto b = hex(golden);
  hermc_pr r;
  EXPECT_EQ(hermc_pr_begin(&r, b.data(), b.size()), 2u);
  EXPECT_TRUE(hermc_pr_element(&r, "@u16"));
  EXPECT_EQ(hermc_pr_u16(&r), 0x0102);
  EXPECT_TRUE(hermc_pr_element(&r, "herm::write_packet"));
  EXPECT_EQ(hermc_pr_u64(&r), 7u);
  EXPECT_EQ(hermc_pr_u8(&r), 1);
  const uint8_t* p = nullptr;
  size_t n = 0;
  hermc_pr_bytes(&r, &p, &n);
  ASSERT_EQ(n, 2u);
  EXPECT_EQ(take(p, n), hex("DE AD"));
  EXPECT_EQ(hermc_pr_finish(&r), HERMC_PR_OK);
}

TEST(hermc_payload_layout, the_empty_message_is_01_00) {
  uint8_t buf[4];
  hermc_pw w;
  hermc_pw_begin(&w, buf, sizeof buf, 0);
  EXPECT_EQ(take(buf, hermc_pw_finish(&w)), hex("01 00"));
}

TEST(hermc_payload_layout, every_primitive_little_endian_and_bools_00_01) {
  uint8_t buf[64];
  hermc_pw w;
  hermc_pw_begin(&w, buf, sizeof buf, 1);
  hermc_pw_element(&w, "t");
  hermc_pw_u32(&w, 0x01020304);
  hermc_pw_u64(&w, 0x0102030405060708ull);
  hermc_pw_bool(&w, 5);
  hermc_pw_bool(&w, 0);
  hermc_pw_str(&w, "hi");
  auto n = hermc_pw_finish(&w);
  EXPECT_EQ(take(buf, n), hex("01 01 01 74 04 03 02 01 08 07 06 05 04 03 02 "
                              "01 01 00 02 68 69"));
  hermc_pr r;
  EXPECT_EQ(hermc_pr_begin(&r, buf, n), 1u);
  EXPECT_TRUE(hermc_pr_element(&r, "t"));
  EXPECT_EQ(hermc_pr_u32(&r), 0x01020304u);
  EXPECT_EQ(hermc_pr_u64(&r), 0x0102030405060708ull);
  EXPECT_EQ(hermc_pr_bool(&r), 1);
  EXPECT_EQ(hermc_pr_bool(&r), 0);
  const uint8_t* s;
  size_t len;
  hermc_pr_bytes(&r, &s, &len);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(s), len), "hi");
  EXPECT_EQ(hermc_pr_finish(&r), HERMC_PR_OK);
}

TEST(hermc_payload_layout, lengths_are_shortest_leb128) {
  std::string s(300, 'x');
  uint8_t buf[400];
  hermc_pw w;
  hermc_pw_begin(&w, buf, sizeof buf, 1);
  hermc_pw_element(&w, "@str");
  hermc_pw_str(&w, s.c_str());
  auto n = hermc_pw_finish(&w);
  ASSERT_EQ(n, 2u + 5u + 2u + 300u);
  EXPECT_EQ(take(buf + 7, 2), hex("AC 02"));
}

TEST(hermc_payload_layout, the_srf04_reading) {
  hermc_srf04_reading x{7, 1768, 10309};
  uint8_t buf[40];
  auto n = hermc_srf04_encode(&x, buf, sizeof buf);
  EXPECT_EQ(take(buf, n),
            hex("01 01 1A 68 65 72 6D 3A 3A 68 65 72 6D 64 3A 3A 73 72 66 30 "
                "34 5F 72 65 61 64 69 6E 67 07 00 E8 06 45 28 00 00"));
  hermc_srf04_reading back{};
  ASSERT_EQ(hermc_srf04_decode(buf, n, &back), HERMC_PR_OK);
  EXPECT_EQ(back.seq, 7);
  EXPECT_EQ(back.distance_mm, 1768);
  EXPECT_EQ(back.echo_us, 10309u);
  EXPECT_EQ(hermc_srf04_encode(&x, buf, n - 1), 0u);
}

TEST(hermc_payload_writer, overflow_is_sticky_and_finish_says_0) {
  uint8_t buf[8];
  hermc_pw w;
  hermc_pw_begin(&w, buf, sizeof buf, 1);
  hermc_pw_element(&w, "@u64");
  hermc_pw_u64(&w, 1); // does not fit
  hermc_pw_u8(&w, 1);  // would fit, but the writer has overflowed
  EXPECT_EQ(hermc_pw_finish(&w), 0u);
  hermc_pw_begin(&w, buf, sizeof buf, 1);
  hermc_pw_element(&w, ""); // type names are 1..255 bytes
  EXPECT_EQ(hermc_pw_finish(&w), 0u);
}

struct refusal {
  const char* what;
  const char* bytes;
  hermc_payload_error error;
};

TEST(hermc_payload_reader, refuses_what_a_strict_herm_receiver_refuses) {
  // Each reads one element "t" holding a bool then a string.
  const refusal cases[] = {
    {"version 2", "02 01 01 74 01 00", HERMC_PR_BAD_VERSION},
    {"count padded", "01 81 00 01 74 01 00", HERMC_PR_BAD_LEB128},
    {"count above the bytes", "01 09 01 74 01 00", HERMC_PR_OVER_BOUND},
    {"name of another type", "01 01 01 75 01 00", HERMC_PR_WRONG_TYPE},
    {"bool 2", "01 01 01 74 02 00", HERMC_PR_BAD_BOOL},
    {"string length padded", "01 01 01 74 01 80 00", HERMC_PR_BAD_LEB128},
    {"string cut", "01 01 01 74 01 03 61", HERMC_PR_OVER_BOUND},
    {"length field cut", "01 01 01 74 01 80", HERMC_PR_TRUNCATED},
    {"bool missing", "01 01 01 74", HERMC_PR_TRUNCATED},
    {"trailing byte", "01 01 01 74 01 00 00", HERMC_PR_TRAILING},
    {"empty", "", HERMC_PR_TRUNCATED},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto b = hex(c.bytes);
    hermc_pr r;
    (void)hermc_pr_begin(&r, b.data(), b.size());
    (void)hermc_pr_element(&r, "t");
    (void)hermc_pr_bool(&r);
    const uint8_t* p;
    size_t n;
    hermc_pr_bytes(&r, &p, &n);
    EXPECT_EQ(hermc_pr_finish(&r), c.error);
  }
}

TEST(hermc_payload_reader, a_tenth_leb128_byte_above_01_is_refused) {
  auto b = hex("01 FF FF FF FF FF FF FF FF FF 02");
  hermc_pr r;
  EXPECT_EQ(hermc_pr_begin(&r, b.data(), b.size()), 0u);
  EXPECT_EQ(r.error, HERMC_PR_BAD_LEB128);
}

TEST(hermc_payload_reader, every_truncation_of_a_reading_is_refused) {
  hermc_srf04_reading x{1, 2, 3}, back{};
  uint8_t buf[40];
  auto n = hermc_srf04_encode(&x, buf, sizeof buf);
  for (size_t len = 0; len < n; ++len)
    EXPECT_NE(hermc_srf04_decode(buf, len, &back), HERMC_PR_OK) << len;
}

} // namespace
