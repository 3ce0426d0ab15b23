// The C client's codecs against HERM's C++ codecs (routing/wire.hpp,
// actors/asl_wire.hpp, actors/marshal.hpp): what the C side encodes the C++
// decoders accept and read back equal, what C++ encodes the C side decodes
// equal, and on mutated bytes both accept or refuse alike. Seeded random
// cases, a bounded number per test.

#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <string>
#include <variant>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/make_message.hpp"
#include "caf/type_id.hpp"

#include "actors/asl_wire.hpp"
#include "actors/marshal.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "apps/hermd/testbed_types.hpp"
#include "routing/wire.hpp"

#include "apps/mcu/client/hermc_asl.h"
#include "apps/mcu/client/hermc_net.h"
#include "apps/mcu/client/hermc_payload.h"

// -- the board's reading as a C++ APO sees it -----------------------------------
// The type hermd's srf04_batcher receives (apps/hermd/testbed_types.hpp): the
// board names it herm::hermd::srf04_reading, as CAF_ADD_TYPE_ID spells it.

namespace interop {
using herm::hermd::srf04_reading;
} // namespace interop


namespace {

using herm::byte_buffer;

constexpr int cases = 300;

byte_buffer from_c(const uint8_t* p, size_t n) {
  return byte_buffer(p, p + n);
}

// -- network packets --------------------------------------------------------------

TEST(hermc_interop_net, data_headers_in_both_directions) {
  std::mt19937 rng(1701);
  for (int i = 0; i < cases; ++i) {
    hermc_data_header c{};
    c.src = static_cast<uint16_t>(rng());
    c.dst = rng() % 4 == 0 ? 0xFFFF : static_cast<uint16_t>(rng());
    c.hop_limit = static_cast<uint8_t>(rng());
    c.size_class = static_cast<uint8_t>(rng() % 4);
    c.priority = static_cast<uint8_t>(rng() % 4);
    c.protocol = static_cast<uint8_t>(rng());
    c.flood_id = c.dst == 0xFFFF && rng() % 2 ? static_cast<uint32_t>(rng()) | 1u
                                              : 0u;
    c.authenticated = static_cast<uint8_t>(rng() % 2);
    uint8_t buf[12];
    auto n = hermc_data_header_encode(&c, buf, sizeof buf);
    auto h = herm::decode_data_header(buf, n);
    ASSERT_TRUE(h) << herm::render(h.error());
    EXPECT_EQ(h->src, c.src);
    EXPECT_EQ(h->dst, c.dst);
    EXPECT_EQ(h->hop_limit, c.hop_limit);
    EXPECT_EQ(h->size_class, c.size_class);
    EXPECT_EQ(h->priority, c.priority);
    EXPECT_EQ(h->protocol, c.protocol);
    EXPECT_EQ(h->flood_id, c.flood_id);
    EXPECT_EQ(h->authenticated, c.authenticated != 0);
    byte_buffer cpp;
    herm::encode(*h, cpp);
    EXPECT_EQ(cpp, from_c(buf, n));
    hermc_data_header back{};
    size_t at = 0;
    ASSERT_EQ(hermc_data_header_decode(cpp.data(), cpp.size(), &back, &at),
              HERMC_NET_OK);
    EXPECT_EQ(at, herm::header_size(*h));
    EXPECT_EQ(back.flood_id, c.flood_id);
  }
}

TEST(hermc_interop_net, hellos_and_seqno_requests_in_both_directions) {
  std::mt19937_64 rng(4711);
  for (int i = 0; i < cases; ++i) {
    hermc_hello c{static_cast<uint16_t>(rng()), rng(),
                  static_cast<uint16_t>(rng()), static_cast<uint16_t>(rng())};
    uint8_t buf[15];
    auto n = hermc_hello_encode(&c, buf, sizeof buf);
    auto h = herm::decode_hello(buf, n);
    ASSERT_TRUE(h);
    EXPECT_EQ(h->sender, c.sender);
    EXPECT_EQ(h->instance, c.instance);
    EXPECT_EQ(h->seqno, c.seqno);
    EXPECT_EQ(h->interval_ms, c.interval_ms);
    byte_buffer cpp;
    herm::encode(*h, cpp);
    EXPECT_EQ(cpp, from_c(buf, n));

    herm::seqno_request r{static_cast<uint16_t>(rng()),
                          static_cast<uint16_t>(rng()),
                          static_cast<uint16_t>(rng()),
                          static_cast<uint8_t>(rng())};
    byte_buffer rb;
    herm::encode(r, rb);
    hermc_seqno_request back{};
    ASSERT_EQ(hermc_seqno_request_decode(rb.data(), rb.size(), &back),
              HERMC_NET_OK);
    EXPECT_EQ(back.sender, r.sender);
    EXPECT_EQ(back.origin, r.origin);
    EXPECT_EQ(back.seqno, r.seqno);
    EXPECT_EQ(back.hop_count, r.hop_count);
    uint8_t again[8];
    EXPECT_EQ(from_c(again, hermc_seqno_request_encode(&back, again, 8)), rb);
  }
}

/// A random advertised destination (some classes retracted).
herm::advertised random_entry(std::mt19937& rng) {
  herm::advertised a;
  a.origin = static_cast<uint16_t>(rng() % 0xFFFE + 1);
  a.seqno = static_cast<uint16_t>(rng());
  for (size_t k = 0; k < 4; ++k) {
    if (rng() % 4 == 0)
      continue;
    a.metrics[k] = static_cast<uint32_t>(rng() % 0xFFFFFFFEu);
    a.hops[k] = static_cast<uint8_t>(rng() % 33);
    for (size_t h = 0; h < a.hops[k]; ++h)
      a.path[k].push_back(static_cast<herm::link_code>(rng() % 8));
  }
  return a;
}

TEST(hermc_interop_net, updates_in_both_directions) {
  std::mt19937 rng(99);
  for (int i = 0; i < cases; ++i) {
    herm::update u;
    u.sender = static_cast<uint16_t>(rng());
    u.instance = rng();
    auto count = rng() % 5;
    for (size_t e = 0; e < count; ++e)
      u.entries.push_back(random_entry(rng));
    byte_buffer cpp;
    herm::encode(u, cpp);
    // C++ -> C: every entry read back equal.
    hermc_update_header h{};
    hermc_update_entry es[4]{};
    ASSERT_EQ(hermc_update_decode(cpp.data(), cpp.size(), &h, es, 4),
              HERMC_NET_OK);
    EXPECT_EQ(h.sender, u.sender);
    EXPECT_EQ(h.instance, u.instance);
    ASSERT_EQ(h.count, u.entries.size());
    for (size_t e = 0; e < count; ++e) {
      auto& a = u.entries[e];
      EXPECT_EQ(es[e].origin, a.origin);
      EXPECT_EQ(es[e].seqno, a.seqno);
      for (size_t k = 0; k < 4; ++k) {
        EXPECT_EQ(es[e].metric[k], a.metrics[k]);
        ASSERT_EQ(es[e].hops[k], a.path[k].size());
        for (size_t p = 0; p < a.path[k].size(); ++p)
          EXPECT_EQ(es[e].path[k][p], static_cast<uint8_t>(a.path[k][p]));
      }
    }
    // C -> C++: the C encoder writes the same bytes from what it read.
    uint8_t buf[700];
    auto n = hermc_update_encode(h.sender, h.instance, es, h.count, buf,
                                 sizeof buf);
    EXPECT_EQ(from_c(buf, n), cpp);
    auto back = herm::decode_update(buf, n);
    ASSERT_TRUE(back) << herm::render(back.error());
    EXPECT_EQ(back->entries.size(), count);
  }
}

TEST(hermc_interop_net, mutated_packets_are_accepted_or_refused_alike) {
  std::mt19937 rng(7);
  for (int i = 0; i < cases * 10; ++i) {
    herm::update u;
    u.sender = 1;
    u.instance = 2;
    u.entries.push_back(random_entry(rng));
    byte_buffer b;
    if (rng() % 2)
      herm::encode(u, b);
    else
      herm::encode(herm::hello{3, 4, 5, 6}, b);
    // Flip, cut or extend.
    switch (rng() % 3) {
      case 0:
        b[rng() % b.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
        break;
      case 1:
        b.resize(rng() % b.size());
        break;
      default:
        b.push_back(static_cast<uint8_t>(rng()));
    }
    hermc_update_header h{};
    EXPECT_EQ(hermc_update_decode(b.data(), b.size(), &h, nullptr, 0)
                == HERMC_NET_OK,
              static_cast<bool>(herm::decode_update(b.data(), b.size())));
    hermc_hello hc{};
    EXPECT_EQ(hermc_hello_decode(b.data(), b.size(), &hc) == HERMC_NET_OK,
              static_cast<bool>(herm::decode_hello(b.data(), b.size())));
  }
}

// -- APO messages -------------------------------------------------------------------

std::string text(const hermc_bytes& b) {
  return std::string(reinterpret_cast<const char*>(b.data), b.size);
}

byte_buffer bytes_of(const hermc_bytes& b) {
  return byte_buffer(b.data, b.data + b.size);
}

std::string random_string(std::mt19937& rng, size_t max) {
  std::string s(rng() % (max + 1), 'x');
  for (auto& c : s)
    c = static_cast<char>(rng());
  return s;
}

TEST(hermc_interop_asl, what_the_board_sends_the_cpp_decoder_reads_back) {
  std::mt19937 rng(2024);
  for (int i = 0; i < cases; ++i) {
    uint8_t buf[600];
    // An answer with up to three entries.
    auto qid = static_cast<uint32_t>(rng());
    uint8_t count = static_cast<uint8_t>(rng() % 4);
    std::vector<herm::asl_entry> entries;
    auto n = hermc_asl_answer_begin(qid, count, buf, sizeof buf);
    for (uint8_t e = 0; e < count; ++e) {
      herm::asl_entry x{static_cast<uint32_t>(rng()), random_string(rng, 20),
                        random_string(rng, 20)};
      n += hermc_asl_answer_entry_encode(x.apo, x.name.data(), x.name.size(),
                                         x.type.data(), x.type.size(), buf + n,
                                         sizeof buf - n);
      entries.push_back(x);
    }
    auto a = herm::decode_asl(buf, n);
    ASSERT_TRUE(a) << herm::render(a.error());
    EXPECT_EQ(std::get<herm::asl_answer>(*a),
              (herm::asl_answer{qid, entries}));

    // A response, ok or error.
    auto rid = (uint64_t{rng()} << 32) | rng() | 1u;
    auto payload = random_string(rng, 40);
    if (rng() % 2) {
      n = hermc_asl_response_ok_header(rid, buf, sizeof buf);
      std::copy(payload.begin(), payload.end(), buf + n);
      n += payload.size();
      auto r = herm::decode_asl(buf, n);
      ASSERT_TRUE(r);
      auto& x = std::get<herm::asl_response>(*r);
      EXPECT_TRUE(x.ok);
      EXPECT_EQ(x.request_id, rid);
      EXPECT_EQ(x.payload, byte_buffer(payload.begin(), payload.end()));
    } else {
      auto code = static_cast<uint8_t>(rng());
      n = hermc_asl_response_error_encode(rid, HERMC_ERROR_CATEGORY_HERM, code,
                                          payload.data(), payload.size(), buf,
                                          sizeof buf);
      auto r = herm::decode_asl(buf, n);
      ASSERT_TRUE(r);
      auto& x = std::get<herm::asl_response>(*r);
      EXPECT_FALSE(x.ok);
      EXPECT_EQ(x.error.category, HERMC_ERROR_CATEGORY_HERM);
      EXPECT_EQ(x.error.code, code);
      EXPECT_EQ(x.error.context, payload);
    }

    // A publish, an advertise, a request, a query.
    auto topic = random_string(rng, 30);
    auto seq = static_cast<uint32_t>(rng());
    n = hermc_asl_publish_header(topic.data(), topic.size(), seq, buf,
                                 sizeof buf);
    std::copy(payload.begin(), payload.end(), buf + n);
    auto p = herm::decode_asl(buf, n + payload.size());
    ASSERT_TRUE(p);
    EXPECT_EQ(std::get<herm::asl_publish>(*p),
              (herm::asl_publish{topic, seq,
                                 byte_buffer(payload.begin(), payload.end())}));
    n = hermc_asl_advertise_encode(topic.data(), topic.size(), buf, sizeof buf);
    auto ad = herm::decode_asl(buf, n);
    ASSERT_TRUE(ad);
    EXPECT_EQ(std::get<herm::asl_advertise>(*ad), herm::asl_advertise{topic});
    auto apo = static_cast<uint32_t>(rng());
    n = hermc_asl_request_header(rid, apo, 0, 0, buf, sizeof buf);
    auto rq = herm::decode_asl(buf, n);
    ASSERT_TRUE(rq);
    EXPECT_EQ(std::get<herm::asl_request>(*rq),
              (herm::asl_request{rid, apo, {}}));
    n = hermc_asl_query_encode(qid, HERMC_BY_NAME, topic.data(), topic.size(),
                               buf, sizeof buf);
    auto q = herm::decode_asl(buf, n);
    ASSERT_TRUE(q);
    EXPECT_EQ(std::get<herm::asl_query>(*q),
              (herm::asl_query{qid, herm::query_by::name, topic}));
  }
}

TEST(hermc_interop_asl, what_a_hermd_sends_the_board_reads_back) {
  std::mt19937 rng(31337);
  for (int i = 0; i < cases; ++i) {
    auto rid = (uint64_t{rng()} << 32) | rng() | 1u;
    auto s = random_string(rng, 30);
    byte_buffer payload(rng() % 20, 0xA5);
    std::vector<herm::asl_message> msgs{
      herm::asl_query{static_cast<uint32_t>(rng()),
                      static_cast<herm::query_by>(rng() % 2), s},
      herm::asl_request{rid, static_cast<uint32_t>(rng()), payload},
      herm::asl_reliable_request{rid, static_cast<uint32_t>(rng()),
                                 rng() % 2 == 0, payload},
      herm::asl_response{rid, true, payload, {}},
      herm::asl_response{rid, false, {}, {HERMC_ERROR_CATEGORY_HERM, 16, s}},
      herm::asl_subscribe{s, static_cast<uint32_t>(rng())},
      herm::asl_unsubscribe{s},
      herm::asl_withdraw{static_cast<uint32_t>(rng()), s},
      herm::asl_ack{rid},
    };
    for (auto& msg : msgs) {
      byte_buffer b;
      herm::encode(msg, b);
      hermc_asl_msg m{};
      ASSERT_EQ(hermc_asl_decode(b.data(), b.size(), &m), HERMC_ASL_OK);
      std::visit(
        [&](auto& x) {
          using T = std::decay_t<decltype(x)>;
          if constexpr (std::is_same_v<T, herm::asl_query>) {
            EXPECT_EQ(m.id32, x.query_id);
            EXPECT_EQ(m.by, static_cast<uint8_t>(x.by));
            EXPECT_EQ(text(m.text), x.pattern);
          } else if constexpr (std::is_same_v<T, herm::asl_request>) {
            EXPECT_EQ(m.request_id, x.request_id);
            EXPECT_EQ(m.id32, x.apo);
            EXPECT_EQ(bytes_of(m.payload), x.payload);
          } else if constexpr (std::is_same_v<T, herm::asl_reliable_request>) {
            EXPECT_EQ(m.kind, HERMC_ASL_RELIABLE_REQUEST);
            EXPECT_EQ(m.oneway != 0, x.oneway);
            EXPECT_EQ(bytes_of(m.payload), x.payload);
          } else if constexpr (std::is_same_v<T, herm::asl_response>) {
            EXPECT_EQ(m.ok != 0, x.ok);
            if (x.ok) {
              EXPECT_EQ(bytes_of(m.payload), x.payload);
            } else {
              EXPECT_EQ(m.err_code, x.error.code);
              EXPECT_EQ(text(m.text), x.error.context);
            }
          } else if constexpr (std::is_same_v<T, herm::asl_subscribe>) {
            EXPECT_EQ(text(m.text), x.topic);
            EXPECT_EQ(m.u32, x.lease_ms);
          } else if constexpr (std::is_same_v<T, herm::asl_withdraw>) {
            EXPECT_EQ(m.id32, x.apo);
            EXPECT_EQ(text(m.text), x.name);
          } else if constexpr (std::is_same_v<T, herm::asl_ack>) {
            EXPECT_EQ(m.request_id, x.request_id);
          } else if constexpr (std::is_same_v<T, herm::asl_unsubscribe>) {
            EXPECT_EQ(text(m.text), x.topic);
          }
        },
        msg);
    }
  }
}

TEST(hermc_interop_asl, mutated_messages_are_accepted_or_refused_alike) {
  std::mt19937 rng(5);
  std::vector<herm::asl_message> seeds{
    herm::asl_query{1, herm::query_by::any, ""},
    herm::asl_answer{2, {{1, "a", "t"}, {2, "", ""}}},
    herm::asl_response{3, false, {}, {1, 2, "ctx"}},
    herm::asl_reliable_request{4, 5, true, {1, 2}},
    herm::asl_down{6, {1, 2, "x"}},
    herm::asl_subscribe{"pose", 1000},
    herm::asl_ack{7},
  };
  for (int i = 0; i < cases * 10; ++i) {
    byte_buffer b;
    herm::encode(seeds[rng() % seeds.size()], b);
    switch (rng() % 3) {
      case 0:
        b[rng() % b.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
        break;
      case 1:
        b.resize(rng() % b.size());
        break;
      default:
        b.push_back(static_cast<uint8_t>(rng()));
    }
    hermc_asl_msg m{};
    EXPECT_EQ(hermc_asl_decode(b.data(), b.size(), &m) == HERMC_ASL_OK,
              static_cast<bool>(herm::decode_asl(b.data(), b.size())));
  }
}

// -- APO payloads --------------------------------------------------------------------

class hermc_interop_payload : public ::testing::Test {
public:
  static void SetUpTestSuite() {
    cfg_ = std::make_unique<caf::actor_system_config>();
    herm::configure(*cfg_);
    cfg_->add_message_types<caf::id_block::herm_apos>();
    sys_ = std::make_unique<caf::actor_system>(*cfg_);
  }

  static void TearDownTestSuite() {
    sys_.reset();
    cfg_.reset();
  }

protected:
  static std::unique_ptr<caf::actor_system_config> cfg_;
  static std::unique_ptr<caf::actor_system> sys_;
};

std::unique_ptr<caf::actor_system_config> hermc_interop_payload::cfg_;
std::unique_ptr<caf::actor_system> hermc_interop_payload::sys_;

TEST_F(hermc_interop_payload, the_boards_reading_unmarshals_into_the_cpp_struct) {
  std::mt19937 rng(12);
  for (int i = 0; i < cases; ++i) {
    hermc_srf04_reading c{static_cast<uint16_t>(rng()),
                          static_cast<uint16_t>(rng()),
                          static_cast<uint32_t>(rng())};
    uint8_t buf[40];
    auto n = hermc_srf04_encode(&c, buf, sizeof buf);
    ASSERT_GT(n, 0u);
    auto msg = herm::unmarshal(*sys_, buf, n);
    ASSERT_TRUE(msg) << herm::render(msg.error());
    ASSERT_TRUE(msg->match_elements<interop::srf04_reading>());
    auto& r = msg->get_as<interop::srf04_reading>(0);
    EXPECT_EQ(r.seq, c.seq);
    EXPECT_EQ(r.distance_mm, c.distance_mm);
    EXPECT_EQ(r.echo_us, c.echo_us);
    // And C++ writes the very same bytes, which the board reads back.
    auto cpp = herm::marshal(*sys_, caf::make_message(r));
    ASSERT_TRUE(cpp);
    EXPECT_EQ(*cpp, from_c(buf, n));
    hermc_srf04_reading back{};
    ASSERT_EQ(hermc_srf04_decode(cpp->data(), cpp->size(), &back), HERMC_PR_OK);
    EXPECT_EQ(back.echo_us, c.echo_us);
  }
}

TEST_F(hermc_interop_payload, primitives_and_strings_as_cpp_marshals_them) {
  std::mt19937 rng(77);
  for (int i = 0; i < cases; ++i) {
    auto u16 = static_cast<uint16_t>(rng());
    auto u64 = (uint64_t{rng()} << 32) | rng();
    auto s = random_string(rng, 200);
    auto msg = caf::make_message(u16, u64, s, rng() % 2 == 0);
    auto cpp = herm::marshal(*sys_, msg);
    ASSERT_TRUE(cpp) << herm::render(cpp.error());
    // The board writes the same.
    uint8_t buf[512];
    hermc_pw w;
    hermc_pw_begin(&w, buf, sizeof buf, 4);
    hermc_pw_element(&w, "@u16");
    hermc_pw_u16(&w, u16);
    hermc_pw_element(&w, "@u64");
    hermc_pw_u64(&w, u64);
    hermc_pw_element(&w, "@str");
    hermc_pw_bytes(&w, reinterpret_cast<const uint8_t*>(s.data()), s.size());
    hermc_pw_element(&w, "bool");
    hermc_pw_bool(&w, msg.get_as<bool>(3));
    auto n = hermc_pw_finish(&w);
    ASSERT_GT(n, 0u);
    EXPECT_EQ(from_c(buf, n), *cpp);
    // And reads it back.
    hermc_pr r;
    ASSERT_EQ(hermc_pr_begin(&r, cpp->data(), cpp->size()), 4u);
    hermc_pr_element(&r, "@u16");
    EXPECT_EQ(hermc_pr_u16(&r), u16);
    hermc_pr_element(&r, "@u64");
    EXPECT_EQ(hermc_pr_u64(&r), u64);
    const uint8_t* p;
    size_t len;
    hermc_pr_element(&r, "@str");
    hermc_pr_bytes(&r, &p, &len);
    EXPECT_EQ(std::string(reinterpret_cast<const char*>(p), len), s);
    hermc_pr_element(&r, "bool");
    EXPECT_EQ(hermc_pr_bool(&r) != 0, msg.get_as<bool>(3));
    EXPECT_EQ(hermc_pr_finish(&r), HERMC_PR_OK);
  }
}

} // namespace
