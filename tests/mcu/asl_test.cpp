// Specification of the C client's APO messages (apps/mcu/client/
// hermc_asl.h): the byte strings of docs/protocol.md, "APO messages", which
// tests/actors/asl_wire_test.cpp pins for the C++ codec, and what the
// decoder refuses.

#include <gtest/gtest.h>

#include <deque>
#include <string>

#include "apps/mcu/client/hermc_asl.h"
#include "tests/mcu/mcu_bytes.hpp"

using namespace mcu_test;

namespace {

std::string str(hermc_bytes b) {
  return std::string(reinterpret_cast<const char*>(b.data), b.size);
}

/// Decodes a copy of `b` kept for the rest of the test program: the
/// message points into it.
hermc_asl_msg decoded(const bytes& b) {
  static std::deque<bytes> kept;
  kept.push_back(b);
  hermc_asl_msg m{};
  EXPECT_EQ(hermc_asl_decode(kept.back().data(), b.size(), &m), HERMC_ASL_OK)
    << to_hex(b);
  return m;
}

TEST(hermc_asl_layout, query) {
  uint8_t out[32];
  auto n = hermc_asl_query_encode(0x01020304, HERMC_BY_TYPE, "cam", 3, out,
                                  sizeof out);
  EXPECT_EQ(take(out, n), hex("01 01 04 03 02 01 01 03 63 61 6D"));
  auto m = decoded(take(out, n));
  EXPECT_EQ(m.kind, HERMC_ASL_QUERY);
  EXPECT_EQ(m.id32, 0x01020304u);
  EXPECT_EQ(m.by, HERMC_BY_TYPE);
  EXPECT_EQ(str(m.text), "cam");
  n = hermc_asl_query_encode(5, HERMC_BY_ANY, "ignored", 7, out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 01 05 00 00 00 02 00"));
}

TEST(hermc_asl_layout, answer) {
  uint8_t out[32];
  auto n = hermc_asl_answer_begin(0x0A, 2, out, sizeof out);
  n += hermc_asl_answer_entry_encode(0x11, "a", 1, "t", 1, out + n,
                                     sizeof out - n);
  n += hermc_asl_answer_entry_encode(0x22, "", 0, "", 0, out + n,
                                     sizeof out - n);
  EXPECT_EQ(take(out, n),
            hex("01 02 0A 00 00 00 02 11 00 00 00 01 61 01 74 22 00 00 00 00 00"));
  auto m = decoded(take(out, n));
  EXPECT_EQ(m.kind, HERMC_ASL_ANSWER);
  EXPECT_EQ(m.count, 2);
  hermc_asl_entry e{};
  size_t at = 0;
  ASSERT_TRUE(hermc_asl_answer_entry(&m, &at, &e));
  EXPECT_EQ(e.apo, 0x11u);
  EXPECT_EQ(str(e.name), "a");
  EXPECT_EQ(str(e.type), "t");
  ASSERT_TRUE(hermc_asl_answer_entry(&m, &at, &e));
  EXPECT_EQ(e.apo, 0x22u);
  EXPECT_EQ(e.name.size, 0u);
  EXPECT_FALSE(hermc_asl_answer_entry(&m, &at, &e));
}

TEST(hermc_asl_layout, request_and_one_way_request) {
  uint8_t out[32];
  auto n = hermc_asl_request_header(0x0807060504030201ull, 0x2A, 0, 0, out,
                                    sizeof out);
  out[n++] = 0xDE;
  out[n++] = 0xAD;
  EXPECT_EQ(take(out, n),
            hex("01 03 01 02 03 04 05 06 07 08 2A 00 00 00 DE AD"));
  auto m = decoded(take(out, n));
  EXPECT_EQ(m.request_id, 0x0807060504030201ull);
  EXPECT_EQ(m.id32, 0x2Au);
  EXPECT_EQ(m.oneway, 0);
  EXPECT_EQ(take(m.payload.data, m.payload.size), hex("DE AD"));
  n = hermc_asl_request_header(0, 0x2A, 0, 1, out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 03 00 00 00 00 00 00 00 00 2A 00 00 00"));
  EXPECT_EQ(decoded(take(out, n)).oneway, 1);
}

TEST(hermc_asl_layout, responses) {
  uint8_t out[64];
  auto n = hermc_asl_response_ok_header(0x0807060504030201ull, out, sizeof out);
  out[n++] = 0xBE;
  out[n++] = 0xEF;
  EXPECT_EQ(take(out, n), hex("01 04 01 02 03 04 05 06 07 08 01 BE EF"));
  n = hermc_asl_response_error_encode(0x0807060504030201ull,
                                      HERMC_ERROR_CATEGORY_HERM, 16, "gone", 4,
                                      out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 04 01 02 03 04 05 06 07 08 00"
                              "F2 AD B6 0F 00 00 00 00 10"
                              "04 67 6F 6E 65"));
  auto m = decoded(take(out, n));
  EXPECT_EQ(m.ok, 0);
  EXPECT_EQ(m.err_category, HERMC_ERROR_CATEGORY_HERM);
  EXPECT_EQ(m.err_code, 16);
  EXPECT_EQ(str(m.text), "gone");
}

TEST(hermc_asl_layout, an_error_context_above_255_bytes_is_cut) {
  std::string ctx(300, 'x');
  uint8_t out[300];
  auto n = hermc_asl_response_error_encode(1, 2, 3, ctx.data(), ctx.size(),
                                           out, sizeof out);
  ASSERT_EQ(n, 21u + 255u);
  EXPECT_EQ(decoded(take(out, n)).text.size, 255u);
}

TEST(hermc_asl_layout, topics) {
  uint8_t out[32];
  auto n = hermc_asl_subscribe_encode("pose", 4, 1000, out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 09 04 70 6F 73 65 E8 03 00 00"));
  EXPECT_EQ(decoded(take(out, n)).u32, 1000u);
  n = hermc_asl_publish_header("pose", 4, 7, out, sizeof out);
  out[n++] = 1;
  out[n++] = 2;
  EXPECT_EQ(take(out, n), hex("01 0B 04 70 6F 73 65 07 00 00 00 01 02"));
  n = hermc_asl_advertise_encode("pose", 4, out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 0C 04 70 6F 73 65"));
  auto u = decoded(hex("01 0A 04 70 6F 73 65"));
  EXPECT_EQ(u.kind, HERMC_ASL_UNSUBSCRIBE);
  EXPECT_EQ(str(u.text), "pose");
}

TEST(hermc_asl_layout, reliable_request_and_ack) {
  uint8_t out[32];
  auto n = hermc_asl_request_header(0x0807060504030201ull, 0x2A, 1, 0, out,
                                    sizeof out);
  out[n++] = 0xDE;
  out[n++] = 0xAD;
  EXPECT_EQ(take(out, n),
            hex("01 0D 01 02 03 04 05 06 07 08 2A 00 00 00 00 DE AD"));
  n = hermc_asl_request_header(5, 0x2A, 1, 1, out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 0D 05 00 00 00 00 00 00 00 2A 00 00 00 01"));
  EXPECT_EQ(decoded(take(out, n)).oneway, 1);
  n = hermc_asl_ack_encode(0x0807060504030201ull, out, sizeof out);
  EXPECT_EQ(take(out, n), hex("01 0E 01 02 03 04 05 06 07 08"));
}

TEST(hermc_asl_layout, watch_down_and_withdraw_decode) {
  EXPECT_EQ(decoded(hex("01 05 2A 00 00 00")).id32, 0x2Au);
  EXPECT_EQ(decoded(hex("01 06 2A 00 00 00")).kind, HERMC_ASL_UNWATCH);
  auto d = decoded(hex("01 07 2A 00 00 00 F2 AD B6 0F 00 00 00 00 10 00"));
  EXPECT_EQ(d.err_code, 16);
  auto w = decoded(hex("01 08 2A 00 00 00 03 63 61 6D"));
  EXPECT_EQ(str(w.text), "cam");
}

TEST(hermc_asl_layout, encoders_refuse_what_does_not_fit) {
  uint8_t out[16];
  EXPECT_EQ(hermc_asl_query_encode(1, HERMC_BY_NAME, "sonar", 5, out, 12), 0u);
  EXPECT_EQ(hermc_asl_answer_begin(1, 65, out, sizeof out), 0u);
  EXPECT_EQ(hermc_asl_ack_encode(0, out, sizeof out), 0u);
  EXPECT_EQ(hermc_asl_response_ok_header(0, out, sizeof out), 0u);
  EXPECT_EQ(hermc_asl_request_header(0, 1, 1, 1, out, sizeof out), 0u);
  std::string big(256, 'a');
  uint8_t wide[300];
  EXPECT_EQ(hermc_asl_advertise_encode(big.data(), big.size(), wide,
                                       sizeof wide), 0u);
}

struct refusal {
  const char* what;
  const char* bytes;
  hermc_asl_error error;
};

TEST(hermc_asl_malformed, refused_as_the_cpp_decoder_refuses) {
  const refusal cases[] = {
    {"empty", "", HERMC_ASL_EMPTY},
    {"version 2", "02 01 05 00 00 00 02 00", HERMC_ASL_BAD_VERSION},
    {"kind 0", "01 00", HERMC_ASL_BAD_KIND},
    {"kind 15", "01 0F", HERMC_ASL_BAD_KIND},
    {"no kind", "01", HERMC_ASL_TRUNCATED},
    {"query by 3", "01 01 05 00 00 00 03 00", HERMC_ASL_BAD_QUERY_BY},
    {"query any with a pattern", "01 01 05 00 00 00 02 01 61",
     HERMC_ASL_PATTERN_ON_ANY},
    {"query pattern cut", "01 01 05 00 00 00 00 03 61 62", HERMC_ASL_TRUNCATED},
    {"answer of 65", "01 02 0A 00 00 00 41", HERMC_ASL_OVER_BOUND},
    {"answer count above the bytes", "01 02 0A 00 00 00 40 00 00 00 00 00 00",
     HERMC_ASL_TRUNCATED},
    {"answer entry name cut", "01 02 0A 00 00 00 01 11 00 00 00 05 61 00",
     HERMC_ASL_TRUNCATED},
    {"response ok 2", "01 04 01 00 00 00 00 00 00 00 02", HERMC_ASL_BAD_BOOL},
    {"response id 0", "01 04 00 00 00 00 00 00 00 00 01",
     HERMC_ASL_ZERO_REQUEST_ID},
    {"error response trailing", "01 04 01 00 00 00 00 00 00 00 00 F2 AD B6 0F "
                                "00 00 00 00 10 00 FF",
     HERMC_ASL_TRAILING},
    {"watch trailing", "01 05 2A 00 00 00 00", HERMC_ASL_TRAILING},
    {"reliable id 0", "01 0D 00 00 00 00 00 00 00 00 2A 00 00 00 00",
     HERMC_ASL_ZERO_REQUEST_ID},
    {"reliable oneway 2", "01 0D 05 00 00 00 00 00 00 00 2A 00 00 00 02",
     HERMC_ASL_BAD_BOOL},
    {"ack id 0", "01 0E 00 00 00 00 00 00 00 00", HERMC_ASL_ZERO_REQUEST_ID},
    {"subscribe lease cut", "01 09 04 70 6F 73 65 E8 03", HERMC_ASL_TRUNCATED},
    {"request header cut", "01 03 01 02 03 04 05 06 07 08 2A 00 00",
     HERMC_ASL_TRUNCATED},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto b = hex(c.bytes);
    hermc_asl_msg m{};
    EXPECT_EQ(hermc_asl_decode(b.data(), b.size(), &m), c.error);
  }
}

} // namespace
