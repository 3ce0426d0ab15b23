// Specification of the APO payload wire format, version 1
// (docs/protocol.md (APO payloads), "## APO payloads").

#include "actors/marshal.hpp"
#include "channels/thread_cache.hpp"

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <new>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/atom.hpp"
#include "caf/make_message.hpp"
#include "caf/message.hpp"
#include "caf/uniform_type_info_map.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "tests/support/replaced_new.hpp"

// -- a user type: one inspect overload and one type-ID entry -------------------

namespace apo_test {

/// Everything the format encodes, in one user type.
struct sample {
  bool flag = false;
  float ratio = 0;
  double weight = 0;
  std::u16string label16;
  std::u32string label32;
  std::map<std::string, std::vector<int32_t>> series;
  std::vector<std::vector<uint8_t>> blobs;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, sample& x) {
  return f(caf::meta::type_name("apo_test::sample"), x.flag, x.ratio, x.weight,
           x.label16, x.label32, x.series, x.blobs);
}

bool operator==(const sample& x, const sample& y) {
  return x.flag == y.flag && x.ratio == y.ratio && x.weight == y.weight
         && x.label16 == y.label16 && x.label32 == y.label32
         && x.series == y.series && x.blobs == y.blobs;
}

/// Has a type ID but is never registered with the actor system.
struct unregistered {
  int32_t x = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, unregistered& x) {
  return f(caf::meta::type_name("apo_test::unregistered"), x.x);
}

} // namespace apo_test

CAF_BEGIN_TYPE_ID_BLOCK(marshal_test, caf::id_block::herm::end)
  CAF_ADD_TYPE_ID(marshal_test, (apo_test::sample))
CAF_END_TYPE_ID_BLOCK(marshal_test)

CAF_BEGIN_TYPE_ID_BLOCK(marshal_test_unregistered,
                        caf::id_block::marshal_test::end)
  CAF_ADD_TYPE_ID(marshal_test_unregistered, (apo_test::unregistered))
CAF_END_TYPE_ID_BLOCK(marshal_test_unregistered)

// -- allocation probe ----------------------------------------------------------

// Records the largest single allocation while armed, to show that announced
// lengths are checked before anything is allocated for them.
namespace {
std::atomic<bool> probe_armed{false};
std::atomic<size_t> probe_largest{0};
} // namespace

void herm::test::on_allocation(std::size_t n) noexcept {
  if (!probe_armed.load(std::memory_order_relaxed))
    return;
  auto prev = probe_largest.load(std::memory_order_relaxed);
  while (n > prev && !probe_largest.compare_exchange_weak(prev, n)) {
    // retry
  }
}

namespace {

using herm::byte_buffer;

// -- fixture -------------------------------------------------------------------

class marshal_test : public ::testing::Test {
public:
  static void SetUpTestSuite() {
    cfg_ = std::make_unique<caf::actor_system_config>();
    herm::configure(*cfg_);
    cfg_->add_message_types<caf::id_block::marshal_test>();
    sys_ = std::make_unique<caf::actor_system>(*cfg_);
  }

  static void TearDownTestSuite() {
    sys_.reset();
    cfg_.reset();
  }

protected:
  caf::actor_system& sys() {
    return *sys_;
  }

  byte_buffer encode(const caf::message& msg) {
    auto bytes = herm::marshal(sys(), msg);
    EXPECT_TRUE(bytes) << herm::render(bytes.error());
    return bytes ? *bytes : byte_buffer{};
  }

  caf::expected<caf::message> decode(const byte_buffer& bytes,
                                     const herm::unmarshal_limits& limits = {}) {
    return herm::unmarshal(sys(), bytes.data(), bytes.size(), limits);
  }

  /// Encodes, decodes and re-encodes `msg`; returns the decoded message.
  caf::message round_trip(const caf::message& msg) {
    auto bytes = encode(msg);
    auto back = decode(bytes);
    EXPECT_TRUE(back) << herm::render(back.error());
    if (!back)
      return {};
    EXPECT_EQ(encode(*back), bytes);
    EXPECT_EQ(caf::to_string(*back), caf::to_string(msg));
    return *back;
  }

  /// Expects `bytes` to be refused with ec::invalid_parameter and a context
  /// containing `what`.
  void expect_refused(const byte_buffer& bytes, const std::string& what,
                      const herm::unmarshal_limits& limits = {},
                      uint8_t code = static_cast<uint8_t>(herm::ec::invalid_parameter)) {
    auto back = decode(bytes, limits);
    ASSERT_FALSE(back) << "decoded " << caf::to_string(*back);
    EXPECT_TRUE(herm::is_herm_error(back.error(), code))
      << herm::render(back.error());
    EXPECT_NE(herm::render(back.error()).find(what), std::string::npos)
      << herm::render(back.error());
  }

  static std::unique_ptr<caf::actor_system_config> cfg_;
  static std::unique_ptr<caf::actor_system> sys_;
};

std::unique_ptr<caf::actor_system_config> marshal_test::cfg_;
std::unique_ptr<caf::actor_system> marshal_test::sys_;

void append(byte_buffer& buf, const std::string& s) {
  buf.insert(buf.end(), s.begin(), s.end());
}

byte_buffer leb128(uint64_t x) {
  byte_buffer out;
  while (x >= 0x80) {
    out.push_back(static_cast<uint8_t>((x & 0x7f) | 0x80));
    x >>= 7;
  }
  out.push_back(static_cast<uint8_t>(x));
  return out;
}

/// Header of a one-element payload: version, count 1, the type name.
byte_buffer one_element(const std::string& type_name) {
  byte_buffer buf{1, 1};
  auto len = leb128(type_name.size());
  buf.insert(buf.end(), len.begin(), len.end());
  append(buf, type_name);
  return buf;
}

herm::write_packet sample_packet() {
  herm::write_packet x;
  x.dst = 0x0102030405060708;
  x.priority = herm::prio_high;
  x.bytes = {0x00, 0xff, 0x10, 0x00};
  return x;
}

herm::channel_info sample_channel_info() {
  herm::channel_info x;
  x.id = 7;
  x.device = "can0";
  x.kind = "can";
  x.address = "*";
  x.local = "0x12";
  x.profile.name = "can2.0";
  x.profile.bandwidth_bps = 1000000;
  x.profile.mtu = 8;
  x.profile.multi_access = true;
  x.profile.delay_coef = 1.25;
  x.profile.frame_overhead_bits = 47;
  x.max_packet = 4096;
  x.peers = {"0x01", "0x7f", ""};
  return x;
}

// -- round trips ---------------------------------------------------------------

TEST_F(marshal_test, round_trips_integers_of_every_width_at_their_extremes) {
  round_trip(caf::make_message(std::numeric_limits<int8_t>::min(),
                               std::numeric_limits<uint8_t>::max(),
                               std::numeric_limits<int16_t>::min(),
                               std::numeric_limits<uint16_t>::max(),
                               std::numeric_limits<int32_t>::min(),
                               std::numeric_limits<uint32_t>::max(),
                               std::numeric_limits<int64_t>::min(),
                               std::numeric_limits<uint64_t>::max()));
  round_trip(caf::make_message(int8_t{-1}, int16_t{-2}, int32_t{-3},
                               int64_t{-4}, uint8_t{0}, uint16_t{0},
                               uint32_t{0}, uint64_t{0}));
}

TEST_F(marshal_test, writes_integers_little_endian_at_fixed_width) {
  auto bytes = encode(caf::make_message(int16_t{-2}, uint32_t{0x01020304},
                                        int64_t{-0x0102030405060708}));
  byte_buffer expected{1, 3};
  for (auto& part : {byte_buffer{4}, byte_buffer{'@', 'i', '1', '6'},
                     byte_buffer{0xfe, 0xff}, byte_buffer{4},
                     byte_buffer{'@', 'u', '3', '2'},
                     byte_buffer{0x04, 0x03, 0x02, 0x01}, byte_buffer{4},
                     byte_buffer{'@', 'i', '6', '4'},
                     byte_buffer{0xf8, 0xf8, 0xf9, 0xfa, 0xfb, 0xfc, 0xfd,
                                 0xfe}})
    expected.insert(expected.end(), part.begin(), part.end());
  EXPECT_EQ(bytes, expected);
}

TEST_F(marshal_test, writes_floats_as_ieee754_little_endian) {
  auto bytes = encode(caf::make_message(1.5f, -2.0));
  auto expected = byte_buffer{1, 2, 5};
  append(expected, "float");
  for (uint8_t b : {0x00, 0x00, 0xc0, 0x3f})
    expected.push_back(b);
  expected.push_back(6);
  append(expected, "double");
  for (uint8_t b : {0, 0, 0, 0, 0, 0, 0, 0xc0})
    expected.push_back(b);
  EXPECT_EQ(bytes, expected);
  round_trip(caf::make_message(std::numeric_limits<double>::infinity(),
                               std::numeric_limits<float>::denorm_min(),
                               -0.0));
}

TEST_F(marshal_test, round_trips_strings_with_zero_bytes_and_utf8) {
  std::string with_zeros("a\0b\0", 4);
  std::string utf8 = "gr\xc3\xbc\xc3\x9f"
                     "e \xe2\x9c\x93";
  auto back = round_trip(caf::make_message(with_zeros, utf8, std::string{},
                                           std::u16string{u"gr\u00fc\u00dfe"},
                                           std::u32string{U"\U0001D11E"}));
  ASSERT_EQ(back.size(), 5u);
  EXPECT_EQ(back.get_as<std::string>(0), with_zeros);
  EXPECT_EQ(back.get_as<std::string>(1), utf8);
  EXPECT_EQ(back.get_as<std::u16string>(3), u"gr\u00fc\u00dfe");
  EXPECT_EQ(back.get_as<std::u32string>(4), U"\U0001D11E");
}

TEST_F(marshal_test, writes_utf16_and_utf32_little_endian_with_byte_lengths) {
  auto bytes = encode(caf::make_message(std::u16string{u"\u00e9"},
                                        std::u32string{U"\U0001D11E"}));
  auto expected = byte_buffer{1, 2, 7};
  append(expected, "@u16str");
  for (uint8_t b : {2, 0xe9, 0x00, 7})
    expected.push_back(b);
  append(expected, "@u32str");
  for (uint8_t b : {4, 0x1e, 0xd1, 0x01, 0x00})
    expected.push_back(b);
  EXPECT_EQ(bytes, expected);
}

TEST_F(marshal_test, round_trips_vectors_maps_and_sets) {
  herm::device_info dev;
  dev.config.name = "eth0";
  dev.config.kind = "udp";
  dev.config.interface = "0.0.0.0:47000";
  dev.config.options = {{"peers", "10.0.0.2:47000"}, {"profile", "ethernet"}};
  dev.local = "10.0.0.1:47000";
  dev.channels = 2;
  round_trip(caf::make_message(std::vector<herm::device_info>{dev, {}},
                               std::set<std::string>{"b", "a", ""},
                               std::vector<herm::device_info>{}));
}

TEST_F(marshal_test, round_trips_nested_herm_structs) {
  auto back = round_trip(caf::make_message(sample_packet(),
                                           sample_channel_info()));
  ASSERT_TRUE((back.match_elements<herm::write_packet, herm::channel_info>()));
  EXPECT_EQ(back.get_as<herm::write_packet>(0), sample_packet());
  auto info = back.get_as<herm::channel_info>(1);
  EXPECT_EQ(info.profile, sample_channel_info().profile);
  EXPECT_EQ(info.peers, sample_channel_info().peers);
  EXPECT_EQ(info.max_packet, 4096u);
}

TEST_F(marshal_test, round_trips_messages_of_more_values_than_it_keeps_in_place) {
  // Up to four values live in the message data itself, the rest in a
  // vector (marshal.cpp, unmarshalled_data); both halves must round trip,
  // match and copy on write.
  auto back = round_trip(caf::make_message(uint8_t{1}, std::string{"two"},
                                           3.0, int32_t{-4},
                                           std::string{"five"}, true));
  ASSERT_TRUE((back.match_elements<uint8_t, std::string, double, int32_t,
                                   std::string, bool>()));
  EXPECT_EQ(back.get_as<int32_t>(3), -4);
  EXPECT_EQ(back.get_as<std::string>(4), "five");
  auto copy = back;
  copy.get_mutable_as<std::string>(4) = "six";
  copy.get_mutable_as<std::string>(1) = "seven";
  EXPECT_EQ(back.get_as<std::string>(4), "five");
  EXPECT_EQ(back.get_as<std::string>(1), "two");
  EXPECT_EQ(copy.get_as<std::string>(4), "six");
  EXPECT_EQ(copy.get_as<std::string>(1), "seven");
  EXPECT_EQ(copy.type_token(), back.type_token());
  EXPECT_EQ(back.type_token(),
            (caf::make_type_token<uint8_t, std::string, double, int32_t,
                                  std::string, bool>()));
}

// A stream of payloads larger than marshal's first guess of 512 bytes:
// the second takes the buffer the first grew to back from the thread's
// cache and does not grow it. (Before, each started from at most 512 bytes
// and doubled its way to 2 KiB, about four allocations a message.)
TEST_F(marshal_test, a_payload_the_size_of_the_last_takes_a_kept_buffer_that_fits) {
  while (herm::this_thread_buffer_cache().held > 0)
    (void) herm::take_buffer(1, herm::buffer_cache_limits::max_capacity);
  auto msg = caf::make_message(std::string(1400, 'x'));
  auto first = herm::marshal(sys(), msg);
  ASSERT_TRUE(first);
  auto size = first->size();
  auto capacity = first->capacity();
  herm::recycle_buffer(std::move(*first));
  auto before = herm::this_thread_buffer_cache();
  auto second = herm::marshal(sys(), msg);
  ASSERT_TRUE(second);
  EXPECT_EQ(second->size(), size);
  EXPECT_EQ(herm::this_thread_buffer_cache().allocated, before.allocated);
  EXPECT_EQ(herm::this_thread_buffer_cache().reused, before.reused + 1);
  EXPECT_EQ(second->capacity(), capacity) << "the kept buffer grew";
  // A small payload next does not take a large buffer it would keep: at
  // most twice what the last one needed.
  herm::recycle_buffer(std::move(*second));
  auto small = herm::marshal(sys(), caf::make_message(int32_t{7}));
  ASSERT_TRUE(small);
  EXPECT_LE(small->capacity(), std::max<size_t>(512, 2 * size));
}

TEST_F(marshal_test, round_trips_a_user_type_with_only_inspect_and_a_type_id) {
  apo_test::sample x;
  x.flag = true;
  x.ratio = 0.25f;
  x.weight = -1e300;
  x.label16 = u"\u00e9t\u00e9";
  x.label32 = std::u32string(1, U'\U0001F916');
  x.series = {{"a", {1, -1, 0x7fffffff}}, {"b", {}}};
  x.blobs = {{}, {0, 1, 2}};
  auto back = round_trip(caf::make_message(x));
  ASSERT_TRUE(back.match_elements<apo_test::sample>());
  EXPECT_EQ(back.get_as<apo_test::sample>(0), x);
}

TEST_F(marshal_test, encodes_the_empty_message_as_version_and_zero_count) {
  auto bytes = encode(caf::message{});
  EXPECT_EQ(bytes, (byte_buffer{1, 0}));
  auto back = decode(bytes);
  ASSERT_TRUE(back);
  EXPECT_TRUE(back->empty());
}

// -- the golden payload (quoted in docs/protocol.md (APO payloads)) -----------------------

TEST_F(marshal_test, golden_payload_pins_the_format) {
  herm::write_packet pkt;
  pkt.dst = 7;
  pkt.priority = herm::prio_high;
  pkt.bytes = {0xde, 0xad};
  auto bytes = encode(caf::make_message(uint16_t{0x0102}, pkt));
  const byte_buffer golden{
    0x01,                                  // version 1
    0x02,                                  // 2 elements
    0x04, '@', 'u', '1', '6',              // type name "@u16"
    0x02, 0x01,                            // uint16_t 0x0102
    0x12, 'h', 'e', 'r', 'm', ':', ':', 'w', 'r', 'i', 't', 'e',
    '_', 'p', 'a', 'c', 'k', 'e', 't',     // type name "herm::write_packet"
    0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // dst = 7 (uint64_t)
    0x01,                                  // priority = 1 (uint8_t)
    0x02, 0xde, 0xad,                      // bytes: count 2, then the bytes
  };
  EXPECT_EQ(bytes, golden);
  auto back = decode(golden);
  ASSERT_TRUE(back) << herm::render(back.error());
  ASSERT_TRUE((back->match_elements<uint16_t, herm::write_packet>()));
  EXPECT_EQ(back->get_as<uint16_t>(0), 0x0102);
  EXPECT_EQ(back->get_as<herm::write_packet>(1), pkt);
}

// -- refusals ------------------------------------------------------------------

TEST_F(marshal_test, refuses_every_truncation_of_a_valid_payload) {
  auto bytes = encode(caf::make_message(sample_packet(), sample_channel_info(),
                                        std::string{"tail"}));
  for (size_t n = 0; n < bytes.size(); ++n) {
    auto back = herm::unmarshal(sys(), bytes.data(), n);
    EXPECT_FALSE(back) << "prefix of " << n << " bytes decoded";
    if (!back) {
      EXPECT_TRUE(herm::is(back.error(), herm::ec::invalid_parameter));
    }
  }
}

TEST_F(marshal_test, says_which_element_and_value_is_truncated) {
  auto bytes = encode(caf::make_message(int32_t{1}, sample_packet()));
  bytes.resize(bytes.size() - 6); // inside write_packet's byte count + bytes
  auto back = decode(bytes);
  ASSERT_FALSE(back);
  EXPECT_NE(herm::render(back.error())
              .find("element 1 (herm::write_packet): truncated in value"),
            std::string::npos)
    << herm::render(back.error());
}

TEST_F(marshal_test, refuses_trailing_bytes) {
  auto bytes = encode(caf::make_message(sample_packet()));
  bytes.push_back(0);
  expect_refused(bytes, "1 trailing bytes");
}

TEST_F(marshal_test, refuses_an_unknown_type_name) {
  auto bytes = one_element("foo::bar");
  bytes.push_back(0);
  // Its own code: the far end answers "message type unknown here".
  expect_refused(bytes, "element 0: unknown type 'foo::bar'", {},
                 static_cast<uint8_t>(herm::app_ec::unknown_type));
}

TEST_F(marshal_test, refuses_other_versions_and_empty_input) {
  expect_refused({}, "empty payload");
  expect_refused({0, 0}, "unsupported APO format version 0");
  expect_refused({2, 0}, "unsupported APO format version 2");
}

TEST_F(marshal_test, refuses_huge_announced_lengths_without_allocating) {
  std::vector<std::pair<byte_buffer, std::string>> cases;
  // A string announcing 2^62 bytes.
  auto str = one_element("@str");
  auto huge = leb128(uint64_t{1} << 62);
  str.insert(str.end(), huge.begin(), huge.end());
  cases.emplace_back(str, "exceeds the limit of 65536");
  // A byte buffer announcing 2^40 bytes.
  auto pkt = one_element("herm::write_packet");
  pkt.insert(pkt.end(), 9, 0);
  huge = leb128(uint64_t{1} << 40);
  pkt.insert(pkt.end(), huge.begin(), huge.end());
  cases.emplace_back(pkt, "above the limit of 1048576");
  // A byte buffer within the limits but longer than the bytes that follow.
  auto short_pkt = one_element("herm::write_packet");
  short_pkt.insert(short_pkt.end(), 9, 0);
  huge = leb128(1000000);
  short_pkt.insert(short_pkt.end(), huge.begin(), huge.end());
  short_pkt.insert(short_pkt.end(), {1, 2, 3});
  cases.emplace_back(short_pkt, "but only 3 bytes follow");
  // A message announcing 2^63 elements.
  auto many = byte_buffer{1};
  huge = leb128(uint64_t{1} << 63);
  many.insert(many.end(), huge.begin(), huge.end());
  cases.emplace_back(many, "exceeds the limit of 16");
  // A length that does not fit 64 bits.
  auto wide = one_element("@str");
  wide.insert(wide.end(), {0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
                           0xff, 0x7f});
  cases.emplace_back(wide, "exceeds 64 bits");
  // The probe sees allocations (else every bound below held vacuously).
  probe_largest = 0;
  probe_armed = true;
  ::operator delete(::operator new(10000));
  probe_armed = false;
  ASSERT_EQ(probe_largest.load(), 10000u);
  for (auto& [bytes, what] : cases) {
    probe_largest = 0;
    probe_armed = true;
    auto back = decode(bytes);
    probe_armed = false;
    ASSERT_FALSE(back);
    EXPECT_NE(herm::render(back.error()).find(what), std::string::npos)
      << herm::render(back.error());
    EXPECT_LT(probe_largest.load(), 4096u)
      << "allocated " << probe_largest.load() << " bytes for: " << what;
  }
}

TEST_F(marshal_test, enforces_every_limit) {
  auto info = encode(caf::make_message(sample_channel_info()));
  herm::unmarshal_limits small;
  small.max_string = 5;
  expect_refused(info, "string of 6 bytes exceeds the limit of 5", small);
  small = {};
  small.max_sequence = 2;
  expect_refused(info, "announces 3 elements, above the limit of 2", small);
  small = {};
  small.max_total = info.size() - 1;
  expect_refused(info, "exceeds the limit of", small);
  small = {};
  small.max_elements = 2;
  expect_refused(encode(caf::make_message(1, 2, 3)),
                 "message of 3 elements exceeds the limit of 2", small);
  // vector<device_info> holds device_config's option map: two levels.
  auto devs = encode(caf::make_message(
    std::vector<herm::device_info>{herm::device_info{}}));
  small = {};
  small.max_depth = 1;
  expect_refused(devs, "nests deeper than 1 levels", small);
  small.max_depth = 2;
  EXPECT_TRUE(decode(devs, small));
}

TEST_F(marshal_test, refuses_non_canonical_encodings) {
  // A boolean other than 0 or 1.
  auto flag = encode(caf::make_message(true));
  flag.back() = 2;
  expect_refused(flag, "non-canonical encoding");
  // An overlong LEB128 length: 0x80 0x00 for 0.
  auto empty = one_element("@str");
  empty.insert(empty.end(), {0x80, 0x00});
  expect_refused(empty, "not in minimal LEB128 form");
  // A set whose elements are out of order.
  auto set = one_element("@strset");
  set.insert(set.end(), {2, 1, 'b', 1, 'a'});
  expect_refused(set, "non-canonical encoding");
}

TEST_F(marshal_test, refuses_actor_handles_in_both_directions) {
  auto out = herm::marshal(sys(), caf::make_message(herm::channel_actor{}));
  ASSERT_FALSE(out);
  EXPECT_NE(herm::render(out.error()).find("element 0 (herm::channel_actor): "
                                           "holds an actor handle"),
            std::string::npos)
    << herm::render(out.error());
  // An actor ID and an empty node ID, as CAF would have written them.
  auto in = one_element("herm::channel_actor");
  in.insert(in.end(), {1, 0, 0, 0, 0, 0, 0, 0}); // actor ID 1
  auto no_node = static_cast<uint64_t>(caf::atom(""));
  for (int i = 0; i < 8; ++i)
    in.push_back(static_cast<uint8_t>(no_node >> (8 * i)));
  expect_refused(in, "holds an actor handle");
}

TEST_F(marshal_test, refuses_to_encode_a_type_the_system_does_not_know) {
  auto out = herm::marshal(sys(),
                           caf::make_message(int32_t{1},
                                             apo_test::unregistered{}));
  ASSERT_FALSE(out);
  EXPECT_TRUE(herm::is(out.error(), herm::ec::invalid_parameter));
  EXPECT_NE(herm::render(out.error())
              .find("element 1: type '"),
            std::string::npos)
    << herm::render(out.error());
}

TEST_F(marshal_test, refuses_long_double) {
  auto out = herm::marshal(sys(), caf::make_message(static_cast<long double>(1)));
  ASSERT_FALSE(out);
  EXPECT_TRUE(herm::is(out.error(), herm::ec::invalid_parameter));
  EXPECT_NE(herm::render(out.error()).find("long double"), std::string::npos);
  auto in = one_element("@ldouble");
  in.insert(in.end(), 16, 0);
  expect_refused(in, "long double");
}

// -- robustness ----------------------------------------------------------------

/// Anything that decodes must re-encode to exactly the same bytes.
void check_decodes_canonically(caf::actor_system& sys, const byte_buffer& in,
                               size_t& decoded) {
  auto back = herm::unmarshal(sys, in.data(), in.size());
  if (!back) {
    // A mutated type name is an unknown type; anything else is malformed.
    ASSERT_TRUE(herm::is(back.error(), herm::ec::invalid_parameter)
                || herm::is(back.error(), herm::app_ec::unknown_type))
      << herm::render(back.error());
    return;
  }
  ++decoded;
  auto again = herm::marshal(sys, *back);
  ASSERT_TRUE(again);
  ASSERT_EQ(*again, in);
}

TEST_F(marshal_test, random_and_mutated_bytes_never_crash_and_stay_canonical) {
  std::mt19937_64 rng{20240611};
  std::vector<byte_buffer> seeds{
    encode(caf::make_message(sample_packet(), sample_channel_info())),
    encode(caf::make_message(std::set<std::string>{"a", "bc"}, true, 1.5f)),
    encode(caf::make_message(std::u16string{u"xy"}, std::u32string{U"z"},
                             int64_t{-9})),
    encode(caf::make_message(std::vector<herm::device_info>{{}})),
  };
  apo_test::sample s;
  s.series = {{"k", {1, 2}}};
  s.blobs = {{9}};
  seeds.push_back(encode(caf::make_message(s)));
  auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  size_t runs = 0;
  size_t decoded = 0;
  for (; runs < 1000000 && std::chrono::steady_clock::now() < deadline;
       ++runs) {
    byte_buffer in;
    if (runs % 4 == 0) {
      in.resize(rng() % 48);
      for (auto& b : in)
        b = static_cast<uint8_t>(rng());
      if (!in.empty() && rng() % 2 == 0)
        in[0] = 1;
    } else {
      in = seeds[rng() % seeds.size()];
      auto edits = 1 + rng() % 4;
      for (size_t e = 0; e < edits && !in.empty(); ++e) {
        auto at = rng() % in.size();
        switch (rng() % 4) {
          case 0:
            in[at] = static_cast<uint8_t>(rng());
            break;
          case 1:
            in[at] ^= static_cast<uint8_t>(1u << (rng() % 8));
            break;
          case 2:
            in.insert(in.begin() + static_cast<long>(at),
                      static_cast<uint8_t>(rng()));
            break;
          default:
            in.erase(in.begin() + static_cast<long>(at));
        }
      }
    }
    check_decodes_canonically(sys(), in, decoded);
    if (HasFatalFailure())
      return;
  }
  EXPECT_GT(runs, 1000u);
  EXPECT_GT(decoded, 0u); // single-bit flips in values still decode
  RecordProperty("runs", static_cast<int>(runs));
  RecordProperty("decoded", static_cast<int>(decoded));
}

} // namespace

// Found by fuzz_marshal (tests/fuzz/crashes/marshal-duration-unit.bin): a
// caf::duration with a time unit past nanoseconds decoded, and printing it
// (CAF prints every message an actor drops) read past CAF's table of unit
// names: one request could kill a module.
TEST_F(marshal_test, refuses_a_duration_with_an_out_of_range_time_unit) {
  // The fuzzer's input: one @duration whose unit is 0x10000000.
  byte_buffer bad{0x01, 0x01, 0x09, '@', 'd', 'u', 'r', 'a', 't', 'i', 'o',
                  'n', 0x00, 0x00, 0x00, 0x10, 0x01, 0x00, 0x00, 0x00,
                  0x00, 0x00, 0x00, 0x00};
  auto back = herm::unmarshal(sys(), bad.data(), bad.size());
  ASSERT_FALSE(back);
  EXPECT_NE(herm::render(back.error()).find("time unit 268435456 is out of range"),
            std::string::npos)
    << herm::render(back.error());
  // The same bytes with a valid unit (seconds) decode.
  auto good = bad;
  good[12] = 0x02;
  good[15] = 0x00;
  auto ok = herm::unmarshal(sys(), good.data(), good.size());
  ASSERT_TRUE(ok) << herm::render(ok.error());
  EXPECT_EQ(ok->get_as<caf::duration>(0).unit, caf::time_unit::seconds);
}
