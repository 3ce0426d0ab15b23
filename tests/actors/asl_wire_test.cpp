// Wire format of the Application Support Layer: exact layouts (the tables of
// docs/protocol.md, "APO messages"), round trips of every kind, refusals,
// and a decoder that is total on any byte string.

#include <gtest/gtest.h>

#include <cstdio>
#include <functional>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "caf/atom.hpp"

#include "actors/asl_wire.hpp"
#include "actors/runtime/error.hpp"

using namespace herm;

namespace {

// -- helpers ---------------------------------------------------------------------

byte_buffer bytes(std::initializer_list<int> xs) {
  byte_buffer out;
  for (auto x : xs)
    out.push_back(static_cast<uint8_t>(x));
  return out;
}

byte_buffer operator+(byte_buffer a, const byte_buffer& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

byte_buffer enc(const asl_message& x) {
  byte_buffer out;
  encode(x, out);
  return out;
}

caf::expected<asl_message> dec(const byte_buffer& b) {
  return decode_asl(b.data(), b.size());
}

/// "01 0B 04 ..." for failure messages.
std::string hex(const byte_buffer& b) {
  std::string out;
  char buf[4];
  for (size_t i = 0; i < b.size(); ++i) {
    std::snprintf(buf, sizeof(buf), i == 0 ? "%02X" : " %02X", b[i]);
    out += buf;
  }
  return out;
}

/// The context string of a decoder's error ("query: 3 trailing bytes").
template <class T>
std::string error_of(const caf::expected<T>& x) {
  if (x)
    return "(decoded)";
  EXPECT_TRUE(is(x.error(), ec::invalid_parameter)) << render(x.error());
  auto text = render(x.error());
  auto prefix = std::string{"herm.invalid_parameter: "};
  return text.compare(0, prefix.size(), prefix) == 0 ? text.substr(prefix.size())
                                                     : text;
}

/// 0, 1, 2, ... (mod 256).
byte_buffer counting(size_t n) {
  byte_buffer out(n);
  for (size_t i = 0; i < n; ++i)
    out[i] = static_cast<uint8_t>(i);
  return out;
}

/// A string of n bytes: "abc...zabc...".
std::string letters(size_t n) {
  std::string out(n, 'a');
  for (size_t i = 0; i < n; ++i)
    out[i] = static_cast<char>('a' + i % 26);
  return out;
}

/// HERM's error category atom ("herm") as it travels.
constexpr uint64_t herm_category = 0x0FB6ADF2;

asl_kind kind_of(const asl_message& x) {
  return static_cast<asl_kind>(x.index() + 1);
}

/// How errors name the kind of `x`.
const char* kind_name(const asl_message& x) {
  static const char* names[] = {"query",    "answer",    "request",
                                "response", "watch",     "unwatch",
                                "down",     "withdraw",  "subscribe",
                                "unsubscribe", "publish", "advertise",
                                "reliable request", "ack"};
  return names[x.index()];
}

template <class T, class = void>
struct has_payload : std::false_type {};

template <class T>
struct has_payload<T, std::void_t<decltype(std::declval<T&>().payload)>>
  : std::true_type {};

/// `x` with its payload replaced (kinds without one: `x` itself).
asl_message with_payload(asl_message x, const byte_buffer& payload) {
  std::visit(
    [&](auto& y) {
      if constexpr (has_payload<std::decay_t<decltype(y)>>::value)
        y.payload = payload;
    },
    x);
  return x;
}

/// Where the payload starts in the encoding of `x`: the size of its encoding
/// for kinds that end without one (error responses included).
size_t payload_offset(const asl_message& x) {
  return enc(with_payload(x, {})).size();
}

/// Whether the encoding of `x` ends in a payload that takes the rest.
bool ends_in_payload(const asl_message& x) {
  if (auto r = std::get_if<asl_response>(&x))
    return r->ok;
  return std::holds_alternative<asl_request>(x)
         || std::holds_alternative<asl_publish>(x)
         || std::holds_alternative<asl_reliable_request>(x);
}

asl_answer largest_answer() {
  asl_answer x{0xFFFFFFFF, {}};
  for (size_t i = 0; i < max_answer_entries; ++i)
    x.entries.push_back({static_cast<uint32_t>(0xFFFFFFFF - i),
                         std::string(max_asl_string, static_cast<char>('A' + i % 26)),
                         letters(max_asl_string)});
  return x;
}

/// Valid messages of every kind with edge values: the seeds of the round
/// trip, truncation, trailing-byte and fuzz tests.
struct sample {
  std::string name;
  asl_message msg;
};

std::vector<sample> samples() {
  auto max32 = uint32_t{0xFFFFFFFF};
  auto max64 = ~uint64_t{0};
  auto s255 = letters(max_asl_string);
  return {
    {"query by name", asl_query{7, query_by::name, "camera"}},
    {"query by type, longest pattern", asl_query{max32, query_by::type, s255}},
    {"query by name, empty pattern", asl_query{0, query_by::name, ""}},
    {"query any", asl_query{1, query_by::any, ""}},
    {"empty answer", asl_answer{5, {}}},
    {"answer", asl_answer{5, {{1, "cam", "camera"}, {0, "", ""}, {max32, "x", ""}}}},
    {"largest answer", largest_answer()},
    {"one-way request, empty payload", asl_request{0, 3, {}}},
    {"request", asl_request{max64, max32, counting(300)}},
    {"ok response, empty payload", asl_response{1, true, {}, {}}},
    {"ok response", asl_response{max64, true, counting(40), {}}},
    {"error response", asl_response{9, false, {}, {herm_category, 16, "gone"}}},
    {"error response, empty context", asl_response{9, false, {}, {0, 0, ""}}},
    {"error response, longest context",
     asl_response{max64, false, {}, {max64, 255, s255}}},
    {"watch", asl_watch{0x2A}},
    {"watch max", asl_watch{max32}},
    {"unwatch", asl_unwatch{0}},
    {"down", asl_down{0x2A, {herm_category, 16, "exited"}}},
    {"down, empty reason", asl_down{0, {0, 0, ""}}},
    {"down, longest context", asl_down{max32, {max64, 255, s255}}},
    {"withdraw", asl_withdraw{3, "cam"}},
    {"withdraw, empty name", asl_withdraw{0, ""}},
    {"withdraw, longest name", asl_withdraw{max32, s255}},
    {"subscribe", asl_subscribe{"pose", 1000}},
    {"subscribe, empty topic", asl_subscribe{"", 0}},
    {"subscribe, longest topic", asl_subscribe{s255, max32}},
    {"unsubscribe", asl_unsubscribe{"pose"}},
    {"unsubscribe, empty topic", asl_unsubscribe{""}},
    {"publish", asl_publish{"pose", 42, counting(12)}},
    {"publish, empty everything", asl_publish{"", 0, {}}},
    {"publish, longest topic, large payload",
     asl_publish{s255, max32, counting(1000)}},
    {"advertise", asl_advertise{"pose"}},
    {"advertise, longest topic", asl_advertise{s255}},
    {"reliable request", asl_reliable_request{1, 3, false, counting(20)}},
    {"reliable one-way, empty payload", asl_reliable_request{max64, max32, true, {}}},
    {"ack", asl_ack{1}},
    {"ack max", asl_ack{max64}},
  };
}

} // namespace

// -- header ----------------------------------------------------------------------

TEST(asl_wire_kind, peek_reads_version_1_and_the_fourteen_kinds) {
  for (int k = 0; k < 256; ++k) {
    SCOPED_TRACE(k);
    auto b = bytes({1, k});
    auto kind = peek_asl_kind(b.data(), b.size());
    if (k >= 1 && k <= 14) {
      ASSERT_TRUE(kind) << render(kind.error());
      EXPECT_EQ(static_cast<int>(*kind), k);
    } else {
      EXPECT_EQ(error_of(kind), "asl: unknown kind " + std::to_string(k));
    }
  }
  EXPECT_EQ(error_of(peek_asl_kind(nullptr, 0)), "asl: empty message");
  auto v2 = bytes({2, 1});
  EXPECT_EQ(error_of(peek_asl_kind(v2.data(), v2.size())),
            "asl: version 2, expected 1");
  auto only_version = bytes({1});
  EXPECT_EQ(error_of(peek_asl_kind(only_version.data(), only_version.size())),
            "asl: kind truncated (needs 1 byte, 0 left)");
}

TEST(asl_wire_kind, every_sample_announces_its_own_kind) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    auto b = enc(s.msg);
    auto kind = peek_asl_kind(b.data(), b.size());
    ASSERT_TRUE(kind) << render(kind.error());
    EXPECT_EQ(*kind, kind_of(s.msg));
  }
}

// -- exact layouts (the tables of the protocol document) ------------------------

TEST(asl_wire_layout, the_error_category_in_these_examples_is_herms_atom) {
  EXPECT_EQ(static_cast<uint64_t>(caf::atom("herm")), herm_category);
}

TEST(asl_wire_layout, query) {
  EXPECT_EQ(hex(enc(asl_query{0x01020304, query_by::type, "cam"})),
            "01 01 04 03 02 01 01 03 63 61 6D");
  EXPECT_EQ(hex(enc(asl_query{5, query_by::any, ""})),
            "01 01 05 00 00 00 02 00");
}

TEST(asl_wire_layout, query_any_sends_an_empty_pattern_whatever_it_holds) {
  EXPECT_EQ(enc(asl_query{5, query_by::any, "ignored"}),
            enc(asl_query{5, query_by::any, ""}));
}

TEST(asl_wire_layout, answer) {
  EXPECT_EQ(hex(enc(asl_answer{0x0A, {{0x11, "a", "t"}, {0x22, "", ""}}})),
            "01 02 0A 00 00 00 02 11 00 00 00 01 61 01 74 22 00 00 00 00 00");
}

TEST(asl_wire_layout, request) {
  EXPECT_EQ(hex(enc(asl_request{0x0807060504030201, 0x2A, {0xDE, 0xAD}})),
            "01 03 01 02 03 04 05 06 07 08 2A 00 00 00 DE AD");
  EXPECT_EQ(hex(enc(asl_request{0, 0x2A, {}})),
            "01 03 00 00 00 00 00 00 00 00 2A 00 00 00");
}

TEST(asl_wire_layout, response_ok) {
  EXPECT_EQ(hex(enc(asl_response{0x0807060504030201, true, {0xBE, 0xEF}, {}})),
            "01 04 01 02 03 04 05 06 07 08 01 BE EF");
}

TEST(asl_wire_layout, response_error) {
  EXPECT_EQ(hex(enc(asl_response{0x0807060504030201, false, {},
                                 {herm_category, 16, "gone"}})),
            "01 04 01 02 03 04 05 06 07 08 00 F2 AD B6 0F 00 00 00 00 10 04 67 "
            "6F 6E 65");
}

TEST(asl_wire_layout, watch_and_unwatch) {
  EXPECT_EQ(hex(enc(asl_watch{0x2A})), "01 05 2A 00 00 00");
  EXPECT_EQ(hex(enc(asl_unwatch{0x2A})), "01 06 2A 00 00 00");
}

TEST(asl_wire_layout, down) {
  EXPECT_EQ(hex(enc(asl_down{0x2A, {herm_category, 16, ""}})),
            "01 07 2A 00 00 00 F2 AD B6 0F 00 00 00 00 10 00");
}

TEST(asl_wire_layout, withdraw) {
  EXPECT_EQ(hex(enc(asl_withdraw{0x2A, "cam"})),
            "01 08 2A 00 00 00 03 63 61 6D");
}

TEST(asl_wire_layout, subscribe_unsubscribe_and_advertise) {
  EXPECT_EQ(hex(enc(asl_subscribe{"pose", 1000})),
            "01 09 04 70 6F 73 65 E8 03 00 00");
  EXPECT_EQ(hex(enc(asl_unsubscribe{"pose"})), "01 0A 04 70 6F 73 65");
  EXPECT_EQ(hex(enc(asl_advertise{"pose"})), "01 0C 04 70 6F 73 65");
}

TEST(asl_wire_layout, publish) {
  EXPECT_EQ(hex(enc(asl_publish{"pose", 7, {0x01, 0x02}})),
            "01 0B 04 70 6F 73 65 07 00 00 00 01 02");
}

TEST(asl_wire_layout, reliable_request_and_ack) {
  EXPECT_EQ(hex(enc(asl_reliable_request{0x0807060504030201, 0x2A, false,
                                         {0xDE, 0xAD}})),
            "01 0D 01 02 03 04 05 06 07 08 2A 00 00 00 00 DE AD");
  EXPECT_EQ(hex(enc(asl_reliable_request{5, 0x2A, true, {}})),
            "01 0D 05 00 00 00 00 00 00 00 2A 00 00 00 01");
  EXPECT_EQ(hex(enc(asl_ack{0x0807060504030201})),
            "01 0E 01 02 03 04 05 06 07 08");
}

TEST(asl_wire_layout, encode_appends_to_what_the_buffer_holds) {
  byte_buffer out{0xAA};
  encode(asl_watch{1}, out);
  EXPECT_EQ(hex(out), "AA 01 05 01 00 00 00");
}

TEST(asl_wire_layout, the_largest_answer_takes_33031_bytes) {
  // 7 header bytes + 64 entries * (4 + 1 + 255 + 1 + 255).
  EXPECT_EQ(enc(largest_answer()).size(), 33031u);
}

// -- round trips -----------------------------------------------------------------

TEST(asl_wire_round_trip, every_sample_decodes_to_itself_and_reencodes_to_the_same_bytes) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    auto b = enc(s.msg);
    auto d = dec(b);
    ASSERT_TRUE(d) << render(d.error()) << "\n" << hex(b);
    EXPECT_TRUE(*d == s.msg);
    EXPECT_EQ(enc(*d), b);
  }
}

TEST(asl_wire_round_trip, an_error_context_longer_than_255_bytes_is_truncated) {
  struct row {
    const char* why;
    std::string context;
    std::string expected;
  };
  const row rows[] = {
    {"ascii", std::string(300, 'x'), std::string(255, 'x')},
    {"exactly 256", letters(256), letters(255)},
    // A character cut by byte 255 is dropped whole: no half UTF-8 sequence.
    {"two-byte character across the cut", std::string(254, 'a') + "\xC3\xA9",
     std::string(254, 'a')},
    {"three-byte character across the cut", std::string(253, 'a') + "\xE2\x82\xAC",
     std::string(253, 'a')},
    {"four-byte character across the cut",
     std::string(252, 'a') + "\xF0\x9F\x98\x80" + "tail", std::string(252, 'a')},
    {"character ending at the cut", std::string(253, 'a') + "\xC3\xA9" + "b",
     std::string(253, 'a') + "\xC3\xA9"},
    {"not UTF-8: cut at 255", std::string(300, '\x80'), std::string(255, '\x80')},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.why);
    for (auto& m : {asl_message{asl_response{1, false, {}, {2, 3, r.context}}},
                    asl_message{asl_down{4, {2, 3, r.context}}}}) {
      auto b = enc(m);
      auto d = dec(b);
      ASSERT_TRUE(d) << render(d.error());
      auto& got = std::holds_alternative<asl_down>(*d)
                    ? std::get<asl_down>(*d).reason
                    : std::get<asl_response>(*d).error;
      EXPECT_EQ(got.context, r.expected);
      EXPECT_EQ(got.category, 2u);
      EXPECT_EQ(got.code, 3u);
    }
  }
}

TEST(asl_wire_round_trip, a_response_carries_only_the_alternative_ok_selects) {
  // Equality of responses compares what ok selects, which is what travels.
  asl_response ok{7, true, {1, 2, 3}, {herm_category, 16, "unsent"}};
  asl_response err{7, false, {1, 2, 3}, {herm_category, 16, "sent"}};
  EXPECT_EQ(enc(ok), enc(asl_response{7, true, {1, 2, 3}, {}}));
  EXPECT_EQ(enc(err), enc(asl_response{7, false, {}, {herm_category, 16, "sent"}}));
  for (auto& m : {asl_message{ok}, asl_message{err}}) {
    auto d = dec(enc(m));
    ASSERT_TRUE(d) << render(d.error());
    EXPECT_TRUE(*d == m);
  }
  EXPECT_FALSE(ok == (asl_response{7, true, {1, 2}, {}}));
  EXPECT_FALSE(err == (asl_response{7, false, {}, {herm_category, 16, "other"}}));
  EXPECT_FALSE(ok == (asl_response{8, true, {1, 2, 3}, {}}));
  asl_response err_with_ok_payload = err;
  err_with_ok_payload.ok = true;
  EXPECT_FALSE(err == err_with_ok_payload);
}

TEST(asl_wire_round_trip, payloads_take_the_rest_of_the_message_whatever_it_holds) {
  // An APO payload may itself start with bytes that look like a header.
  for (auto& payload : {byte_buffer{}, bytes({1, 4}), bytes({0}), counting(256)}) {
    for (auto& m : {asl_message{asl_request{1, 2, payload}},
                    asl_message{asl_response{1, true, payload, {}}},
                    asl_message{asl_publish{"t", 3, payload}}}) {
      auto d = dec(enc(m));
      ASSERT_TRUE(d) << render(d.error());
      EXPECT_TRUE(*d == m);
    }
  }
}

TEST(asl_wire_round_trip, decoding_a_whole_buffer_gives_it_to_the_payload_without_a_copy) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    auto b = enc(s.msg);
    auto copy = b;
    const uint8_t* storage = copy.data();
    auto d = decode_asl(std::move(copy));
    ASSERT_TRUE(d) << render(d.error());
    EXPECT_TRUE(*d == s.msg);
    EXPECT_EQ(enc(*d), b);
    const byte_buffer* payload = std::visit(
      [](auto& x) -> const byte_buffer* {
        using T = std::decay_t<decltype(x)>;
        if constexpr (std::is_same_v<T, asl_request> || std::is_same_v<T, asl_response>
                      || std::is_same_v<T, asl_publish>
                      || std::is_same_v<T, asl_reliable_request>)
          return &x.payload;
        else
          return nullptr;
      },
      *d);
    if (payload == nullptr) {
      EXPECT_EQ(copy, b); // kinds without a payload leave it
    } else if (!payload->empty()) {
      EXPECT_EQ(payload->data(), storage); // the message's own bytes
    }
  }
  // On an error the buffer is left as it was.
  auto b = enc(asl_message{asl_request{1, 2, counting(16)}});
  b[0] = 2;
  auto copy = b;
  EXPECT_FALSE(decode_asl(std::move(copy)));
  EXPECT_EQ(copy, b);
}

// -- malformed messages ----------------------------------------------------------

TEST(asl_wire_malformed, every_truncation_before_a_payload_is_refused) {
  // A message that ends in a payload decodes at any length from where the
  // payload starts, with a shorter payload; every shorter prefix, and every
  // prefix of a message without payload, is refused.
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    auto b = enc(s.msg);
    auto start = payload_offset(s.msg);
    if (!ends_in_payload(s.msg)) {
      ASSERT_EQ(start, b.size());
    }
    for (size_t n = 0; n < b.size(); ++n) {
      SCOPED_TRACE(n);
      byte_buffer cut(b.begin(), b.begin() + static_cast<ptrdiff_t>(n));
      auto d = dec(cut);
      if (n < start) {
        ASSERT_FALSE(d);
        EXPECT_TRUE(is(d.error(), ec::invalid_parameter));
      } else {
        ASSERT_TRUE(ends_in_payload(s.msg));
        ASSERT_TRUE(d) << render(d.error());
        byte_buffer rest(cut.begin() + static_cast<ptrdiff_t>(start), cut.end());
        EXPECT_TRUE(*d == with_payload(s.msg, rest));
      }
    }
  }
}

TEST(asl_wire_malformed, trailing_bytes_are_refused_unless_a_payload_takes_them) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    for (size_t extra : {1, 3, 200}) {
      auto b = enc(s.msg);
      b.resize(b.size() + extra, 0x5A);
      auto d = dec(b);
      if (ends_in_payload(s.msg)) {
        ASSERT_TRUE(d) << render(d.error());
        EXPECT_EQ(enc(*d), b);
      } else {
        EXPECT_EQ(error_of(d),
                  std::string{} + kind_name(s.msg) + ": "
                    + std::to_string(extra)
                    + (extra == 1 ? " trailing byte" : " trailing bytes"));
      }
    }
  }
}

TEST(asl_wire_malformed, a_version_other_than_1_is_refused_for_every_kind) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    for (int v = 0; v < 256; ++v) {
      if (v == asl_wire_version)
        continue;
      auto b = enc(s.msg);
      b[0] = static_cast<uint8_t>(v);
      EXPECT_EQ(error_of(dec(b)),
                "asl: version " + std::to_string(v) + ", expected 1");
    }
  }
}

TEST(asl_wire_malformed, unknown_kinds_are_refused) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    for (int k : {0, 15, 16, 100, 127, 128, 255}) {
      auto b = enc(s.msg);
      b[1] = static_cast<uint8_t>(k);
      EXPECT_EQ(error_of(dec(b)), "asl: unknown kind " + std::to_string(k));
    }
  }
}

TEST(asl_wire_malformed, an_ok_byte_other_than_0_or_1_is_refused) {
  for (auto& m : {asl_message{asl_response{7, true, {1, 2}, {}}},
                  asl_message{asl_response{7, false, {}, {1, 2, "x"}}}}) {
    for (int v = 2; v < 256; ++v) {
      auto b = enc(m);
      b[10] = static_cast<uint8_t>(v);
      EXPECT_EQ(error_of(dec(b)),
                "response: ok is " + std::to_string(v) + ", expected 0 or 1");
    }
  }
}

TEST(asl_wire_malformed, a_query_by_value_above_2_is_refused) {
  for (int v = 3; v < 256; ++v) {
    auto b = enc(asl_query{1, query_by::name, "cam"});
    b[6] = static_cast<uint8_t>(v);
    EXPECT_EQ(error_of(dec(b)), "query: by " + std::to_string(v)
                                  + " unknown (0 name, 1 type, 2 any)");
  }
}

TEST(asl_wire_malformed, a_query_for_any_with_a_pattern_is_refused) {
  for (auto& pattern : {std::string{"x"}, letters(255)}) {
    auto b = enc(asl_query{1, query_by::name, pattern});
    b[6] = static_cast<uint8_t>(query_by::any);
    EXPECT_EQ(error_of(dec(b)), "query: by any with a "
                                  + std::to_string(pattern.size())
                                  + "-byte pattern (must be empty)");
  }
}

TEST(asl_wire_malformed, an_answer_with_more_than_64_entries_is_refused) {
  for (int count = 65; count < 256; ++count) {
    // Enough bytes for the entries to be there, so the bound is what fails.
    auto b = enc(asl_answer{1, {}});
    b[6] = static_cast<uint8_t>(count);
    b.resize(b.size() + static_cast<size_t>(count) * 6, 0);
    EXPECT_EQ(error_of(dec(b)),
              "answer: " + std::to_string(count) + " entries, at most 64");
  }
  // The encoder's bound matches: 64 entries decode.
  asl_answer full{1, {}};
  for (uint32_t i = 0; i < max_answer_entries; ++i)
    full.entries.push_back({i, "", ""});
  auto d = dec(enc(full));
  ASSERT_TRUE(d) << render(d.error());
  EXPECT_TRUE(*d == asl_message{full});
}

TEST(asl_wire_malformed, an_answer_count_is_checked_against_the_bytes_before_allocating) {
  // 64 announced entries need at least 64 * 6 bytes (apo and two empty
  // strings each); fewer are refused at the count, before any entry is read.
  for (size_t n = 0; n < 64 * 6; n += 5) {
    auto b = enc(asl_answer{1, {}});
    b[6] = 64;
    b.resize(b.size() + n, 0);
    EXPECT_EQ(error_of(dec(b)), "answer: 64 entries need at least 384 bytes, "
                                  + std::to_string(n) + " left");
  }
}

TEST(asl_wire_malformed, a_response_needs_a_request_id_but_a_request_may_be_one_way) {
  auto response = enc(asl_response{1, true, {}, {}});
  response[2] = 0;
  EXPECT_EQ(error_of(dec(response)),
            "response: request_id 0 (one-way requests get no response)");
  auto request = enc(asl_request{0, 1, {9}});
  auto d = dec(request);
  ASSERT_TRUE(d) << render(d.error());
  EXPECT_EQ(std::get<asl_request>(*d).request_id, 0u);
}

TEST(asl_wire_malformed, errors_say_what_was_wrong) {
  struct row {
    const char* name;
    byte_buffer bytes;
    std::string expected;
  };
  auto zero = [](size_t n) { return byte_buffer(n, 0); };
  auto herm = bytes({0xF2, 0xAD, 0xB6, 0x0F, 0, 0, 0, 0});
  const row rows[] = {
    {"empty", {}, "asl: empty message"},
    {"version", bytes({2, 1}), "asl: version 2, expected 1"},
    {"no kind", bytes({1}), "asl: kind truncated (needs 1 byte, 0 left)"},
    {"kind 0", bytes({1, 0}), "asl: unknown kind 0"},
    {"kind 15", bytes({1, 15}), "asl: unknown kind 15"},
    {"query id", bytes({1, 1, 4}),
     "query: query_id truncated (needs 4 bytes, 1 left)"},
    {"query by", bytes({1, 1, 4, 3, 2, 1}),
     "query: by truncated (needs 1 byte, 0 left)"},
    {"query by 3", bytes({1, 1, 0, 0, 0, 0, 3, 0}),
     "query: by 3 unknown (0 name, 1 type, 2 any)"},
    {"pattern length", bytes({1, 1, 0, 0, 0, 0, 0}),
     "query: pattern length truncated (needs 1 byte, 0 left)"},
    {"pattern", bytes({1, 1, 0, 0, 0, 0, 0, 5, 'a', 'b'}),
     "query: pattern truncated (needs 5 bytes, 2 left)"},
    {"any with pattern", bytes({1, 1, 0, 0, 0, 0, 2, 1, 'x'}),
     "query: by any with a 1-byte pattern (must be empty)"},
    {"query trailing", enc(asl_query{1, query_by::any, ""}) + zero(3),
     "query: 3 trailing bytes"},
    {"answer count", bytes({1, 2, 0, 0, 0, 0}),
     "answer: count truncated (needs 1 byte, 0 left)"},
    {"answer too many", bytes({1, 2, 0, 0, 0, 0, 65}),
     "answer: 65 entries, at most 64"},
    {"answer count beyond the bytes", bytes({1, 2, 0, 0, 0, 0, 64}) + zero(10),
     "answer: 64 entries need at least 384 bytes, 10 left"},
    {"answer name", bytes({1, 2, 0, 0, 0, 0, 2, 1, 0, 0, 0, 0, 0, 2, 0, 0, 0, 7,
                           'a', 'b', 'c'}),
     "answer: entry 2: name truncated (needs 7 bytes, 3 left)"},
    {"answer type length", bytes({1, 2, 0, 0, 0, 0, 1, 1, 0, 0, 0, 2, 'a', 'b'}),
     "answer: entry 1: type length truncated (needs 1 byte, 0 left)"},
    {"answer trailing", enc(asl_answer{1, {{1, "a", "b"}}}) + zero(1),
     "answer: 1 trailing byte"},
    {"request id", bytes({1, 3, 1, 2}),
     "request: request_id truncated (needs 8 bytes, 2 left)"},
    {"request apo", bytes({1, 3}) + zero(8) + bytes({1}),
     "request: apo truncated (needs 4 bytes, 1 left)"},
    {"response id 0", bytes({1, 4}) + zero(8) + bytes({1}),
     "response: request_id 0 (one-way requests get no response)"},
    {"response ok missing", bytes({1, 4, 1}) + zero(7),
     "response: ok truncated (needs 1 byte, 0 left)"},
    {"response ok 2", bytes({1, 4, 1}) + zero(7) + bytes({2}),
     "response: ok is 2, expected 0 or 1"},
    {"response error category", bytes({1, 4, 1}) + zero(7) + bytes({0, 0xF2, 0xAD}),
     "response: error.category truncated (needs 8 bytes, 2 left)"},
    {"response error code", bytes({1, 4, 1}) + zero(7) + bytes({0}) + herm,
     "response: error.code truncated (needs 1 byte, 0 left)"},
    {"response error context", bytes({1, 4, 1}) + zero(7) + bytes({0}) + herm
                                 + bytes({16, 4, 'g'}),
     "response: error.context truncated (needs 4 bytes, 1 left)"},
    {"response error trailing",
     enc(asl_response{1, false, {}, {herm_category, 16, "gone"}}) + zero(2),
     "response: 2 trailing bytes"},
    {"watch", bytes({1, 5, 0x2A, 0, 0}), "watch: apo truncated (needs 4 bytes, 3 left)"},
    {"watch trailing", bytes({1, 5, 0x2A, 0, 0, 0, 0}), "watch: 1 trailing byte"},
    {"unwatch trailing", bytes({1, 6, 0x2A, 0, 0, 0, 0, 0}),
     "unwatch: 2 trailing bytes"},
    {"down reason category", bytes({1, 7, 0x2A, 0, 0, 0, 0xF2}),
     "down: reason.category truncated (needs 8 bytes, 1 left)"},
    {"down reason context length", bytes({1, 7, 0x2A, 0, 0, 0}) + herm + bytes({16}),
     "down: reason.context length truncated (needs 1 byte, 0 left)"},
    {"withdraw name", bytes({1, 8, 0x2A, 0, 0, 0, 3, 'c'}),
     "withdraw: name truncated (needs 3 bytes, 1 left)"},
    {"subscribe topic length", bytes({1, 9}),
     "subscribe: topic length truncated (needs 1 byte, 0 left)"},
    {"subscribe lease", bytes({1, 9, 4, 'p', 'o', 's', 'e', 0xE8, 3}),
     "subscribe: lease_ms truncated (needs 4 bytes, 2 left)"},
    {"unsubscribe trailing", bytes({1, 10, 1, 'p', 'q'}),
     "unsubscribe: 1 trailing byte"},
    {"publish topic", bytes({1, 11, 255}) + zero(254),
     "publish: topic truncated (needs 255 bytes, 254 left)"},
    {"publish seq", bytes({1, 11, 0, 7, 0, 0}),
     "publish: seq truncated (needs 4 bytes, 3 left)"},
    {"advertise topic", bytes({1, 12, 2, 'p'}),
     "advertise: topic truncated (needs 2 bytes, 1 left)"},
    {"reliable request id 0", bytes({1, 13}) + zero(8) + bytes({1, 0, 0, 0, 0}),
     "reliable request: request_id 0 (reliable requests are numbered)"},
    {"reliable request oneway", bytes({1, 13, 1}) + zero(7) + bytes({1, 0, 0, 0, 2}),
     "reliable request: oneway is 2, expected 0 or 1"},
    {"reliable request apo", bytes({1, 13, 1}) + zero(7) + bytes({1, 0}),
     "reliable request: apo truncated (needs 4 bytes, 2 left)"},
    {"ack id 0", bytes({1, 14}) + zero(8),
     "ack: request_id 0 (reliable requests are numbered)"},
    {"ack trailing", bytes({1, 14, 1}) + zero(8),
     "ack: 1 trailing byte"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    EXPECT_EQ(error_of(dec(r.bytes)), r.expected) << hex(r.bytes);
  }
}

// -- robustness ------------------------------------------------------------------

namespace {

/// SplitMix64: fast and fully determined by its seed.
struct fast_rng {
  uint64_t state;

  uint64_t operator()() {
    auto z = (state += 0x9E3779B97F4A7C15);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EB;
    return z ^ (z >> 31);
  }
};

void mutate(byte_buffer& b, fast_rng& rng) {
  auto n = 1 + rng() % 4;
  for (size_t i = 0; i < n; ++i) {
    switch (rng() % 6) {
      case 0: // flip a bit
        if (!b.empty())
          b[rng() % b.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
        break;
      case 1: // overwrite a byte, mostly near the start where the fields are
        if (!b.empty())
          b[rng() % std::min<size_t>(b.size(), 24)] = static_cast<uint8_t>(rng());
        break;
      case 2: // cut
        b.resize(b.empty() ? 0 : rng() % b.size());
        break;
      case 3: // insert a byte
        b.insert(b.begin() + static_cast<ptrdiff_t>(rng() % (b.size() + 1)),
                 static_cast<uint8_t>(rng()));
        break;
      case 4: // drop a byte
        if (!b.empty())
          b.erase(b.begin() + static_cast<ptrdiff_t>(rng() % b.size()));
        break;
      case 5: // append garbage
        for (auto k = rng() % 5; k > 0; --k)
          b.push_back(static_cast<uint8_t>(rng()));
        break;
    }
  }
}

} // namespace

TEST(asl_wire_robustness, the_decoder_is_total_and_what_decodes_reencodes_to_the_same_bytes) {
  // 200,000 random and mutated byte strings, the same ones on every run.
  // Under ASan/UBSan (HERM_SANITIZE) this is a small fuzz of the bounds;
  // here it checks that every decoded value is exactly what its bytes said
  // (the encoding is canonical: re-encoding reproduces them) and that the
  // decoder agrees with peek_asl_kind.
  constexpr size_t inputs = 200'000;
  fast_rng rng{20240611};
  std::vector<byte_buffer> seeds;
  for (auto& s : samples())
    seeds.push_back(enc(s.msg));
  std::vector<size_t> decoded(std::variant_size_v<asl_message>, 0);
  byte_buffer in;
  for (size_t i = 0; i < inputs; ++i) {
    if (rng() % 2 == 0) {
      // Noise of random length; usually with a valid version and kind.
      in.resize(rng() % 8 == 0 ? rng() % 600 : rng() % 48);
      for (auto& x : in)
        x = static_cast<uint8_t>(rng());
      if (in.size() >= 2 && rng() % 4 != 0) {
        in[0] = asl_wire_version;
        in[1] = static_cast<uint8_t>(1 + rng() % 14);
      }
    } else {
      in = seeds[rng() % seeds.size()];
      mutate(in, rng);
    }
    auto d = decode_asl(in.data(), in.size());
    auto kind = peek_asl_kind(in.data(), in.size());
    if (!d) {
      ASSERT_TRUE(is(d.error(), ec::invalid_parameter)) << render(d.error());
      continue;
    }
    ++decoded[d->index()];
    ASSERT_TRUE(kind) << hex(in);
    ASSERT_EQ(*kind, kind_of(*d)) << hex(in);
    ASSERT_EQ(enc(*d), in) << hex(in);
  }
  // The mix reached a successful decode of every kind.
  for (size_t k = 0; k < decoded.size(); ++k) {
    SCOPED_TRACE(k + 1);
    EXPECT_GT(decoded[k], 0u);
  }
}
