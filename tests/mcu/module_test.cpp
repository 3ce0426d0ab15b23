// Specification of the C client's module (apps/mcu/client/hermc.h) driven
// as a main loop drives it: bytes in (hermc_feed), bytes out
// (hermc_poll_tx), a millisecond clock (hermc_tick). The test plays the
// neighbour: it frames packets with the client's own serial link layer and
// decodes what the module sends with the C codecs.
//
// Built twice (tests/mcu/CMakeLists.txt): against the default library
// (hermc_module_test) and against the sonar firmware's configuration
// (hermc_module_sonar_test: no topics, no escaped framing, no reliable
// requests, one local APO, 16-bit counters, smaller bounds) and against a
// build serving no APO (hermc_module_no_apos_test). The tests of a feature a
// build leaves out are replaced by tests of what that build does instead.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "apps/mcu/client/hermc.h"
#include "apps/mcu/client/hermc_payload.h"
#include "tests/mcu/mcu_bytes.hpp"
#include "tests/mcu/mcu_packets.hpp"

using namespace mcu_test;

namespace {

constexpr uint16_t self_id = 0x0042;
constexpr uint16_t peer_id = 0x0010;
constexpr uint64_t self_instance = 0x1122334455667788ull;
/// The build serves local APOs (HERMC_MAX_APOS > 0): the fixture registers
/// the echo APO "sonar" as APO 1.
constexpr bool serves_apos = HERMC_MAX_APOS > 0;

/// A decoded packet the module sent.
struct sent {
  hermc_packet_type type;
  bytes raw;
  hermc_data_header data{};
  hermc_asl_msg asl{};
};

/// The echo APO: answers with the request's payload; code 4 when empty.
uint8_t echo(void* ctx, const uint8_t* req, size_t n, uint8_t* resp,
             size_t cap, size_t* len) {
  ++*static_cast<int*>(ctx);
  if (n == 0)
    return HERMC_EC_INVALID_PARAMETER;
  if (n > cap)
    return HERMC_EC_QUEUE_FULL;
  for (size_t i = 0; i < n; ++i)
    resp[i] = req[i];
  *len = n;
  return 0;
}

struct outcome {
  int calls = 0;
  hermc_status status = HERMC_STATUS_OK;
  bytes payload;
  uint8_t code = 0;
};

void on_response(void* ctx, hermc_status status, const uint8_t* p, size_t n,
                 uint64_t, uint8_t code) {
  auto* o = static_cast<outcome*>(ctx);
  ++o->calls;
  o->status = status;
  o->payload = p ? take(p, n) : bytes{};
  o->code = code;
}

class hermc_module_test : public ::testing::Test {
protected:
  void SetUp() override {
    hermc_config cfg;
    hermc_config_default(&cfg, self_id, self_instance);
    ASSERT_EQ(hermc_init(&m, &cfg), HERMC_OK);
    hermc_link_tx_init(&to_module, false);
    hermc_link_rx_init(&from_module, false);
    ASSERT_EQ(hermc_register_apo(&m, "sonar", "herm.srf04", echo, &calls),
              serves_apos ? 1 : HERMC_ERR_NO_ROOM);
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

  /// Everything the module sent since the last call, decoded.
  std::vector<sent> drain() {
    packets.clear();
    uint8_t buf[64];
    size_t n;
    while ((n = hermc_poll_tx(&m, buf, sizeof buf)) > 0)
      hermc_link_rx_feed(&from_module, buf, n, collect, this);
    // Decoded in place: the messages point into `kept`'s raw bytes.
    kept.assign(packets.size(), sent{});
    for (size_t i = 0; i < packets.size(); ++i) {
      auto& s = kept[i];
      s.raw = packets[i];
      EXPECT_EQ(hermc_peek_type(s.raw.data(), s.raw.size(), &s.type),
                HERMC_NET_OK);
      if (s.type == HERMC_PT_DATA) {
        size_t at = 0;
        EXPECT_EQ(hermc_data_header_decode(s.raw.data(), s.raw.size(), &s.data,
                                           &at),
                  HERMC_NET_OK);
        EXPECT_EQ(hermc_asl_decode(s.raw.data() + at, s.raw.size() - at, &s.asl),
                  HERMC_ASL_OK);
      }
    }
    return kept;
  }

  static void collect(void* ctx, uint8_t, const uint8_t* p, size_t n) {
    static_cast<hermc_module_test*>(ctx)->packets.push_back(take(p, n));
  }

  /// Starts the module and meets the neighbour; drops what that sends.
  void start() {
    hermc_tick(&m, now);
    deliver(hello(peer_id, 0xAB, 1000));
    drain();
  }

  void advance(uint32_t ms) {
    for (uint32_t t = 0; t < ms; t += 50) {
      now += 50;
      hermc_tick(&m, now);
    }
  }

  hermc_module m{};
  hermc_link_tx to_module{};
  hermc_link_rx from_module{};
  std::vector<bytes> packets;
  std::vector<sent> kept;
  int calls = 0;
  uint32_t now = 1000;
};

// -- routing ------------------------------------------------------------------

TEST_F(hermc_module_test, the_first_tick_says_hello_and_advertises_its_own_id) {
  hermc_tick(&m, now);
  auto out = drain();
  ASSERT_EQ(out.size(), 2u);
  hermc_hello h{};
  ASSERT_EQ(hermc_hello_decode(out[0].raw.data(), out[0].raw.size(), &h),
            HERMC_NET_OK);
  EXPECT_EQ(h.sender, self_id);
  EXPECT_EQ(h.instance, self_instance);
  EXPECT_EQ(h.interval_ms, 1000);
  hermc_update_header u{};
  hermc_update_entry e[1]{};
  ASSERT_EQ(hermc_update_decode(out[1].raw.data(), out[1].raw.size(), &u, e, 1),
            HERMC_NET_OK);
  EXPECT_EQ(u.sender, self_id);
  ASSERT_EQ(u.count, 1);
  EXPECT_EQ(e[0].origin, self_id);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(e[0].metric[k], 0u);
    EXPECT_EQ(e[0].hops[k], 0);
  }
}

TEST_F(hermc_module_test, hellos_every_interval_and_an_update_every_fourth) {
  hermc_tick(&m, now);
  drain();
  int hellos = 0, updates = 0;
  for (int i = 0; i < 80; ++i) {
    advance(100);
    for (auto& s : drain()) {
      hellos += s.type == HERMC_PT_HELLO;
      updates += s.type == HERMC_PT_UPDATE;
    }
  }
  EXPECT_EQ(hellos, 8);
  EXPECT_EQ(updates, 2);
}

TEST_F(hermc_module_test, a_new_neighbour_gets_a_hello_then_our_update) {
  hermc_tick(&m, now);
  drain();
  deliver(hello(peer_id, 0xAB, 1000));
  auto out = drain();
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].type, HERMC_PT_HELLO);
  EXPECT_EQ(out[1].type, HERMC_PT_UPDATE);
  deliver(hello(peer_id, 0xAB, 1000)); // the same neighbour: nothing new
  EXPECT_TRUE(drain().empty());
  deliver(hello(peer_id, 0xAC, 1000)); // it restarted
  EXPECT_EQ(drain().size(), 2u);
  EXPECT_EQ(m.counters.neighbour_changes, 2u);
}

TEST_F(hermc_module_test, a_goodbye_forgets_the_neighbour_and_silence_too) {
  start();
  deliver(hello(peer_id, 0xAB, 0));
  EXPECT_EQ(m.neighbour, HERMC_NO_MODULE);
  deliver(hello(peer_id, 0xAB, 1000));
  EXPECT_EQ(m.neighbour, peer_id);
  advance(1600);
  EXPECT_EQ(m.neighbour, HERMC_NO_MODULE);
  EXPECT_EQ(m.counters.neighbour_changes, 2u);
}

TEST_F(hermc_module_test, a_seqno_request_for_its_id_raises_its_seqno) {
  start();
  hermc_seqno_request r{peer_id, self_id, 0x0123, 32};
  uint8_t buf[8];
  deliver(take(buf, hermc_seqno_request_encode(&r, buf, sizeof buf)));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  hermc_update_header u{};
  hermc_update_entry e[1]{};
  ASSERT_EQ(hermc_update_decode(out[0].raw.data(), out[0].raw.size(), &u, e, 1),
            HERMC_NET_OK);
  EXPECT_EQ(e[0].seqno, 0x0123);
  hermc_seqno_request other{peer_id, 0x0077, 5, 32};
  deliver(take(buf, hermc_seqno_request_encode(&other, buf, sizeof buf)));
  EXPECT_TRUE(drain().empty()); // a leaf forwards nothing
}

// -- discovery and requests -----------------------------------------------------

#if HERMC_MAX_APOS > 0
TEST_F(hermc_module_test, a_query_by_name_type_or_any_is_answered_once) {
  start();
  deliver(data(peer_id, 0xFFFF, query(9, HERMC_BY_NAME, "sonar"), 77));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].data.dst, peer_id);
  EXPECT_EQ(out[0].data.src, self_id);
  EXPECT_EQ(out[0].data.protocol, 1);
  ASSERT_EQ(out[0].asl.kind, HERMC_ASL_ANSWER);
  EXPECT_EQ(out[0].asl.id32, 9u);
  hermc_asl_entry e{};
  size_t at = 0;
  ASSERT_TRUE(hermc_asl_answer_entry(&out[0].asl, &at, &e));
  EXPECT_EQ(e.apo, 1u);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(e.type.data), e.type.size),
            "herm.srf04");
  // The same flood again (another path): dropped.
  deliver(data(peer_id, 0xFFFF, query(9, HERMC_BY_NAME, "sonar"), 77));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_flood_duplicates, 1u);
  deliver(data(peer_id, 0xFFFF, query(10, HERMC_BY_TYPE, "herm.srf04"), 78));
  EXPECT_EQ(drain().size(), 1u);
  deliver(data(peer_id, 0xFFFF, query(11, HERMC_BY_ANY, ""), 79));
  EXPECT_EQ(drain().size(), 1u);
  // Nothing matches: no answer, as HERM's discovery table does.
  deliver(data(peer_id, 0xFFFF, query(12, HERMC_BY_NAME, "camera"), 80));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.queries_answered, 3u);
}

TEST_F(hermc_module_test, a_request_gets_the_handlers_response) {
  start();
  deliver(data(peer_id, self_id, request(0x55, 1, hex("01 02 03"))));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].asl.kind, HERMC_ASL_RESPONSE);
  EXPECT_EQ(out[0].asl.request_id, 0x55u);
  EXPECT_EQ(out[0].asl.ok, 1);
  EXPECT_EQ(take(out[0].asl.payload.data, out[0].asl.payload.size),
            hex("01 02 03"));
  EXPECT_EQ(out[0].data.dst, peer_id);
  EXPECT_EQ(calls, 1);
}

TEST_F(hermc_module_test, an_unknown_apo_gets_the_typed_error_apo_gone) {
  start();
  deliver(data(peer_id, self_id, request(0x56, 9, hex("01"))));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].asl.kind, HERMC_ASL_RESPONSE);
  EXPECT_EQ(out[0].asl.ok, 0);
  EXPECT_EQ(out[0].asl.err_category, HERMC_ERROR_CATEGORY_HERM);
  EXPECT_EQ(out[0].asl.err_code, HERMC_EC_APO_GONE);
  EXPECT_EQ(m.counters.rx_unknown_apo, 1u);
  EXPECT_EQ(calls, 0);
}

TEST_F(hermc_module_test, a_handler_error_travels_as_its_code) {
  start();
  deliver(data(peer_id, self_id, request(0x57, 1, {})));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].asl.ok, 0);
  EXPECT_EQ(out[0].asl.err_code, HERMC_EC_INVALID_PARAMETER);
}

TEST_F(hermc_module_test, a_one_way_request_reaches_the_handler_without_response) {
  start();
  deliver(data(peer_id, self_id, request(0, 1, hex("07"))));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(calls, 1);
  deliver(data(peer_id, self_id, request(0, 9, hex("07"))));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_unknown_apo, 1u);
}

#endif // HERMC_MAX_APOS > 0

#if HERMC_MAX_APOS >= 3
TEST_F(hermc_module_test, apos_that_do_not_fit_one_answer_go_in_the_next) {
  // Two more APOs of 67-byte entries: with the fixture's (21 bytes) they
  // need 155 bytes of entries, more than an answer holds (HERMC_MAX_PACKET
  // less the data header and the answer's own 7 bytes).
  static const std::string a(60, 'a'), b(60, 'b');
  static_assert(HERMC_MAX_PACKET - 8 - 7 < 21 + 67 + 67,
                "the three entries must not fit one answer");
  static_assert(HERMC_MAX_PACKET - 8 - 7 >= 21 + 67,
                "two entries must fit one answer");
  ASSERT_EQ(hermc_register_apo(&m, a.c_str(), "t", echo, &calls), 2);
  ASSERT_EQ(hermc_register_apo(&m, b.c_str(), "t", echo, &calls), 3);
  start();
  deliver(data(peer_id, 0xFFFF, query(5, HERMC_BY_ANY, ""), 90));
  auto out = drain();
  ASSERT_EQ(out.size(), 2u);
  std::vector<uint32_t> apos;
  for (const auto& s : out) {
    ASSERT_EQ(s.asl.kind, HERMC_ASL_ANSWER);
    EXPECT_EQ(s.asl.id32, 5u);
    EXPECT_EQ(s.data.dst, peer_id);
    hermc_asl_entry e{};
    size_t at = 0;
    while (hermc_asl_answer_entry(&s.asl, &at, &e))
      apos.push_back(e.apo);
  }
  EXPECT_EQ(out[0].asl.count, 2u);
  EXPECT_EQ(out[1].asl.count, 1u);
  EXPECT_EQ(apos, (std::vector<uint32_t>{1, 2, 3}));
  EXPECT_EQ(m.counters.tx_dropped, 0u);
}
#endif

#if HERMC_MAX_APOS >= 2
TEST_F(hermc_module_test, an_apo_whose_entry_alone_does_not_fit_is_left_out_and_counted) {
  // An entry is 4 + 1 + name + 1 + type bytes: one byte more than the room
  // of an answer (HERMC_MAX_PACKET less the data header and 7 bytes).
  static const std::string big(HERMC_MAX_PACKET - 8 - 7 - 7 + 1, 'x');
  ASSERT_EQ(hermc_register_apo(&m, big.c_str(), "t", echo, &calls), 2);
  start();
  deliver(data(peer_id, 0xFFFF, query(6, HERMC_BY_ANY, ""), 91));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u); // the fixture's APO alone
  EXPECT_EQ(out[0].asl.count, 1u);
  EXPECT_EQ(m.counters.tx_dropped, 1u);
}

/// A handler that claims more response bytes than it was given room for.
uint8_t overflowing(void*, const uint8_t*, size_t, uint8_t*, size_t cap,
                    size_t* len) {
  *len = cap + 1;
  return 0;
}

TEST_F(hermc_module_test, a_response_larger_than_the_room_becomes_invalid_parameter) {
  ASSERT_EQ(hermc_register_apo(&m, "big", "t", overflowing, nullptr), 2);
  start();
  deliver(data(peer_id, self_id, request(0x58, 2, hex("01"))));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].asl.kind, HERMC_ASL_RESPONSE);
  EXPECT_EQ(out[0].asl.request_id, 0x58u);
  EXPECT_EQ(out[0].asl.ok, 0);
  EXPECT_EQ(out[0].asl.err_category, HERMC_ERROR_CATEGORY_HERM);
  EXPECT_EQ(out[0].asl.err_code, HERMC_EC_INVALID_PARAMETER);
  EXPECT_EQ(m.counters.requests_served, 1u);
}
#endif

#if HERMC_MAX_APOS == 0
TEST_F(hermc_module_test, without_local_apos_no_query_is_answered_and_requests_get_apo_gone) {
  start();
  deliver(data(peer_id, 0xFFFF, query(9, HERMC_BY_NAME, "sonar"), 77));
  deliver(data(peer_id, 0xFFFF, query(10, HERMC_BY_ANY, ""), 78));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.queries_answered, 0u);
  deliver(data(peer_id, self_id, request(0x55, 1, hex("01 02 03"))));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].asl.kind, HERMC_ASL_RESPONSE);
  EXPECT_EQ(out[0].asl.request_id, 0x55u);
  EXPECT_EQ(out[0].asl.ok, 0);
  EXPECT_EQ(out[0].asl.err_code, HERMC_EC_APO_GONE);
  deliver(data(peer_id, self_id, request(0, 1, hex("07")))); // one-way
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_unknown_apo, 2u);
  EXPECT_EQ(m.counters.requests_served, 0u);
  EXPECT_EQ(calls, 0);
}
#endif

#if HERMC_RELIABLE && HERMC_MAX_APOS > 0
TEST_F(hermc_module_test, a_reliable_request_is_answered_and_a_one_way_one_acked) {
  start();
  uint8_t buf[32];
  auto n = hermc_asl_request_header(0x99, 1, 1, 0, buf, sizeof buf);
  buf[n++] = 0x42;
  deliver(data(peer_id, self_id, take(buf, n)));
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].asl.kind, HERMC_ASL_RESPONSE);
  n = hermc_asl_request_header(0x9A, 1, 1, 1, buf, sizeof buf);
  buf[n++] = 0x42;
  deliver(data(peer_id, self_id, take(buf, n)));
  out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].asl.kind, HERMC_ASL_ACK);
  EXPECT_EQ(out[0].asl.request_id, 0x9Au);
}
#endif

#if !HERMC_RELIABLE
TEST_F(hermc_module_test, without_reliable_requests_they_are_ignored_and_counted) {
  start();
  uint8_t buf[32];
  auto n = hermc_asl_request_header(0x99, 1, 1, 0, buf, sizeof buf);
  buf[n++] = 0x42;
  deliver(data(peer_id, self_id, take(buf, n)));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_asl_ignored, 1u);
  EXPECT_EQ(calls, 0);
}
#endif

TEST_F(hermc_module_test, a_remote_apo_is_discovered_with_backoff_then_requested) {
  int r = hermc_remote(&m, "sonar");
  ASSERT_EQ(r, 0);
  EXPECT_EQ(hermc_request(&m, r, nullptr, 0, on_response, nullptr, 0),
            HERMC_ERR_NOT_READY);
  hermc_tick(&m, now);
  auto queries = [&] {
    int q = 0;
    for (auto& s : drain())
      q += s.type == HERMC_PT_DATA && s.asl.kind == HERMC_ASL_QUERY;
    return q;
  };
  EXPECT_EQ(queries(), 1);
  advance(250);
  EXPECT_EQ(queries(), 1); // after 250 ms
  advance(250);
  EXPECT_EQ(queries(), 0); // the next after 500 more
  advance(250);
  EXPECT_EQ(queries(), 1);
  uint32_t qid = m.remotes[0].query_id;
  uint8_t buf[64];
  auto n = hermc_asl_answer_begin(qid, 1, buf, sizeof buf);
  n += hermc_asl_answer_entry_encode(0x33, "sonar", 5, "t", 1, buf + n,
                                     sizeof buf - n);
  deliver(data(0x0020, self_id, take(buf, n)));
  ASSERT_TRUE(hermc_remote_ready(&m, r));
  outcome o;
  const uint8_t payload[] = {0xAA, 0xBB};
  ASSERT_EQ(hermc_request(&m, r, payload, 2, on_response, &o, 0), HERMC_OK);
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].data.dst, 0x0020);
  ASSERT_EQ(out[0].asl.kind, HERMC_ASL_REQUEST);
  EXPECT_EQ(out[0].asl.id32, 0x33u);
  EXPECT_EQ(take(out[0].asl.payload.data, out[0].asl.payload.size),
            hex("AA BB"));
  auto rid = out[0].asl.request_id;
  ASSERT_NE(rid, 0u);
  n = hermc_asl_response_ok_header(rid, buf, sizeof buf);
  buf[n++] = 0x01;
  deliver(data(0x0020, self_id, take(buf, n)));
  EXPECT_EQ(o.calls, 1);
  EXPECT_EQ(o.status, HERMC_STATUS_OK);
  EXPECT_EQ(o.payload, hex("01"));
  // The same response again matches nothing.
  deliver(data(0x0020, self_id, take(buf, n)));
  EXPECT_EQ(o.calls, 1);
  EXPECT_EQ(m.counters.rx_unexpected_response, 1u);
}

TEST_F(hermc_module_test, a_response_whose_id_differs_only_above_32_bits_matches_nothing) {
  int r = hermc_remote(&m, "sonar");
  hermc_tick(&m, now);
  drain();
  uint8_t buf[64];
  auto n = hermc_asl_answer_begin(m.remotes[0].query_id, 1, buf, sizeof buf);
  n += hermc_asl_answer_entry_encode(0x33, "sonar", 5, "", 0, buf + n,
                                     sizeof buf - n);
  deliver(data(0x0020, self_id, take(buf, n)));
  outcome o;
  ASSERT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &o, 0), HERMC_OK);
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  auto rid = out[0].asl.request_id;
  ASSERT_NE(rid, 0u);
  ASSERT_EQ(rid >> 32, 0u);  // the client's ids are 32-bit on the wire's 64
  n = hermc_asl_response_ok_header(rid | (1ull << 32), buf, sizeof buf);
  deliver(data(0x0020, self_id, take(buf, n)));
  EXPECT_EQ(o.calls, 0);
  EXPECT_EQ(m.counters.rx_unexpected_response, 1u);
  // The error response with the exact id ends it, with category and code.
  n = hermc_asl_response_error_encode(rid, HERMC_ERROR_CATEGORY_HERM,
                                      HERMC_EC_QUEUE_FULL, "busy", 4, buf,
                                      sizeof buf);
  deliver(data(0x0020, self_id, take(buf, n)));
  EXPECT_EQ(o.calls, 1);
  EXPECT_EQ(o.status, HERMC_STATUS_ERROR);
  EXPECT_EQ(o.code, HERMC_EC_QUEUE_FULL);
  EXPECT_TRUE(o.payload.empty());
}

TEST_F(hermc_module_test, a_request_without_response_times_out_and_rediscovers) {
  int r = hermc_remote(&m, "sonar");
  hermc_tick(&m, now);
  drain();
  uint8_t buf[64];
  auto n = hermc_asl_answer_begin(m.remotes[0].query_id, 1, buf, sizeof buf);
  n += hermc_asl_answer_entry_encode(0x33, "sonar", 5, "", 0, buf + n,
                                     sizeof buf - n);
  deliver(data(0x0020, self_id, take(buf, n)));
  outcome o;
  ASSERT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &o, 500), HERMC_OK);
  drain();
  advance(450);
  EXPECT_EQ(o.calls, 0);
  advance(100);
  EXPECT_EQ(o.calls, 1);
  EXPECT_EQ(o.status, HERMC_STATUS_TIMEOUT);
  EXPECT_EQ(m.counters.request_timeouts, 1u);
  EXPECT_FALSE(hermc_remote_ready(&m, r));
}

// One request timing out sends the remote back to discovery; another one
// still pending to the same module gets its response all the same.
TEST_F(hermc_module_test, a_timeout_of_one_request_does_not_orphan_anothers_response) {
  int r = hermc_remote(&m, "sonar");
  hermc_tick(&m, now);
  drain();
  uint8_t buf[64];
  auto n = hermc_asl_answer_begin(m.remotes[0].query_id, 1, buf, sizeof buf);
  n += hermc_asl_answer_entry_encode(0x33, "sonar", 5, "", 0, buf + n,
                                     sizeof buf - n);
  deliver(data(0x0020, self_id, take(buf, n)));
  outcome a, b;
  ASSERT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &a, 500), HERMC_OK);
  ASSERT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &b, 5000), HERMC_OK);
  auto out = drain();
  ASSERT_EQ(out.size(), 2u);
  auto rid_b = out[1].asl.request_id;
  advance(550);
  EXPECT_EQ(a.status, HERMC_STATUS_TIMEOUT);
  EXPECT_FALSE(hermc_remote_ready(&m, r));
  n = hermc_asl_response_ok_header(rid_b, buf, sizeof buf);
  buf[n++] = 0x01;
  deliver(data(0x0020, self_id, take(buf, n)));
  EXPECT_EQ(b.calls, 1);
  EXPECT_EQ(b.status, HERMC_STATUS_OK);
  EXPECT_EQ(m.counters.rx_unexpected_response, 0u);
}

// A boot counter makes instances that differ in a few bits: the ids of two
// boots still start far apart, so a late reply to the last boot's query or
// request is not taken for one of this boot's.
TEST_F(hermc_module_test, ids_of_consecutive_boots_start_apart) {
  hermc_module boot1{}, boot2{};
  hermc_config c1, c2;
  hermc_config_default(&c1, self_id, (uint64_t{1} << 16) | self_id);
  hermc_config_default(&c2, self_id, (uint64_t{2} << 16) | self_id);
  ASSERT_EQ(hermc_init(&boot1, &c1), HERMC_OK);
  ASSERT_EQ(hermc_init(&boot2, &c2), HERMC_OK);
  auto apart = [](uint32_t x, uint32_t y) {
    uint32_t d = x - y;
    return d > 0x10000u && uint32_t(0u - d) > 0x10000u;
  };
  EXPECT_TRUE(apart(boot1.next_query_id, boot2.next_query_id));
  EXPECT_TRUE(apart(boot1.next_request_id, boot2.next_request_id));
  EXPECT_TRUE(apart(boot1.next_flood_id, boot2.next_flood_id));
}

TEST_F(hermc_module_test, an_apo_gone_error_ends_the_request_and_rediscovers) {
  int r = hermc_remote(&m, "sonar");
  hermc_tick(&m, now);
  drain();
  uint8_t buf[64];
  auto n = hermc_asl_answer_begin(m.remotes[0].query_id, 1, buf, sizeof buf);
  n += hermc_asl_answer_entry_encode(0x33, "sonar", 5, "", 0, buf + n,
                                     sizeof buf - n);
  deliver(data(0x0020, self_id, take(buf, n)));
  outcome o;
  ASSERT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &o, 0), HERMC_OK);
  auto out = drain();
  ASSERT_EQ(out.size(), 1u);
  n = hermc_asl_response_error_encode(out[0].asl.request_id,
                                      HERMC_ERROR_CATEGORY_HERM,
                                      HERMC_EC_APO_GONE, "gone", 4, buf,
                                      sizeof buf);
  deliver(data(0x0020, self_id, take(buf, n)));
  EXPECT_EQ(o.status, HERMC_STATUS_ERROR);
  EXPECT_EQ(o.code, HERMC_EC_APO_GONE);
  EXPECT_FALSE(hermc_remote_ready(&m, r));
}

TEST_F(hermc_module_test, the_pending_table_refuses_past_its_bound) {
  int r = hermc_remote(&m, "sonar");
  m.remotes[r].module = 0x0020; // as if discovered
  m.remotes[r].apo = 1;
  outcome o;
  for (int i = 0; i < HERMC_MAX_PENDING; ++i)
    ASSERT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &o, 0), HERMC_OK);
  EXPECT_EQ(hermc_request(&m, r, nullptr, 0, on_response, &o, 0),
            HERMC_ERR_NO_ROOM);
  EXPECT_EQ(m.counters.requests_refused, 1u);
  // One-way requests take no slot.
  EXPECT_EQ(hermc_request(&m, r, nullptr, 0, nullptr, nullptr, 0), HERMC_OK);
}

TEST_F(hermc_module_test, tables_of_apos_remotes_and_topics_are_bounded) {
  for (int i = 1; i < HERMC_MAX_APOS; ++i)
    EXPECT_EQ(hermc_register_apo(&m, "x", "t", echo, &calls), i + 1);
  EXPECT_EQ(hermc_register_apo(&m, "x", "t", echo, &calls), HERMC_ERR_NO_ROOM);
  for (int i = 0; i < HERMC_MAX_REMOTES; ++i)
    EXPECT_EQ(hermc_remote(&m, "y"), i);
  EXPECT_EQ(hermc_remote(&m, "y"), HERMC_ERR_NO_ROOM);
#if HERMC_TOPICS
  for (int i = 0; i < HERMC_MAX_TOPICS; ++i)
    EXPECT_EQ(hermc_topic(&m, "z"), i);
  EXPECT_EQ(hermc_topic(&m, "z"), HERMC_ERR_NO_ROOM);
#endif
}

// -- topics -------------------------------------------------------------------

#if HERMC_TOPICS
TEST_F(hermc_module_test, publishes_to_subscribers_within_their_lease_and_bound) {
  int t = hermc_topic(&m, "range");
  start(); // meeting the neighbour advertises the topic
  uint8_t buf[32];
  auto n = hermc_asl_subscribe_encode("range", 5, 1000, buf, sizeof buf);
  for (uint16_t s = 0; s <= HERMC_MAX_SUBSCRIBERS; ++s)
    deliver(data(static_cast<uint16_t>(0x100 + s), 0xFFFF, take(buf, n),
                 100u + s));
  EXPECT_EQ(m.counters.subscribers_refused, 1u);
  const uint8_t v[] = {0x01, 0x00};
  EXPECT_EQ(hermc_publish(&m, t, v, 2), HERMC_MAX_SUBSCRIBERS);
  auto out = drain();
  ASSERT_EQ(out.size(), size_t{HERMC_MAX_SUBSCRIBERS});
  EXPECT_EQ(out[0].asl.kind, HERMC_ASL_PUBLISH);
  EXPECT_EQ(out[0].asl.u32, 1u);
  EXPECT_EQ(take(out[0].asl.payload.data, out[0].asl.payload.size), hex("01 00"));
  advance(1050); // every lease ran out
  drain();
  EXPECT_EQ(hermc_publish(&m, t, v, 2), 0);
  // Not our topic: ignored.
  n = hermc_asl_subscribe_encode("pose", 4, 1000, buf, sizeof buf);
  deliver(data(0x100, self_id, take(buf, n)));
  EXPECT_EQ(hermc_publish(&m, t, v, 2), 0);
}

TEST_F(hermc_module_test, meeting_a_neighbour_advertises_the_topics) {
  hermc_topic(&m, "range");
  hermc_tick(&m, now);
  drain();
  deliver(hello(peer_id, 0xAB, 1000));
  auto out = drain();
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[2].asl.kind, HERMC_ASL_ADVERTISE);
  EXPECT_EQ(out[2].data.dst, 0xFFFF);
  EXPECT_NE(out[2].data.flood_id, 0u);
}
#else
TEST_F(hermc_module_test, without_topics_subscriptions_are_ignored_and_counted) {
  start();
  uint8_t buf[32];
  auto n = hermc_asl_subscribe_encode("range", 5, 1000, buf, sizeof buf);
  deliver(data(0x100, self_id, take(buf, n)));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_asl_ignored, 1u);
}
#endif

// -- bad input ----------------------------------------------------------------

TEST_F(hermc_module_test, malformed_and_foreign_packets_are_counted_not_answered) {
  start();
  deliver(hex("21 00"));                                  // version 2
  deliver(hex("11 4E 00 01"));                             // short hello
  deliver(hex("10 4E 00 42 00 11 8E 01"));                 // reserved bit
  deliver(data(peer_id, self_id, hex("01 0F")));           // APO kind 15
  deliver(data(peer_id, 0x0077, request(1, 1, hex("01")))); // not for us
  deliver(data(0xFFFF, self_id, request(1, 1, hex("01")))); // from broadcast
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_malformed, 3u);
  EXPECT_EQ(m.counters.rx_asl_malformed, 2u);
  EXPECT_EQ(m.counters.rx_not_for_us, 1u);
  EXPECT_EQ(calls, 0);
}

TEST_F(hermc_module_test, the_flood_cache_is_bounded_and_counts_evictions) {
  start();
  for (uint32_t f = 1; f <= HERMC_FLOOD_CACHE + 3; ++f)
    deliver(data(peer_id, 0xFFFF, query(f, HERMC_BY_NAME, "none"), f));
  EXPECT_EQ(m.counters.flood_evictions, 3u);
  EXPECT_EQ(m.counters.rx_flood_duplicates, 0u);
  // The oldest were evicted: a copy of the first is taken as new.
  deliver(data(peer_id, 0xFFFF, query(1, HERMC_BY_NAME, "sonar"), 1));
  EXPECT_EQ(drain().size(), serves_apos ? 1u : 0u);
  EXPECT_EQ(m.counters.rx_flood_duplicates, 0u);
  // Our own flood coming back is a duplicate.
  deliver(data(self_id, 0xFFFF, query(1, HERMC_BY_NAME, "sonar"), 5000));
  EXPECT_TRUE(drain().empty());
  EXPECT_EQ(m.counters.rx_flood_duplicates, 1u);
}

TEST_F(hermc_module_test, a_full_transmit_ring_drops_and_counts) {
  start();
  // Nobody drains the UART: answers pile up until the ring refuses.
  for (uint32_t i = 1; i <= 40; ++i)
    deliver(data(peer_id, self_id, request(i, 1, hex("01 02 03 04"))));
  EXPECT_GT(m.counters.tx_dropped, 0u);
  // Each was handled (served, or refused with apo_gone without local APOs).
  EXPECT_EQ(serves_apos ? m.counters.requests_served : m.counters.rx_unknown_apo,
            40u);
}

TEST(hermc_module, init_refuses_impossible_configurations) {
  hermc_module m{};
  hermc_config cfg;
  hermc_config_default(&cfg, 0, 1);
  EXPECT_EQ(hermc_init(&m, &cfg), HERMC_ERR_ARG);
  hermc_config_default(&cfg, 0xFFFF, 1);
  EXPECT_EQ(hermc_init(&m, &cfg), HERMC_ERR_ARG);
  hermc_config_default(&cfg, 5, 0);
  EXPECT_EQ(hermc_init(&m, &cfg), HERMC_ERR_ARG);
  hermc_config_default(&cfg, 5, 1);
  cfg.hello_interval_ms = 0;
  EXPECT_EQ(hermc_init(&m, &cfg), HERMC_ERR_ARG);
  hermc_config_default(&cfg, 5, 1);
  cfg.escaped = 1;
  EXPECT_EQ(hermc_init(&m, &cfg), HERMC_ESCAPED ? HERMC_OK : HERMC_ERR_ARG);
}

} // namespace
