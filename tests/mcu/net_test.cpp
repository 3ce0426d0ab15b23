// Specification of the C client's network packets (apps/mcu/client/
// hermc_net.h): the byte strings of docs/protocol.md, "Network packets",
// which tests/routing/wire_test.cpp pins for the C++ codec, and what the
// decoders refuse.

#include <gtest/gtest.h>

#include "apps/mcu/client/hermc_net.h"
#include "tests/mcu/mcu_bytes.hpp"

using namespace mcu_test;

namespace {

TEST(hermc_net_layout, data_header) {
  hermc_data_header h{0x004E, 0x1042, 17, 2, 3, 1, 0, 0};
  uint8_t out[16];
  ASSERT_EQ(hermc_data_header_encode(&h, out, sizeof out), 8u);
  EXPECT_EQ(take(out, 8), hex("10 4E 00 42 10 11 0E 01"));
  hermc_data_header back{};
  size_t at = 0;
  ASSERT_EQ(hermc_data_header_decode(out, 8, &back, &at), HERMC_NET_OK);
  EXPECT_EQ(at, 8u);
  EXPECT_EQ(back.src, 0x004E);
  EXPECT_EQ(back.dst, 0x1042);
  EXPECT_EQ(back.hop_limit, 17);
  EXPECT_EQ(back.size_class, 2);
  EXPECT_EQ(back.priority, 3);
  EXPECT_EQ(back.protocol, 1);
  EXPECT_EQ(back.flood_id, 0u);
}

TEST(hermc_net_layout, flooded_broadcast_header) {
  hermc_data_header h{0x004E, 0xFFFF, 32, 0, 2, 1, 0x01020304, 0};
  uint8_t out[16];
  ASSERT_EQ(hermc_data_header_encode(&h, out, sizeof out), 12u);
  EXPECT_EQ(take(out, 12), hex("10 4E 00 FF FF 20 18 01 04 03 02 01"));
  hermc_data_header back{};
  size_t at = 0;
  ASSERT_EQ(hermc_data_header_decode(out, 12, &back, &at), HERMC_NET_OK);
  EXPECT_EQ(at, 12u);
  EXPECT_EQ(back.flood_id, 0x01020304u);
}

TEST(hermc_net_layout, data_header_with_the_authentication_flag) {
  hermc_data_header h{0x004E, 0x1042, 17, 2, 3, 1, 0, 1};
  uint8_t out[8];
  ASSERT_EQ(hermc_data_header_encode(&h, out, sizeof out), 8u);
  EXPECT_EQ(take(out, 8), hex("10 4E 00 42 10 11 2E 01"));
}

TEST(hermc_net_layout, hello) {
  hermc_hello h{0x4E, 0x0807060504030201ull, 0xABCD, 1000};
  uint8_t out[15];
  ASSERT_EQ(hermc_hello_encode(&h, out, sizeof out), 15u);
  EXPECT_EQ(take(out, 15), hex("11 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03"));
  hermc_hello back{};
  ASSERT_EQ(hermc_hello_decode(out, 15, &back), HERMC_NET_OK);
  EXPECT_EQ(back.sender, 0x4E);
  EXPECT_EQ(back.instance, 0x0807060504030201ull);
  EXPECT_EQ(back.seqno, 0xABCD);
  EXPECT_EQ(back.interval_ms, 1000);
}

TEST(hermc_net_layout, update_of_the_protocol_example) {
  const uint8_t c0[] = {5}, c1[] = {6, 2};
  hermc_update_entry e{};
  e.origin = 0x4E;
  e.seqno = 0x0102;
  e.metric[0] = 8;
  e.hops[0] = 1;
  e.path[0] = c0;
  e.metric[1] = 30;
  e.hops[1] = 2;
  e.path[1] = c1;
  e.metric[2] = HERMC_INFINITE_METRIC;
  e.metric[3] = 0x01020304;
  uint8_t out[64];
  auto n = hermc_update_encode(0x42, 0x0807060504030201ull, &e, 1, out,
                               sizeof out);
  auto expected = hex("12 42 00 01 02 03 04 05 06 07 08 01"
                      "4E 00 02 01"
                      "08 00 00 00 01 05"
                      "1E 00 00 00 02 06 02"
                      "FF FF FF FF"
                      "04 03 02 01 00");
  ASSERT_EQ(take(out, n), expected) << to_hex(take(out, n));
  hermc_update_header h{};
  hermc_update_entry back[1]{};
  ASSERT_EQ(hermc_update_decode(out, n, &h, back, 1), HERMC_NET_OK);
  EXPECT_EQ(h.sender, 0x42);
  EXPECT_EQ(h.instance, 0x0807060504030201ull);
  EXPECT_EQ(h.count, 1);
  EXPECT_EQ(back[0].origin, 0x4E);
  EXPECT_EQ(back[0].seqno, 0x0102);
  EXPECT_EQ(back[0].metric[1], 30u);
  ASSERT_EQ(back[0].hops[1], 2);
  EXPECT_EQ(back[0].path[1][0], 6);
  EXPECT_EQ(back[0].path[1][1], 2);
  EXPECT_EQ(back[0].hops[2], 0);
  EXPECT_EQ(back[0].metric[3], 0x01020304u);
}

TEST(hermc_net_layout, a_class_the_receiver_would_refuse_goes_as_a_retraction) {
  const uint8_t bad[] = {9};
  hermc_update_entry e{};
  e.origin = 7;
  e.metric[0] = 1;
  e.hops[0] = 1;
  e.path[0] = bad; // code 9: above 7
  e.metric[1] = 1;
  e.hops[1] = 33; // above 32 hops
  e.metric[2] = HERMC_INFINITE_METRIC;
  e.metric[3] = HERMC_INFINITE_METRIC;
  uint8_t out[64];
  auto n = hermc_update_encode(1, 2, &e, 1, out, sizeof out);
  ASSERT_EQ(n, 12u + 4u + 16u);
  for (size_t k = 0; k < 4; ++k)
    EXPECT_EQ(take(out + 16 + 4 * k, 4), hex("FF FF FF FF"));
}

TEST(hermc_net_layout, seqno_request) {
  hermc_seqno_request r{0x42, 0x4E, 0xFFFE, 7};
  uint8_t out[8];
  ASSERT_EQ(hermc_seqno_request_encode(&r, out, sizeof out), 8u);
  EXPECT_EQ(take(out, 8), hex("13 42 00 4E 00 FE FF 07"));
  hermc_seqno_request back{};
  ASSERT_EQ(hermc_seqno_request_decode(out, 8, &back), HERMC_NET_OK);
  EXPECT_EQ(back.origin, 0x4E);
  EXPECT_EQ(back.seqno, 0xFFFE);
  EXPECT_EQ(back.hop_count, 7);
}

TEST(hermc_net_layout, claim) {
  hermc_claim c{0x1234, 0x1111111111111111ull, 0x0807060504030201ull, 32};
  uint8_t out[20];
  ASSERT_EQ(hermc_claim_encode(&c, out, sizeof out), 20u);
  EXPECT_EQ(take(out, 20), hex("14 34 12 11 11 11 11 11 11 11 11 01 02 03 04 "
                               "05 06 07 08 20"));
  hermc_claim back{};
  ASSERT_EQ(hermc_claim_decode(out, 20, &back), HERMC_NET_OK);
  EXPECT_EQ(back.nonce, 0x1111111111111111ull);
}

TEST(hermc_net_layout, encoders_refuse_a_buffer_too_small) {
  hermc_hello h{1, 2, 3, 4};
  uint8_t out[15];
  EXPECT_EQ(hermc_hello_encode(&h, out, 14), 0u);
  hermc_data_header d{1, 0xFFFF, 32, 0, 2, 1, 5, 0};
  EXPECT_EQ(hermc_data_header_encode(&d, out, 11), 0u);
  hermc_update_entry e{};
  EXPECT_EQ(hermc_update_encode(1, 2, &e, 1, out, 15), 0u);
  EXPECT_EQ(hermc_update_encode(1, 2, &e, 25, out, sizeof out), 0u);
}

// -- what decoders refuse -----------------------------------------------------

struct refusal {
  const char* what;
  const char* bytes;
  hermc_net_error error;
};

TEST(hermc_net_malformed, control_packets_are_refused_as_the_cpp_decoder_does) {
  const refusal cases[] = {
    {"empty", "", HERMC_NET_EMPTY},
    {"version 2", "21 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03",
     HERMC_NET_BAD_VERSION},
    {"type 8", "18", HERMC_NET_BAD_TYPE},
    {"hello truncated", "11 4E 00 01 02 03 04 05 06 07 08 CD AB E8",
     HERMC_NET_TRUNCATED},
    {"hello trailing", "11 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03 00",
     HERMC_NET_TRAILING},
    {"an update as a hello", "12 42 00 01 02 03 04 05 06 07 08 00",
     HERMC_NET_BAD_TYPE},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto b = hex(c.bytes);
    hermc_hello h{};
    EXPECT_EQ(hermc_hello_decode(b.data(), b.size(), &h), c.error);
  }
  auto s = hex("13 42 00 4E 00 FE FF");
  hermc_seqno_request r{};
  EXPECT_EQ(hermc_seqno_request_decode(s.data(), s.size(), &r),
            HERMC_NET_TRUNCATED);
}

TEST(hermc_net_malformed, data_headers) {
  const refusal cases[] = {
    {"short", "10 4E 00 42 10 11 0E", HERMC_NET_TRUNCATED},
    {"reserved flag bit 7", "10 4E 00 42 10 11 8E 01", HERMC_NET_RESERVED},
    {"reserved flag bit 6", "10 4E 00 42 10 11 4E 01", HERMC_NET_RESERVED},
    {"flood id on a unicast", "10 4E 00 42 10 11 1E 01 01 00 00 00",
     HERMC_NET_BAD_FLOOD},
    {"flood id 0", "10 4E 00 FF FF 20 18 01 00 00 00 00", HERMC_NET_BAD_FLOOD},
    {"flood id cut", "10 4E 00 FF FF 20 18 01 04 03 02", HERMC_NET_TRUNCATED},
    {"a hello", "11 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03",
     HERMC_NET_BAD_TYPE},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto b = hex(c.bytes);
    hermc_data_header h{};
    size_t at = 0;
    EXPECT_EQ(hermc_data_header_decode(b.data(), b.size(), &h, &at), c.error);
  }
}

TEST(hermc_net_malformed, updates) {
  const char* header = "12 42 00 01 02 03 04 05 06 07 08 ";
  const refusal cases[] = {
    {"25 entries", "19", HERMC_NET_OVER_BOUND},
    {"count above the bytes present", "02 4E 00 02 01 FF FF FF FF FF FF FF FF "
                                      "FF FF FF FF FF FF FF FF",
     HERMC_NET_TRUNCATED},
    {"33 hops", "01 4E 00 02 01 08 00 00 00 21 FF FF FF FF FF FF FF FF FF FF "
                "FF FF",
     HERMC_NET_OVER_BOUND},
    {"link code 8", "01 4E 00 02 01 08 00 00 00 01 08 FF FF FF FF FF FF FF FF "
                    "FF FF FF FF",
     HERMC_NET_BAD_LINK_CODE},
    {"path cut", "01 4E 00 02 01 FF FF FF FF FF FF FF FF FF FF FF FF 08 00 00 "
                 "00 03 05",
     HERMC_NET_TRUNCATED},
    {"trailing", "00 00", HERMC_NET_TRAILING},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto b = hex(std::string{header} + c.bytes);
    hermc_update_header h{};
    EXPECT_EQ(hermc_update_decode(b.data(), b.size(), &h, nullptr, 0), c.error);
  }
}

TEST(hermc_net_malformed, every_truncation_of_a_good_update_is_refused) {
  const uint8_t c0[] = {5};
  hermc_update_entry e{};
  e.origin = 3;
  for (int k = 0; k < 4; ++k) {
    e.metric[k] = 10u + unsigned(k);
    e.hops[k] = 1;
    e.path[k] = c0;
  }
  uint8_t out[64];
  auto n = hermc_update_encode(1, 2, &e, 1, out, sizeof out);
  ASSERT_GT(n, 0u);
  hermc_update_header h{};
  for (size_t len = 0; len < n; ++len)
    EXPECT_NE(hermc_update_decode(out, len, &h, nullptr, 0), HERMC_NET_OK)
      << len;
  EXPECT_EQ(hermc_update_decode(out, n, &h, nullptr, 0), HERMC_NET_OK);
}

// -- metrics and seqnos -------------------------------------------------------

TEST(hermc_net_metric, rs232c_and_can_as_routing_metric_computes_them) {
  uint32_t m[4];
  hermc_link_metrics(47, 32, m); // rs232c: cost 47, MTU 32
  EXPECT_EQ(m[0], 47u);
  EXPECT_EQ(m[1], 94u);
  EXPECT_EQ(m[2], 47u * 32u);
  EXPECT_EQ(m[3], 47u * 2048u);
  hermc_link_metrics(30, 8, m); // can2.0: cost 30, MTU 8
  EXPECT_EQ(m[0], 30u);
  EXPECT_EQ(m[3], 30u * 8192u);
  hermc_link_metrics(47, 0, m);
  EXPECT_EQ(m[0], HERMC_INFINITE_METRIC);
  hermc_link_metrics(0xFFFFFFF0u, 8, m); // saturates
  EXPECT_EQ(m[0], 0xFFFFFFF0u);
  EXPECT_EQ(m[1], HERMC_INFINITE_METRIC);
}

TEST(hermc_net_metric, size_classes) {
  EXPECT_EQ(hermc_size_class_of(0), 0);
  EXPECT_EQ(hermc_size_class_of(8), 0);
  EXPECT_EQ(hermc_size_class_of(9), 1);
  EXPECT_EQ(hermc_size_class_of(64), 1);
  EXPECT_EQ(hermc_size_class_of(1024), 2);
  EXPECT_EQ(hermc_size_class_of(1025), 3);
  EXPECT_EQ(hermc_size_class_of(1000000), 3);
}

TEST(hermc_net_metric, seqnos_compare_modulo_2_16) {
  EXPECT_TRUE(hermc_seqno_newer(1, 0));
  EXPECT_TRUE(hermc_seqno_newer(0, 0xFFFF));
  EXPECT_FALSE(hermc_seqno_newer(5, 5));
  EXPECT_FALSE(hermc_seqno_newer(0, 1));
  EXPECT_FALSE(hermc_seqno_newer(0x8000, 0));
  EXPECT_TRUE(hermc_seqno_newer(0x7FFF, 0));
}

} // namespace
