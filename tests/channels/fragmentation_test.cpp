// Fragmentation and reassembly: the wire format of docs/protocol.md
// ("Fragment header") byte by byte, the reassembler's promises under loss,
// duplication and reordering, its memory bounds and its clock.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <functional>
#include <new>
#include <numeric>
#include <optional>
#include <ostream>
#include <random>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "channels/fragmentation.hpp"
#include "channels/link_driver.hpp"
#include "tests/support/replaced_new.hpp"

using namespace herm;
using namespace std::chrono_literals;

// -- allocation counting -----------------------------------------------------------

// The whole test binary allocates through these; only the hot-path tests
// turn counting on.
namespace {

bool counting_allocations = false;
size_t allocation_count = 0;

} // namespace

void herm::test::on_allocation(std::size_t) noexcept {
  if (counting_allocations)
    ++allocation_count;
}

namespace herm {

// Readable failure messages for EXPECT_EQ(result, ...).
void PrintTo(reassembler::result r, std::ostream* os) {
  switch (r) {
    case reassembler::result::complete:
      *os << "complete";
      break;
    case reassembler::result::pending:
      *os << "pending";
      break;
    case reassembler::result::dropped:
      *os << "dropped";
      break;
  }
}

} // namespace herm

namespace {

size_t allocations_during(const std::function<void()>& f) {
  allocation_count = 0;
  counting_allocations = true;
  f();
  counting_allocations = false;
  return allocation_count;
}

// -- helpers -----------------------------------------------------------------------

using result = reassembler::result;
using time_point = reassembler::time_point;
using counter = uint64_t reassembly_stats::*;

const time_point t0{std::chrono::seconds{1000}};

const std::pair<const char*, counter> all_counters[] = {
  {"packets", &reassembly_stats::packets},
  {"malformed", &reassembly_stats::malformed},
  {"duplicates", &reassembly_stats::duplicates},
  {"orphans", &reassembly_stats::orphans},
  {"timed_out", &reassembly_stats::timed_out},
  {"over_limit", &reassembly_stats::over_limit},
  {"bad_checksum", &reassembly_stats::bad_checksum},
  {"superseded", &reassembly_stats::superseded},
};

/// Expects `which` (if any) to have gone up by one and every other counter
/// to be unchanged.
void expect_only(const reassembly_stats& before, const reassembly_stats& after,
                 counter which) {
  for (auto& [name, c] : all_counters) {
    SCOPED_TRACE(name);
    EXPECT_EQ(after.*c, before.*c + (c == which ? 1 : 0));
  }
}

/// The sum of the counters that drop something.
uint64_t drops(const reassembly_stats& s) {
  return s.malformed + s.duplicates + s.orphans + s.timed_out + s.over_limit
         + s.bad_checksum + s.superseded;
}

/// Deterministic, non-repeating payload bytes.
byte_buffer pattern(size_t size, uint32_t seed = 1) {
  byte_buffer out(size);
  uint32_t x = seed * 2654435761u + 12345u;
  for (auto& b : out) {
    x = x * 1664525u + 1013904223u;
    b = static_cast<uint8_t>(x >> 24);
  }
  return out;
}

std::vector<byte_buffer> split(fragmenter& f, const byte_buffer& packet) {
  std::vector<byte_buffer> frames;
  f.split(packet.data(), packet.size(), [&](const uint8_t* p, size_t n) {
    frames.emplace_back(p, p + n);
  });
  return frames;
}

/// CRC-32 as docs/protocol.md specifies it, written out bit by bit so the
/// test does not trust zlib to be what the document says.
uint32_t reference_crc32(const byte_buffer& bytes) {
  uint32_t crc = 0xffffffffu;
  for (auto b : bytes) {
    crc ^= b;
    for (int k = 0; k < 8; ++k)
      crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xffffffffu;
}

byte_buffer concat(std::initializer_list<byte_buffer> parts) {
  byte_buffer out;
  for (auto& p : parts)
    out.insert(out.end(), p.begin(), p.end());
  return out;
}

/// payload || CRC-32(payload), little endian: the fragmented stream.
byte_buffer with_crc(const byte_buffer& payload) {
  auto crc = reference_crc32(payload);
  return concat({payload,
                 {static_cast<uint8_t>(crc), static_cast<uint8_t>(crc >> 8),
                  static_cast<uint8_t>(crc >> 16),
                  static_cast<uint8_t>(crc >> 24)}});
}

/// A reassembler and what it delivered.
struct receiver {
  explicit receiver(reassembly_limits limits = {}) : r(limits) {
  }

  result push(const byte_buffer& frame, link_addr src = 1,
              time_point now = t0) {
    byte_buffer out;
    auto res = r.push(src, frame.data(), frame.size(), now, out);
    if (res == result::complete)
      delivered.push_back(std::move(out));
    return res;
  }

  /// Pushes frames[i] for each i in `order`; returns the last result.
  result push(const std::vector<byte_buffer>& frames,
              std::initializer_list<size_t> order, link_addr src = 1) {
    auto res = result::dropped;
    for (auto i : order)
      res = push(frames.at(i), src);
    return res;
  }

  result push_all(const std::vector<byte_buffer>& frames, link_addr src = 1,
                  time_point now = t0) {
    auto res = result::dropped;
    for (auto& f : frames)
      res = push(f, src, now);
    return res;
  }

  reassembler r;
  std::vector<byte_buffer> delivered;
};

} // namespace

// -- the header, frame by frame ------------------------------------------------------

namespace {

struct decode_case {
  const char* name;
  byte_buffer frame;
  result expected;
  counter raises; // the one counter that goes up, or null
  bool holds_memory;
};

byte_buffer bytes(size_t n, uint8_t value = 0x5a) {
  return byte_buffer(n, value);
}

// Every frame is pushed into a fresh reassembler with max_packet = 100.
const decode_case decode_cases[] = {
  {"empty frame", {}, result::dropped, &reassembly_stats::malformed, false},
  {"single", {0x00, 1, 2, 3}, result::complete, &reassembly_stats::packets,
   false},
  {"single carrying an empty packet", {0x00}, result::complete,
   &reassembly_stats::packets, false},
  {"single with tag 3", {0x30, 7}, result::complete, &reassembly_stats::packets,
   false},
  {"single with reserved bit 0 set", {0x01, 7}, result::dropped,
   &reassembly_stats::malformed, false},
  {"single with reserved bit 3 set", {0x08, 7}, result::dropped,
   &reassembly_stats::malformed, false},
  {"single of exactly max_packet", concat({{0x00}, bytes(100)}),
   result::complete, &reassembly_stats::packets, false},
  {"single above max_packet", concat({{0x00}, bytes(101)}), result::dropped,
   &reassembly_stats::malformed, false},
  {"narrow first", {0x40, 10, 1, 2, 3, 4, 5}, result::pending, nullptr, true},
  {"wide first", {0x48, 10, 1, 2, 3, 4, 5}, result::pending, nullptr, true},
  {"first with tag 2", {0x60, 10, 1, 2, 3, 4, 5}, result::pending, nullptr,
   true},
  {"first with reserved bit 0 set", {0x41, 10, 1, 2, 3, 4, 5}, result::dropped,
   &reassembly_stats::malformed, false},
  {"first with reserved bit 2 set", {0x44, 10, 1, 2, 3, 4, 5}, result::dropped,
   &reassembly_stats::malformed, false},
  {"first ending inside its length", {0x40, 0x8a}, result::dropped,
   &reassembly_stats::malformed, false},
  {"first ending inside a two-byte length", {0x40, 0x8a, 0x80}, result::dropped,
   &reassembly_stats::malformed, false},
  {"first with no data after its length", {0x40, 10}, result::dropped,
   &reassembly_stats::malformed, false},
  {"first with a four-byte length", {0x40, 0x80, 0x80, 0x80, 0x00, 1},
   result::dropped, &reassembly_stats::malformed, false},
  {"first announcing max_packet", {0x40, 100, 1, 2, 3, 4, 5}, result::pending,
   nullptr, true},
  {"first announcing max_packet + 1", {0x40, 101, 1, 2, 3, 4, 5},
   result::dropped, &reassembly_stats::malformed, false},
  {"first announcing 2^21 - 1", {0x40, 0xff, 0xff, 0x7f, 1, 2, 3},
   result::dropped, &reassembly_stats::malformed, false},
  {"first carrying more than length + 4 bytes", {0x40, 1, 1, 2, 3, 4, 5, 6},
   result::dropped, &reassembly_stats::malformed, false},
  {"first carrying the whole stream", concat({{0x40, 2}, with_crc({0xab, 0xcd})}),
   result::complete, &reassembly_stats::packets, false},
  {"first carrying the whole stream of an empty packet",
   {0x40, 0, 0, 0, 0, 0}, result::complete, &reassembly_stats::packets, false},
  {"first carrying the whole stream with a bad checksum",
   {0x40, 2, 0xab, 0xcd, 0xd0, 0xc9, 0xff, 0xe8}, result::dropped,
   &reassembly_stats::bad_checksum, false},
  {"first with a padded (non-minimal) length",
   concat({{0x40, 0x82, 0x80, 0x00}, with_crc({0xab, 0xcd})}), result::complete,
   &reassembly_stats::packets, false},
  {"narrow consecutive, header only", {0x81}, result::dropped,
   &reassembly_stats::malformed, false},
  {"wide consecutive, header only", {0xc0, 0x01}, result::dropped,
   &reassembly_stats::malformed, false},
  {"wide consecutive, half a header", {0xc0}, result::dropped,
   &reassembly_stats::malformed, false},
  {"narrow consecutive before any first (stashed)", {0x81, 1, 2, 3},
   result::pending, nullptr, true},
  {"wide consecutive before any first (stashed)", {0xc0, 0x01, 1, 2},
   result::pending, nullptr, true},
};

} // namespace

TEST(fragment_header, decodes_every_header_type_and_drops_each_malformed_variant) {
  for (auto& c : decode_cases) {
    SCOPED_TRACE(c.name);
    reassembly_limits limits;
    limits.max_packet = 100;
    reassembler r{limits};
    byte_buffer out;
    auto res = r.push(1, c.frame.data(), c.frame.size(), t0, out);
    EXPECT_EQ(res, c.expected);
    expect_only(reassembly_stats{}, r.stats(), c.raises);
    EXPECT_EQ(r.memory_in_use() > 0, c.holds_memory);
  }
}

TEST(fragment_header, delivers_the_payload_of_a_single_frame) {
  receiver rx;
  EXPECT_EQ(rx.push({0x20, 'a', 'b', 'c'}), result::complete);
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], (byte_buffer{'a', 'b', 'c'}));
}

TEST(fragment_header, refuses_an_announced_length_above_max_packet_before_allocating) {
  reassembly_limits limits;
  limits.max_packet = 1000;
  receiver rx{limits};
  byte_buffer frame{0x40, 0xe9, 0x07, 1, 2, 3, 4, 5}; // announces 1001 bytes
  auto allocations = allocations_during([&] { rx.push(frame); });
  EXPECT_EQ(rx.r.stats().malformed, 1u);
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
  EXPECT_EQ(rx.r.pending(), 0u);
  EXPECT_EQ(allocations, 0u);
}

namespace {

struct leb_case {
  size_t length;
  byte_buffer encoding;
};

const leb_case leb_cases[] = {
  {0, {0x00}},
  {1, {0x01}},
  {127, {0x7f}},
  {128, {0x80, 0x01}},
  {300, {0xac, 0x02}},
  {16383, {0xff, 0x7f}},
  {16384, {0x80, 0x80, 0x01}},
  {65536, {0x80, 0x80, 0x04}},
  {2097151, {0xff, 0xff, 0x7f}},
};

} // namespace

TEST(fragment_header, encodes_the_length_as_minimal_leb128) {
  for (auto& c : leb_cases) {
    if (c.length < 8)
      continue; // a single frame at MTU 8: no length field
    SCOPED_TRACE(c.length);
    fragmenter f{8};
    auto packet = pattern(c.length);
    byte_buffer first;
    f.split(packet.data(), packet.size(), [&](const uint8_t* p, size_t n) {
      if (first.empty())
        first.assign(p, p + n);
    });
    ASSERT_GT(first.size(), c.encoding.size());
    EXPECT_EQ(byte_buffer(first.begin() + 1,
                          first.begin() + 1
                            + static_cast<ptrdiff_t>(c.encoding.size())),
              c.encoding);
  }
}

TEST(fragment_header, decodes_leb128_lengths_up_to_three_bytes) {
  for (auto& c : leb_cases) {
    SCOPED_TRACE(c.length);
    reassembly_limits limits;
    limits.max_packet = 2097151;
    limits.per_sender = limits.total = 8 * 1024 * 1024;
    receiver rx{limits};
    EXPECT_EQ(rx.push(concat({{0x40}, c.encoding, {0x11}})), result::pending);
    EXPECT_GE(rx.r.memory_in_use(), c.length + 4);
    EXPECT_LT(rx.r.memory_in_use(), c.length + 4 + c.length / 8 + 1024);
  }
}

TEST(fragment_header, the_checksum_is_crc32_ieee_over_the_payload) {
  // The standard check value of CRC-32/ISO-HDLC.
  byte_buffer check{'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  ASSERT_EQ(reference_crc32(check), 0xcbf43926u);
  fragmenter f{8};
  auto frames = split(f, check);
  // 40 09 '1'..'6' | 81 '7' '8' '9' crc0 crc1 crc2 crc3: the stream ends
  // with the CRC, little endian.
  ASSERT_EQ(frames.size(), 2u);
  auto& last = frames.back();
  EXPECT_EQ(byte_buffer(last.end() - 4, last.end()),
            (byte_buffer{0x26, 0x39, 0xf4, 0xcb}));
}

TEST(fragment_header, splits_a_20_byte_packet_at_mtu_8_as_in_the_protocol_document) {
  byte_buffer packet(20);
  std::iota(packet.begin(), packet.end(), uint8_t{0});
  fragmenter f{8};
  std::vector<byte_buffer> expected{
    {0x40, 0x14, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05},
    {0x81, 0x06, 0x07, 0x08, 0x09, 0x0a, 0x0b, 0x0c},
    {0x82, 0x0d, 0x0e, 0x0f, 0x10, 0x11, 0x12, 0x13},
    {0x83, 0xa4, 0xff, 0xdd, 0x3b},
  };
  EXPECT_EQ(split(f, packet), expected);
  EXPECT_EQ(f.frames_for(20), 4u);
}

TEST(fragment_header, numbers_narrow_fragments_mod_16_below_mtu_64) {
  fragmenter f{63};
  auto frames = split(f, pattern(40 * 62));
  ASSERT_GT(frames.size(), 33u);
  EXPECT_EQ(frames[0][0], 0x40); // first, tag 0, W clear
  for (size_t i = 1; i < frames.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(frames[i][0], 0x80 | (i % 16));
  }
}

TEST(fragment_header, numbers_wide_fragments_mod_4096_from_mtu_64) {
  fragmenter f{64};
  auto frames = split(f, pattern(4100 * 62));
  ASSERT_GT(frames.size(), 4097u);
  EXPECT_EQ(frames[0][0], 0x48); // first, tag 0, W set
  for (size_t i = 1; i < frames.size(); ++i) {
    SCOPED_TRACE(i);
    ASSERT_GE(frames[i].size(), 3u);
    EXPECT_EQ(frames[i][0], 0xc0 | ((i % 4096) >> 8));
    EXPECT_EQ(frames[i][1], i % 256);
  }
}

TEST(fragment_header, advances_the_tag_with_every_packet) {
  fragmenter f{8};
  const size_t sizes[] = {3, 100, 0, 7, 8, 5000};
  const uint8_t tags[] = {0, 1, 2, 3, 0, 1};
  for (size_t k = 0; k < std::size(sizes); ++k) {
    SCOPED_TRACE(k);
    for (auto& frame : split(f, pattern(sizes[k])))
      EXPECT_EQ((frame[0] >> 4) & 3, tags[k]);
  }
}

TEST(fragment_header, refuses_packets_the_length_field_cannot_announce) {
  fragmenter f{1500};
  auto huge = pattern(size_t{1} << 21);
  EXPECT_EQ(f.frames_for(huge.size()), 0u);
  EXPECT_TRUE(split(f, huge).empty());
  // 2^21 - 1 is the largest: 1496 stream bytes in the first frame, then
  // 1399 frames of up to 1498.
  EXPECT_EQ(f.frames_for(huge.size() - 1), 1400u);
}

// -- round trips -------------------------------------------------------------------

namespace {

const uint32_t round_trip_mtus[] = {8, 32, 63, 64, 1472, 1500};

/// Splits `size` bytes, checks each frame's size against the sender rules,
/// and reassembles them. Returns false (with failures) on any deviation.
void expect_round_trip(uint32_t mtu, size_t size) {
  fragmenter f{mtu};
  auto packet = pattern(size, static_cast<uint32_t>(size));
  auto frames = split(f, packet);
  ASSERT_EQ(frames.size(), f.frames_for(size));
  if (size < mtu) {
    ASSERT_EQ(frames.size(), 1u);
    EXPECT_EQ(frames[0].size(), size + 1);
    EXPECT_EQ(frames[0][0] >> 6, 0); // single
  } else {
    ASSERT_GE(frames.size(), 2u);
    EXPECT_EQ(frames[0][0] >> 6, 1); // first
    EXPECT_EQ((frames[0][0] & 0x08) != 0, mtu >= 64);
    for (size_t i = 0; i + 1 < frames.size(); ++i)
      EXPECT_EQ(frames[i].size(), mtu) << "frame " << i << " is not full";
    EXPECT_LE(frames.back().size(), mtu);
    EXPECT_GT(frames.back().size(), mtu >= 64 ? 2u : 1u);
  }
  receiver rx;
  for (size_t i = 0; i < frames.size(); ++i)
    EXPECT_EQ(rx.push(frames[i]),
              i + 1 == frames.size() ? result::complete : result::pending);
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], packet);
  EXPECT_EQ(drops(rx.r.stats()), 0u);
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
}

} // namespace

TEST(fragment_round_trip, survives_sizes_around_the_mtu) {
  for (auto mtu : round_trip_mtus) {
    const size_t sizes[] = {0, 1, mtu - 2u, mtu - 1u, mtu, mtu + 1u,
                            2u * mtu, 128, 16384, 65536};
    for (auto size : sizes) {
      SCOPED_TRACE(testing::Message() << "mtu " << mtu << ", size " << size);
      expect_round_trip(mtu, size);
    }
  }
}

TEST(fragment_round_trip, frames_for_matches_split_for_every_size_up_to_three_mtus) {
  // Covers every boundary: single/first, two/three frames, the last frame
  // carrying only CRC bytes, the length field growing from 1 to 2 bytes.
  for (auto mtu : round_trip_mtus) {
    for (size_t size = 0; size <= 3 * mtu + 8; ++size) {
      SCOPED_TRACE(testing::Message() << "mtu " << mtu << ", size " << size);
      expect_round_trip(mtu, size);
      if (testing::Test::HasFailure())
        return;
    }
  }
}

// -- efficiency ----------------------------------------------------------------------

namespace {

double efficiency(size_t payload, size_t frames, uint32_t mtu) {
  return static_cast<double>(payload) / static_cast<double>(frames * mtu);
}

} // namespace

TEST(fragment_efficiency, carries_at_least_87_percent_payload_at_mtu_8_from_2082_bytes) {
  // Per packet: 1 header byte + 2..3 length bytes + 4 CRC bytes + 1 byte per
  // further frame + the unfilled rest of the last frame. From 2000 bytes the
  // worst case is 2004 bytes in 288 frames (86.98 %); from 2082 bytes every
  // size reaches 87 %, tending to 7/8.
  fragmenter f{8};
  double worst_from_2000 = 1;
  for (size_t size = 2000; size <= 70000; ++size) {
    auto e = efficiency(size, f.frames_for(size), 8);
    worst_from_2000 = std::min(worst_from_2000, e);
    if (size >= 2082) {
      ASSERT_GE(e, 0.87) << size;
    }
    ASSERT_LT(e, 0.875) << size;
  }
  EXPECT_DOUBLE_EQ(worst_from_2000, 2004.0 / (288 * 8));
}

TEST(fragment_efficiency, the_frames_split_emits_match_the_computed_efficiency) {
  fragmenter f{8};
  const size_t sizes[] = {2000, 2004, 2082, 4096, 10000, 65536};
  for (auto size : sizes) {
    SCOPED_TRACE(size);
    size_t frames = 0;
    size_t wire = 0;
    auto packet = pattern(size);
    f.split(packet.data(), packet.size(), [&](const uint8_t*, size_t n) {
      ++frames;
      wire += n;
    });
    EXPECT_EQ(frames, f.frames_for(size));
    EXPECT_GE(efficiency(size, frames, 8), 2004.0 / (288 * 8));
    if (size >= 2082) {
      EXPECT_GE(efficiency(size, frames, 8), 0.87);
    }
    EXPECT_GT(wire, (frames - 1) * 8); // all but the last frame full
  }
}

// -- hot path --------------------------------------------------------------------------

TEST(fragment_hot_path, split_allocates_nothing_per_frame_once_warmed_up) {
  fragmenter f{8};
  auto packet = pattern(5000);
  size_t frames = 0;
  std::function<void(const uint8_t*, size_t)> emit
    = [&](const uint8_t*, size_t) { ++frames; };
  f.split(packet.data(), packet.size(), emit);
  EXPECT_EQ(allocations_during(
              [&] { f.split(packet.data(), packet.size(), emit); }),
            0u);
  EXPECT_EQ(frames, 2 * f.frames_for(packet.size()));
}

TEST(fragment_hot_path, reassembly_allocates_one_buffer_per_packet) {
  fragmenter f{8};
  auto a = pattern(3000, 1);
  auto b = pattern(3000, 2);
  auto frames_a = split(f, a);
  auto frames_b = split(f, b);
  reassembler r;
  byte_buffer out;
  for (auto& fr : frames_a)
    r.push(7, fr.data(), fr.size(), t0, out);
  ASSERT_EQ(out, a);
  size_t completed = 0;
  auto n = allocations_during([&] {
    for (auto& fr : frames_b)
      completed += r.push(7, fr.data(), fr.size(), t0, out) == result::complete;
  });
  EXPECT_EQ(completed, 1u);
  EXPECT_EQ(out, b);
  EXPECT_EQ(n, 1u);
}

// -- reassembly --------------------------------------------------------------------------

namespace {

/// Frames of one packet of `size` bytes at `mtu` (tag 0).
std::vector<byte_buffer> frames_of(uint32_t mtu, const byte_buffer& packet) {
  fragmenter f{mtu};
  return split(f, packet);
}

} // namespace

TEST(reassembly, ignores_a_duplicate_consecutive_fragment_inside_the_window) {
  auto packet = pattern(40);
  auto frames = frames_of(8, packet); // 7 frames
  receiver rx;
  rx.push(frames, {0, 2, 3}); // index 1 is the lowest missing
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push(frames[2]), result::dropped);
  expect_only(before, rx.r.stats(), &reassembly_stats::duplicates);
  rx.push(frames, {1, 4, 5, 6});
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], packet);
}

TEST(reassembly, recognises_a_late_duplicate_below_the_window_by_its_bytes) {
  // The window starts at the lowest missing index, so a copy of frame 3
  // arriving after frames 0..5 maps to index 19 (== 3 mod 16). Its bytes
  // equal frame 3's, which is already in place: a duplicate, not frame 19.
  auto packet = pattern(300);
  auto frames = frames_of(8, packet); // 44 frames
  receiver rx;
  rx.push(frames, {0, 1, 2, 3, 4, 5});
  EXPECT_EQ(rx.push(frames[3]), result::dropped);
  for (size_t i = 6; i < frames.size(); ++i)
    rx.push(frames[i]);
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], packet);
  rx.r.expire(t0 + 1h);
  reassembly_stats expected;
  expected.packets = 1;
  expected.duplicates = 1;
  for (auto& [name, c] : all_counters) {
    SCOPED_TRACE(name);
    EXPECT_EQ(rx.r.stats().*c, expected.*c);
  }
}

TEST(reassembly, misplaces_a_frame_reordered_beyond_the_window_and_drops_the_packet) {
  // Frame 20 arriving right after frames 0..3 maps to index 4 (== 20 mod 16)
  // where it does not fit the packet's bytes; the CRC rejects the result:
  // lost, never corrupted. The price of 4-bit sequence numbers.
  auto packet = pattern(300);
  auto frames = frames_of(8, packet);
  receiver rx;
  rx.push(frames, {0, 1, 2, 3, 20});
  for (size_t i = 4; i < frames.size(); ++i)
    if (i != 20)
      rx.push(frames[i]);
  EXPECT_TRUE(rx.delivered.empty());
  rx.r.expire(t0 + 1h);
  EXPECT_EQ(rx.r.stats().packets, 0u);
  EXPECT_EQ(rx.r.stats().bad_checksum + rx.r.stats().timed_out, 1u);
}

TEST(reassembly, ignores_a_late_duplicate_that_maps_beyond_the_last_frame) {
  auto packet = pattern(40);
  auto frames = frames_of(8, packet); // 7 frames: index 17 does not exist
  receiver rx;
  rx.push(frames, {0, 1, 2});
  EXPECT_EQ(rx.push(frames[1]), result::dropped);
  rx.push(frames, {3, 4, 5, 6});
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], packet);
  rx.r.expire(t0 + 1h);
  reassembly_stats expected;
  expected.packets = 1;
  expected.duplicates = 1;
  for (auto& [name, c] : all_counters) {
    SCOPED_TRACE(name);
    EXPECT_EQ(rx.r.stats().*c, expected.*c);
  }
}

TEST(reassembly, ignores_a_duplicate_first_fragment_of_the_same_packet) {
  auto packet = pattern(40);
  auto frames = frames_of(8, packet);
  receiver rx;
  rx.push(frames, {0, 1});
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push(frames[0]), result::dropped);
  expect_only(before, rx.r.stats(), &reassembly_stats::duplicates);
  rx.push(frames, {2, 3, 4, 5, 6});
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], packet);
}

namespace {

struct order_case {
  const char* name;
  uint32_t mtu;
  size_t size;
  std::vector<size_t> order; // frame indices in arrival order
};

std::vector<size_t> reversed_after_first(size_t frames) {
  std::vector<size_t> order{0};
  for (size_t i = frames - 1; i > 0; --i)
    order.push_back(i);
  return order;
}

std::vector<size_t> first_last(size_t frames) {
  std::vector<size_t> order;
  for (size_t i = 1; i < frames; ++i)
    order.push_back(i);
  order.push_back(0);
  return order;
}

const order_case in_window_orders[] = {
  // 16 frames: 1..15 all within [1, 17).
  {"narrow, consecutive fragments reversed", 8, 105, reversed_after_first(16)},
  {"narrow, every consecutive fragment before the first", 8, 105,
   first_last(16)},
  {"narrow, pairs swapped", 8, 200, {1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10, 13,
                                     12, 15, 14, 17, 16, 19, 18, 21, 20, 23, 22,
                                     25, 24, 27, 26, 29, 28}},
  {"narrow, a fragment 15 ahead of the lowest missing", 8, 200,
   {0, 16, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 17, 18, 19, 20,
    21, 22, 23, 24, 25, 26, 27, 28, 29}},
  {"wide, 300 consecutive fragments reversed", 64, 300 * 62,
   reversed_after_first(301)},
  {"wide, every consecutive fragment before the first", 64, 300 * 62,
   first_last(301)},
};

} // namespace

TEST(reassembly, reassembles_fragments_reordered_within_the_window) {
  for (auto& c : in_window_orders) {
    SCOPED_TRACE(c.name);
    auto packet = pattern(c.size);
    auto frames = frames_of(c.mtu, packet);
    ASSERT_EQ(frames.size(), c.order.size());
    receiver rx;
    for (auto i : c.order)
      rx.push(frames[i]);
    ASSERT_EQ(rx.delivered.size(), 1u);
    EXPECT_EQ(rx.delivered[0], packet);
    EXPECT_EQ(drops(rx.r.stats()), 0u);
    EXPECT_EQ(rx.r.memory_in_use(), 0u);
    EXPECT_EQ(rx.r.pending(), 0u);
  }
}

TEST(reassembly, drops_a_packet_whose_fragment_was_reordered_beyond_the_window) {
  auto packet = pattern(300);
  auto frames = frames_of(8, packet); // 44 frames, narrow
  receiver rx;
  // Frame 18 (seq 2) arrives while index 2 is the lowest missing: it lands
  // in slot 2. Frame 2 then lands in slot 18. The CRC notices.
  rx.push(frames, {0, 1});
  for (size_t i = 3; i <= 16; ++i)
    rx.push(frames[i]);
  EXPECT_EQ(rx.push(frames[18]), result::pending);
  EXPECT_EQ(rx.push(frames[2]), result::pending);
  auto before = rx.r.stats();
  rx.push(frames[17]);
  for (size_t i = 19; i < frames.size(); ++i)
    rx.push(frames[i]);
  expect_only(before, rx.r.stats(), &reassembly_stats::bad_checksum);
  EXPECT_TRUE(rx.delivered.empty());
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
}

TEST(reassembly, drops_a_packet_with_a_flipped_byte_in_a_middle_fragment) {
  const uint32_t mtus[] = {8, 1500};
  for (auto mtu : mtus) {
    SCOPED_TRACE(mtu);
    auto packet = pattern(5000);
    auto frames = frames_of(mtu, packet);
    frames[frames.size() / 2].back() ^= 0x10;
    receiver rx;
    EXPECT_EQ(rx.push_all(frames), result::dropped);
    EXPECT_TRUE(rx.delivered.empty());
    expect_only(reassembly_stats{}, rx.r.stats(), &reassembly_stats::bad_checksum);
    EXPECT_EQ(rx.r.memory_in_use(), 0u);
  }
}

TEST(reassembly, reassembles_interleaved_fragments_from_two_senders) {
  // Both senders use tag 0 for their first packet: only the address tells
  // the packets apart.
  auto a = pattern(500, 1);
  auto b = pattern(300, 2);
  auto frames_a = frames_of(8, a);
  auto frames_b = frames_of(8, b);
  receiver rx;
  for (size_t i = 0; i < std::max(frames_a.size(), frames_b.size()); ++i) {
    if (i < frames_b.size())
      rx.push(frames_b[i], 20);
    if (i < frames_a.size())
      rx.push(frames_a[i], 10);
  }
  ASSERT_EQ(rx.delivered.size(), 2u);
  EXPECT_EQ(rx.delivered[0], b);
  EXPECT_EQ(rx.delivered[1], a);
  EXPECT_EQ(drops(rx.r.stats()), 0u);
}

TEST(reassembly, reassembles_interleaved_packets_from_several_senders_on_one_bus) {
  std::mt19937_64 rng{42};
  const size_t senders = 5;
  std::vector<fragmenter> tx(senders, fragmenter{8});
  std::vector<std::vector<byte_buffer>> sent(senders);
  std::vector<std::vector<byte_buffer>> queues(senders);
  for (size_t s = 0; s < senders; ++s) {
    for (int k = 0; k < 20; ++k) {
      sent[s].push_back(pattern(rng() % 600, static_cast<uint32_t>(rng())));
      for (auto& fr : split(tx[s], sent[s].back()))
        queues[s].push_back(fr);
    }
  }
  reassembler r;
  std::vector<size_t> next(senders, 0);
  std::vector<std::vector<byte_buffer>> got(senders);
  for (;;) {
    std::vector<size_t> busy;
    for (size_t s = 0; s < senders; ++s)
      if (next[s] < queues[s].size())
        busy.push_back(s);
    if (busy.empty())
      break;
    auto s = busy[rng() % busy.size()];
    auto& fr = queues[s][next[s]++];
    byte_buffer out;
    if (r.push(100 + s, fr.data(), fr.size(), t0, out) == result::complete)
      got[s].push_back(out);
  }
  EXPECT_EQ(got, sent);
  EXPECT_EQ(drops(r.stats()), 0u);
}

TEST(reassembly, supersedes_an_incomplete_packet_when_its_tag_comes_round_again) {
  fragmenter f{8};
  std::vector<byte_buffer> packets;
  std::vector<std::vector<byte_buffer>> frames;
  for (uint32_t k = 0; k < 5; ++k) {
    packets.push_back(pattern(60, k));
    frames.push_back(split(f, packets.back()));
  }
  receiver rx;
  rx.push(frames[0], {0, 1, 2}); // tag 0, never finished
  for (int k = 1; k <= 3; ++k)
    rx.push_all(frames[k]);
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push(frames[4][0]), result::pending); // tag 0 again
  expect_only(before, rx.r.stats(), &reassembly_stats::superseded);
  rx.push_all(std::vector<byte_buffer>(frames[4].begin() + 1, frames[4].end()));
  EXPECT_EQ(rx.delivered, std::vector<byte_buffer>(packets.begin() + 1,
                                                   packets.end()));
  EXPECT_EQ(rx.r.pending(), 0u);
}

TEST(reassembly, a_single_frame_leaves_an_incomplete_packet_with_its_tag_alone) {
  auto packet = pattern(60);
  auto frames = frames_of(8, packet);
  receiver rx;
  rx.push(frames, {0, 1});
  EXPECT_EQ(rx.push({0x00, 'x'}), result::complete); // tag 0 too
  rx.push_all(std::vector<byte_buffer>(frames.begin() + 2, frames.end()));
  ASSERT_EQ(rx.delivered.size(), 2u);
  EXPECT_EQ(rx.delivered[1], packet);
}

TEST(reassembly, drops_a_consecutive_fragment_whose_width_differs_from_its_first) {
  auto frames = frames_of(8, pattern(40)); // narrow
  receiver rx;
  rx.push(frames[0]);
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push({0xc0, 0x01, 1, 2, 3, 4, 5, 6}), result::dropped);
  expect_only(before, rx.r.stats(), &reassembly_stats::malformed);
}

TEST(reassembly, counts_a_consecutive_fragment_without_its_first_as_orphan_when_it_expires) {
  auto frames = frames_of(8, pattern(40));
  receiver rx;
  EXPECT_EQ(rx.push(frames[3]), result::pending);
  EXPECT_GT(rx.r.memory_in_use(), 0u);
  EXPECT_EQ(rx.r.pending(), 0u); // a stashed fragment is not a packet
  auto deadline = rx.r.next_deadline();
  ASSERT_TRUE(deadline);
  EXPECT_EQ(rx.r.expire(*deadline), 0u); // no packet expired...
  expect_only(reassembly_stats{}, rx.r.stats(), &reassembly_stats::orphans);
  EXPECT_EQ(rx.r.memory_in_use(), 0u); // ...but the fragment is gone
  EXPECT_FALSE(rx.r.next_deadline());
}

TEST(reassembly, holds_a_fragment_that_does_not_fit_its_packet_as_an_orphan) {
  auto frames = frames_of(8, pattern(40)); // 7 frames, the last one short
  receiver rx;
  rx.push(frames[0]);
  auto short_middle = frames[2];
  short_middle.pop_back();
  const byte_buffer misfits[] = {
    short_middle,          // wrong size for index 2
    {0x88, 1, 2, 3, 4, 5, 6, 7}, // index 8 > last index 6
  };
  for (auto& m : misfits)
    EXPECT_EQ(rx.push(m), result::pending);
  rx.r.expire(t0 + 1h);
  EXPECT_EQ(rx.r.stats().orphans, 2u);
  EXPECT_EQ(rx.r.stats().timed_out, 1u);
}

TEST(reassembly, counts_a_repeated_stashed_fragment_as_duplicate) {
  auto frames = frames_of(8, pattern(40));
  receiver rx;
  rx.push(frames[2]);
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push(frames[2]), result::dropped);
  expect_only(before, rx.r.stats(), &reassembly_stats::duplicates);
  rx.push(frames, {0, 1, 3, 4, 5, 6});
  EXPECT_EQ(rx.delivered.size(), 1u);
}

// -- time --------------------------------------------------------------------------------

TEST(reassembly_time, expires_an_incomplete_packet_once_it_is_older_than_the_timeout) {
  reassembly_limits limits;
  limits.timeout = 500ms;
  receiver rx{limits};
  auto frames = frames_of(8, pattern(40));
  EXPECT_FALSE(rx.r.next_deadline());
  rx.push(frames[0], 1, t0);
  auto deadline = rx.r.next_deadline();
  ASSERT_TRUE(deadline);
  // "Older than the timeout": started before now - timeout.
  EXPECT_EQ(*deadline, t0 + 500ms + time_point::duration{1});
  EXPECT_EQ(rx.r.expire(t0 + 500ms), 0u);
  EXPECT_EQ(rx.r.pending(), 1u);
  EXPECT_EQ(rx.r.expire(*deadline), 1u);
  expect_only(reassembly_stats{}, rx.r.stats(), &reassembly_stats::timed_out);
  EXPECT_EQ(rx.r.pending(), 0u);
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
  EXPECT_FALSE(rx.r.next_deadline());
  // The rest of the packet now has no first fragment.
  rx.push(frames[1], 1, *deadline);
  rx.r.expire(*deadline + 1s);
  EXPECT_EQ(rx.r.stats().orphans, 1u);
}

TEST(reassembly_time, next_deadline_is_the_earliest_of_packets_and_stashed_fragments) {
  reassembly_limits limits;
  limits.timeout = 100ms;
  receiver rx{limits};
  auto a = frames_of(8, pattern(40, 1));
  auto b = frames_of(8, pattern(40, 2));
  rx.push(a[0], 1, t0 + 30ms);
  rx.push(b[1], 2, t0 + 10ms); // stashed
  rx.push(b[0], 3, t0 + 20ms);
  auto tick = time_point::duration{1};
  EXPECT_EQ(rx.r.next_deadline(), t0 + 110ms + tick);
  EXPECT_EQ(rx.r.expire(t0 + 110ms + tick), 0u); // the stashed fragment
  EXPECT_EQ(rx.r.next_deadline(), t0 + 120ms + tick);
  EXPECT_EQ(rx.r.expire(t0 + 125ms), 1u);
  EXPECT_EQ(rx.r.next_deadline(), t0 + 130ms + tick);
  EXPECT_EQ(rx.r.expire(t0 + 1s), 1u);
  EXPECT_EQ(rx.r.stats().timed_out, 2u);
  EXPECT_EQ(rx.r.stats().orphans, 1u);
}

TEST(reassembly_time, survives_extreme_clock_values) {
  reassembly_limits limits;
  limits.timeout = std::chrono::milliseconds::max();
  receiver rx{limits};
  auto frames = frames_of(8, pattern(40));
  rx.push(frames[0], 1, time_point::max() - 1s);
  EXPECT_EQ(rx.r.next_deadline(), time_point::max());
  EXPECT_EQ(rx.r.expire(time_point::max() - 1ns), 0u);
  EXPECT_EQ(rx.r.expire(time_point::max()), 1u);
}

// -- memory --------------------------------------------------------------------------------

TEST(reassembly_memory, holds_what_a_packet_needs_and_releases_it_on_completion) {
  auto packet = pattern(10000);
  auto frames = frames_of(32, packet);
  receiver rx;
  rx.push(frames[0]);
  EXPECT_GE(rx.r.memory_in_use(), 10004u);
  EXPECT_LE(rx.r.memory_in_use(), 10004u + 2048u);
  EXPECT_EQ(rx.r.pending(), 1u);
  rx.push_all(std::vector<byte_buffer>(frames.begin() + 1, frames.end()));
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
  EXPECT_EQ(rx.r.pending(), 0u);
}

TEST(reassembly_memory, refuses_a_packet_larger_than_the_per_sender_bound) {
  reassembly_limits limits;
  limits.per_sender = 4000;
  receiver rx{limits};
  auto frames = frames_of(32, pattern(5000));
  size_t allocations
    = allocations_during([&] { EXPECT_EQ(rx.push(frames[0]), result::dropped); });
  expect_only(reassembly_stats{}, rx.r.stats(), &reassembly_stats::over_limit);
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
  EXPECT_EQ(allocations, 0u);
  // A smaller packet from the same sender still fits.
  auto small = pattern(2000);
  rx.push_all(frames_of(32, small));
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], small);
}

TEST(reassembly_memory, evicts_a_senders_older_packet_to_make_room_for_its_newest) {
  reassembly_limits limits;
  limits.per_sender = 5000;
  receiver rx{limits};
  fragmenter f{32};
  auto old_packet = split(f, pattern(3000, 1));
  auto new_packet = pattern(3000, 2);
  auto new_frames = split(f, new_packet);
  rx.push(old_packet, {0, 1, 2}, 1);
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push(new_frames[0]), result::pending);
  expect_only(before, rx.r.stats(), &reassembly_stats::over_limit);
  EXPECT_EQ(rx.r.pending(), 1u);
  EXPECT_LE(rx.r.memory_in_use(), limits.per_sender);
  rx.push_all(std::vector<byte_buffer>(new_frames.begin() + 1, new_frames.end()));
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], new_packet);
}

TEST(reassembly_memory, refuses_a_packet_beyond_the_total_bound_without_evicting_other_senders) {
  reassembly_limits limits;
  limits.total = 5000;
  receiver rx{limits};
  auto a = pattern(3000, 1);
  auto frames_a = frames_of(32, a);
  auto frames_b = frames_of(32, pattern(3000, 2));
  rx.push(frames_a[0], 1);
  auto held = rx.r.memory_in_use();
  auto before = rx.r.stats();
  EXPECT_EQ(rx.push(frames_b[0], 2), result::dropped);
  expect_only(before, rx.r.stats(), &reassembly_stats::over_limit);
  EXPECT_EQ(rx.r.memory_in_use(), held);
  rx.push_all(std::vector<byte_buffer>(frames_a.begin() + 1, frames_a.end()), 1);
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], a);
}

TEST(reassembly_memory, bounds_stashed_fragments_and_evicts_the_oldest_first) {
  reassembly_limits limits;
  limits.per_sender = 2000;
  limits.total = 3000;
  receiver rx{limits};
  // Wide consecutive fragments of 62 bytes, all different, never claimed:
  // from two senders, so that both bounds come into play.
  for (int k = 0; k < 500; ++k) {
    byte_buffer fr{static_cast<uint8_t>(0xc0 | (k >> 8 & 0x0f)),
                   static_cast<uint8_t>(k)};
    auto body = pattern(62, static_cast<uint32_t>(k));
    fr.insert(fr.end(), body.begin(), body.end());
    EXPECT_EQ(rx.push(fr, 1 + k % 2), result::pending);
    ASSERT_LE(rx.r.memory_in_use(), limits.total);
  }
  auto stashed_before = rx.r.stats().orphans;
  EXPECT_GT(stashed_before, 400u); // most were evicted, each counted once
  rx.r.expire(t0 + 1h);
  EXPECT_EQ(rx.r.stats().orphans, 500u);
  EXPECT_EQ(rx.r.memory_in_use(), 0u);
}

TEST(reassembly_memory, a_new_packet_displaces_stashed_fragments) {
  reassembly_limits limits;
  limits.per_sender = 4000;
  receiver rx{limits};
  for (int k = 1; k <= 30; ++k)
    rx.push({static_cast<uint8_t>(0x90 | (k % 16)), 1, 2, 3, 4, 5, 6, 7,
             static_cast<uint8_t>(k)});
  auto packet = pattern(3000);
  rx.push_all(frames_of(32, packet));
  ASSERT_EQ(rx.delivered.size(), 1u);
  EXPECT_EQ(rx.delivered[0], packet);
}

TEST(reassembly, is_movable) {
  auto packet = pattern(100);
  auto frames = frames_of(8, packet);
  receiver rx;
  rx.push(frames, {0, 1, 2});
  reassembler moved{std::move(rx.r)};
  byte_buffer out;
  for (size_t i = 3; i < frames.size(); ++i)
    moved.push(1, frames[i].data(), frames[i].size(), t0, out);
  EXPECT_EQ(out, packet);
  reassembler assigned;
  assigned = std::move(moved);
  EXPECT_EQ(assigned.stats().packets, 1u);
}

// -- arbitrary bytes ---------------------------------------------------------------------------

TEST(reassembly_robustness, stays_within_its_bounds_whatever_bytes_arrive) {
  // Garbage of every header type mixed into real traffic from the same
  // three addresses, with tight limits, so that garbage meets packets in
  // every state. Run under ASan/UBSan (HERM_SANITIZE) this is a small fuzz.
  std::mt19937_64 rng{2024};
  reassembly_limits limits;
  limits.max_packet = 3000;
  limits.per_sender = 5000;
  limits.total = 9000;
  limits.timeout = 20ms;
  reassembler r{limits};
  std::vector<fragmenter> tx{fragmenter{8}, fragmenter{32}, fragmenter{64}};
  std::vector<std::vector<byte_buffer>> queued(tx.size());
  uint64_t opened = 0;
  uint64_t refused = 0;
  auto now = t0;
  byte_buffer out;
  byte_buffer frame;
  for (int i = 0; i < 200'000; ++i) {
    auto src = static_cast<size_t>(rng() % tx.size());
    if (rng() % 2 == 0) {
      if (queued[src].empty())
        queued[src] = split(tx[src], pattern(rng() % 4000, static_cast<uint32_t>(i)));
      frame = std::move(queued[src].front());
      queued[src].erase(queued[src].begin());
    } else {
      frame.resize(rng() % 70);
      for (auto& b : frame)
        b = static_cast<uint8_t>(rng());
      if (!frame.empty() && rng() % 2 == 0) // plausible headers, more often
        frame[0] &= static_cast<uint8_t>(0xf0 | (rng() % 2 == 0 ? 0x0f : 0x08));
    }
    now += 10us;
    auto before = r.stats();
    auto res = r.push(src, frame.data(), frame.size(), now, out);
    auto& after = r.stats();
    if (!frame.empty() && frame[0] >> 6 <= 1) {
      if (res != result::dropped || after.bad_checksum > before.bad_checksum)
        ++opened;
      else if (after.over_limit > before.over_limit)
        ++refused;
    }
    ASSERT_LE(r.memory_in_use(), limits.total);
    ASSERT_LE(r.pending(), 4 * tx.size());
    if (i % 500 == 0)
      r.expire(now);
  }
  r.expire(now + 1h);
  auto& s = r.stats();
  EXPECT_EQ(opened + refused, s.packets + s.timed_out + s.superseded
                                + s.bad_checksum + s.over_limit);
  EXPECT_EQ(r.memory_in_use(), 0u);
  EXPECT_FALSE(r.next_deadline());
  // The mix did reach every outcome.
  for (auto& [name, c] : all_counters) {
    SCOPED_TRACE(name);
    EXPECT_GT(s.*c, 0u);
  }
}

// -- random traffic -----------------------------------------------------------------------------

namespace {

struct impairment {
  double loss = 0;        // probability a frame (or a copy) is lost
  double duplication = 0; // probability a frame arrives twice
  bool reorder = false;   // frames overtake each other, within the window
};

struct traffic_case {
  std::string name;
  uint32_t mtu;
  size_t senders;
  size_t packets; // over all senders
  impairment imp;
  uint64_t seed;
};

struct bus_frame {
  size_t sender;
  size_t offset; // into traffic::pool
  uint32_t size;
};

/// What went onto the bus and in which order it arrives.
struct traffic {
  std::vector<std::vector<byte_buffer>> sent; // per sender
  byte_buffer pool;
  std::vector<bus_frame> arrivals;
};

/// Sizes spread evenly over orders of magnitude from 0 to 65536 bytes, so
/// that single frames, short and very long packets all occur.
size_t random_size(std::mt19937_64& rng) {
  auto magnitude = rng() % 17;
  return static_cast<size_t>(rng() % ((uint64_t{1} << magnitude) + 1));
}

traffic make_traffic(const traffic_case& c) {
  std::mt19937_64 rng{c.seed};
  std::uniform_real_distribution<double> uniform{0.0, 1.0};
  traffic t;
  t.sent.resize(c.senders);
  std::vector<fragmenter> tx(c.senders, fragmenter{c.mtu});
  // Per sender: its frames in order, each with the index of its packet.
  struct sent_frame {
    bus_frame frame;
    size_t packet;
  };
  std::vector<std::vector<sent_frame>> queues(c.senders);
  for (size_t k = 0; k < c.packets; ++k) {
    auto s = k % c.senders;
    byte_buffer packet(random_size(rng));
    for (auto& b : packet)
      b = static_cast<uint8_t>(rng());
    tx[s].split(packet.data(), packet.size(), [&](const uint8_t* p, size_t n) {
      queues[s].push_back({{s, t.pool.size(), static_cast<uint32_t>(n)},
                           t.sent[s].size()});
      t.pool.insert(t.pool.end(), p, p + n);
    });
    t.sent[s].push_back(std::move(packet));
  }
  // The bus interleaves the senders frame by frame at random.
  std::vector<sent_frame> bus;
  std::vector<size_t> next(c.senders, 0);
  for (;;) {
    size_t left = 0;
    for (size_t s = 0; s < c.senders; ++s)
      left += queues[s].size() - next[s];
    if (left == 0)
      break;
    auto pick = rng() % left;
    for (size_t s = 0; s < c.senders; ++s) {
      auto rest = queues[s].size() - next[s];
      if (pick < rest) {
        bus.push_back(queues[s][next[s]++]);
        break;
      }
      pick -= rest;
    }
  }
  // Each frame gets an arrival key. Reordering adds up to 7 positions of
  // jitter, which displaces any frame by at most 6 positions among its
  // sender's frames: inside the 16-frame window. A packet's frames never
  // overtake the frames of the packet sent 4 earlier (same tag), which the
  // 2-bit tag could not tell apart.
  struct keyed {
    double key;
    size_t index;
  };
  std::vector<keyed> keys;
  std::vector<std::unordered_map<size_t, double>> latest(c.senders);
  for (size_t p = 0; p < bus.size(); ++p) {
    auto& f = bus[p];
    auto key = static_cast<double>(p);
    if (c.imp.reorder) {
      key += 6.999 * uniform(rng);
      auto& seen = latest[f.frame.sender];
      if (f.packet >= 4) {
        auto same_tag = seen.find(f.packet - 4);
        if (same_tag != seen.end())
          key = std::max(key, same_tag->second + 1e-6);
      }
      auto& mine = seen[f.packet];
      mine = std::max(mine, key);
    }
    if (uniform(rng) >= c.imp.loss)
      keys.push_back({key, p});
    if (uniform(rng) < c.imp.duplication && uniform(rng) >= c.imp.loss)
      keys.push_back({key + 1e-3 + 7.0 * uniform(rng), p});
  }
  std::stable_sort(keys.begin(), keys.end(),
                   [](const keyed& x, const keyed& y) { return x.key < y.key; });
  for (auto& k : keys)
    t.arrivals.push_back(bus[k.index].frame);
  return t;
}

void PrintTo(const traffic_case& c, std::ostream* os) {
  *os << c.name << " (seed " << c.seed << ")";
}

class random_traffic : public testing::TestWithParam<traffic_case> {};

} // namespace

TEST_P(random_traffic, delivers_only_sent_packets_and_accounts_for_every_other) {
  auto& c = GetParam();
  auto t = make_traffic(c);
  reassembly_limits limits;
  reassembler r{limits};
  // Every sent packet, findable by content. Packets with equal content
  // (there are many empty ones) share the id of the first of them.
  std::vector<std::unordered_multimap<size_t, size_t>> index(c.senders);
  std::vector<std::vector<size_t>> ids(c.senders);
  auto hash_of = [](const byte_buffer& b) {
    return std::hash<std::string_view>{}(
      std::string_view{reinterpret_cast<const char*>(b.data()), b.size()});
  };
  auto find = [&](size_t sender, const byte_buffer& b) -> std::optional<size_t> {
    auto range = index[sender].equal_range(hash_of(b));
    for (auto i = range.first; i != range.second; ++i)
      if (t.sent[sender][i->second] == b)
        return i->second;
    return std::nullopt;
  };
  for (size_t s = 0; s < c.senders; ++s) {
    for (size_t k = 0; k < t.sent[s].size(); ++k) {
      auto known = find(s, t.sent[s][k]);
      ids[s].push_back(known ? *known : k);
      if (!known)
        index[s].emplace(hash_of(t.sent[s][k]), k);
    }
  }
  std::vector<std::vector<size_t>> delivered(c.senders);
  // Packets the reassembler took on (a single, or a first fragment it
  // accepted) and first fragments it refused for memory.
  uint64_t opened = 0;
  uint64_t refused = 0;
  size_t corrupted = 0;
  auto now = t0;
  byte_buffer out;
  for (size_t i = 0; i < t.arrivals.size(); ++i) {
    auto& f = t.arrivals[i];
    const uint8_t* bytes = t.pool.data() + f.offset;
    now += 20us;
    auto before = r.stats();
    auto res = r.push(100 + f.sender, bytes, f.size, now, out);
    auto& after = r.stats();
    if (bytes[0] >> 6 <= 1) {
      if (res != result::dropped || after.bad_checksum > before.bad_checksum)
        ++opened;
      else if (after.over_limit > before.over_limit)
        ++refused;
    }
    if (res == result::complete) {
      if (auto id = find(f.sender, out))
        delivered[f.sender].push_back(*id);
      else
        ++corrupted;
    }
    ASSERT_LE(r.memory_in_use(), limits.total);
    if (i % 1024 == 0) {
      r.expire(now);
      auto& s = r.stats();
      ASSERT_EQ(opened + refused, s.packets + s.timed_out + s.superseded
                                    + s.bad_checksum + s.over_limit + r.pending());
    }
  }
  r.expire(now + 1h);
  auto& s = r.stats();
  EXPECT_EQ(corrupted, 0u) << "a delivered packet was never sent";
  EXPECT_EQ(r.pending(), 0u);
  EXPECT_EQ(r.memory_in_use(), 0u);
  EXPECT_FALSE(r.next_deadline());
  // Every packet the reassembler took on was delivered or dropped under
  // exactly one counter.
  EXPECT_EQ(opened + refused, s.packets + s.timed_out + s.superseded
                                + s.bad_checksum + s.over_limit);
  size_t total_delivered = 0;
  for (auto& d : delivered)
    total_delivered += d.size();
  EXPECT_EQ(total_delivered, s.packets);
  auto clean = c.imp.loss == 0 && c.imp.duplication == 0;
  for (size_t sender = 0; sender < c.senders; ++sender) {
    SCOPED_TRACE(sender);
    auto& all = ids[sender];
    if (clean && !c.imp.reorder) {
      EXPECT_EQ(delivered[sender], all) << "not every packet, or not in order";
    } else if (clean) {
      auto got = delivered[sender];
      auto want = all;
      std::sort(got.begin(), got.end());
      std::sort(want.begin(), want.end());
      EXPECT_EQ(got, want) << "reordering within the window lost a packet";
    } else if (c.imp.loss == 0 && !c.imp.reorder) {
      // Duplicated frames alone cost (almost) no packet (single-frame
      // packets may be delivered twice: they carry no sequence number).
      auto got = delivered[sender];
      std::sort(got.begin(), got.end());
      got.erase(std::unique(got.begin(), got.end()), got.end());
      auto want = all; // ids are by content: equal packets share one
      std::sort(want.begin(), want.end());
      want.erase(std::unique(want.begin(), want.end()), want.end());
      std::vector<size_t> missing;
      std::set_difference(want.begin(), want.end(), got.begin(), got.end(),
                          std::back_inserter(missing));
      // Duplicates are recognised by the window, the tag's history and the
      // stash check; what remains is a copy delayed past the sender's next
      // three packets (2-bit tags), which costs its packet (never corrupts
      // it). Bound: 0.2 % of packets.
      EXPECT_LE(missing.size() * 500, want.size())
        << "a duplicated frame lost " << missing.size() << " packets, first "
        << (missing.empty() ? 0 : missing[0]) << " of "
        << (missing.empty() ? 0 : t.sent[sender][missing[0]].size())
        << " bytes; stats " << s.duplicates << " dup " << s.bad_checksum
        << " crc " << s.orphans << " orphans " << s.timed_out << " timed out "
        << s.superseded << " superseded";
    }
  }
  if (clean) {
    EXPECT_EQ(drops(s), 0u);
  }
  RecordProperty("frames", static_cast<int>(t.arrivals.size()));
  RecordProperty("delivered", static_cast<int>(s.packets));
}

namespace {

std::vector<traffic_case> traffic_cases() {
  const impairment clean{};
  const impairment loss{0.002, 0, false};
  const impairment duplication{0, 0.02, false};
  const impairment reordering{0, 0, true};
  const impairment combined{0.002, 0.02, true};
  std::vector<traffic_case> cases;
  const uint32_t mtus[] = {8, 32, 1500};
  uint64_t seed = 1;
  for (auto mtu : mtus) {
    auto name = [&](const char* what) {
      return "mtu" + std::to_string(mtu) + "_" + what;
    };
    auto loss_here = loss;
    auto combined_here = combined;
    if (mtu == 1500) // few frames per packet: make loss matter
      loss_here.loss = combined_here.loss = 0.02;
    cases.push_back({name("clean"), mtu, 1, 2000, clean, seed++});
    cases.push_back({name("loss"), mtu, 1, 2000, loss_here, seed++});
    cases.push_back({name("duplication"), mtu, 1, 2000, duplication, seed++});
    cases.push_back({name("reordering"), mtu, 1, 2000, reordering, seed++});
    cases.push_back({name("combined"), mtu, 1, 2000, combined_here, seed++});
    cases.push_back({name("three_senders_reordering"), mtu, 3, 1500,
                     reordering, seed++});
    cases.push_back({name("three_senders_combined"), mtu, 3, 1500,
                     combined_here, seed++});
  }
  return cases;
}

} // namespace

INSTANTIATE_TEST_SUITE_P(fragmentation, random_traffic,
                         testing::ValuesIn(traffic_cases()),
                         [](const testing::TestParamInfo<traffic_case>& c) {
                           return c.param.name;
                         });

TEST(reassembly, reassembles_a_payload_that_repeats_every_16_frames) {
  // All zeros: frame i and frame i + 16 carry the same bytes. In order, each
  // is new, not a late duplicate of the one a window back.
  for (uint32_t mtu : {8u, 32u}) {
    SCOPED_TRACE(mtu);
    byte_buffer packet(1000, 0);
    auto frames = frames_of(mtu, packet);
    ASSERT_GT(frames.size(), 32u);
    receiver rx;
    for (auto& f : frames)
      rx.push(f);
    ASSERT_EQ(rx.delivered.size(), 1u);
    EXPECT_EQ(rx.delivered[0], packet);
    EXPECT_EQ(rx.r.stats().duplicates, 0u);
  }
}

TEST(reassembly, delivers_identical_packets_repeated_with_single_frames_between) {
  // Periodic traffic: the same 2-frame packet every fourth packet (so it
  // reuses its tag), with single-frame packets in between. Each repeat is a
  // new packet, not a duplicate of the last.
  fragmenter f{8};
  receiver rx;
  auto periodic = pattern(12); // 3 frames at MTU 8
  auto small = pattern(3);     // 1 frame
  size_t sent = 0;
  for (int round = 0; round < 6; ++round) {
    for (auto* p : {&periodic, &small, &small, &small}) {
      f.split(p->data(), p->size(), [&](const uint8_t* d, size_t n) {
        rx.push(byte_buffer(d, d + n));
      });
      ++sent;
    }
  }
  EXPECT_EQ(rx.delivered.size(), sent);
  EXPECT_EQ(rx.r.stats().duplicates, 0u);
}

TEST(reassembly, ignores_a_late_copy_of_a_completed_packets_frame) {
  // A copy of a middle frame arriving after its packet completed must not
  // wait as an early fragment of the tag's next packet.
  fragmenter f{8};
  receiver rx;
  std::vector<byte_buffer> frames;
  auto a = pattern(40, 1);
  f.split(a.data(), a.size(), [&](const uint8_t* d, size_t n) {
    frames.emplace_back(d, d + n);
  });
  for (auto& fr : frames)
    rx.push(fr);
  rx.push(frames[2]); // late copy
  ASSERT_EQ(rx.delivered.size(), 1u);
  // Three more packets, then the tag's next packet arrives intact.
  for (int k = 0; k < 4; ++k) {
    auto b = pattern(40, static_cast<uint8_t>(10 + k));
    f.split(b.data(), b.size(), [&](const uint8_t* d, size_t n) {
      rx.push(byte_buffer(d, d + n));
    });
  }
  EXPECT_EQ(rx.delivered.size(), 5u);
  EXPECT_EQ(rx.r.stats().duplicates, 1u);
  EXPECT_EQ(rx.r.stats().bad_checksum, 0u);
}

TEST(reassembly, a_bus_receiver_gets_every_packet_addressed_to_it) {
  // One sender on a bus talks to three stations in turn; each hears only its
  // own packets. Packets to one station share their first frame (on CAN it
  // holds only the routing header), so with one tag sequence for all
  // destinations a station would see the same tag and first frame again
  // without the other tags in between, and take new packets for late
  // duplicates. One tag sequence per destination keeps every station's
  // stream complete.
  fragmenter f{8};
  std::array<receiver, 3> rx;
  size_t sent = 0;
  for (uint8_t round = 0; round < 20; ++round) {
    for (link_addr dst = 0; dst < 3; ++dst) {
      auto p = pattern(30);
      p[20] = round; // differs only after the first frame
      f.split(dst, p.data(), p.size(), [&](const uint8_t* d, size_t n) {
        rx[dst].push(byte_buffer(d, d + n));
      });
      ++sent;
    }
  }
  for (auto& r : rx) {
    EXPECT_EQ(r.delivered.size(), 20u);
    EXPECT_EQ(r.r.stats().duplicates, 0u);
  }
}

// -- lanes: packets that overtake each other (CAN) ---------------------------------

namespace {

/// A frame on its way through a CAN controller, in its lane (2 * priority,
/// + 1 for a broadcast: can::lane_of; lower is more urgent).
struct lane_frame {
  byte_buffer bytes;
  uint8_t lane;
};

/// The order in which one sender's frames leave its CAN controller. The
/// transmit queue holds `queue` frames and sends the most urgent lane first,
/// FIFO within a lane, as the emulated controller does (`later` in
/// channels/drivers/can.cpp) and a controller whose mailboxes arbitrate by
/// identifier would. What does not fit waits in the channel's backlog,
/// which hands frames over in its own order (a started packet finishes
/// first: tx_backlog.hpp) every `flush_every` frame times (the channel's
/// retry timer). `first` is written at time 0, `second` after `written_at`
/// frame times, straight into the queue if the backlog is empty.
std::vector<lane_frame> controller_order(const std::vector<lane_frame>& first,
                                         const std::vector<lane_frame>& second,
                                         size_t queue, size_t flush_every,
                                         size_t written_at) {
  std::vector<lane_frame> backlog{first};
  std::vector<lane_frame> queued;
  std::vector<lane_frame> bus;
  auto hand_over = [&] {
    while (!backlog.empty() && queued.size() < queue) {
      queued.push_back(backlog.front());
      backlog.erase(backlog.begin());
    }
  };
  hand_over();
  for (size_t t = 0; bus.size() < first.size() + second.size(); ++t) {
    if (t == written_at) {
      bool direct = backlog.empty();
      backlog.insert(backlog.end(), second.begin(), second.end());
      if (direct)
        hand_over();
    }
    if (t % flush_every == 0)
      hand_over();
    if (queued.empty())
      continue;
    auto next = std::min_element(queued.begin(), queued.end(),
                                 [](auto& x, auto& y) { return x.lane < y.lane; });
    bus.push_back(*next);
    queued.erase(next);
  }
  return bus;
}

struct overtaking_case {
  const char* name;
  size_t first_size;
  uint8_t first_lane;
  size_t second_size;
  uint8_t second_lane;
  size_t queue;
  size_t flush_every;
  size_t written_at;
  /// Did the first and second packet arrive at a receiver that kept one
  /// reassembly per sender, before lanes (both packets have tag 0)?
  bool first_in_one_lane;
  bool second_in_one_lane;
};

// Lanes as can::lane_of gives them: control 0, bulk 6, bulk broadcast 7.
// Sizes as in overload_test: bulk packets of 256 bytes (38 frames at MTU
// 8), control packets of 24 (5 frames). Queue 64 and a flush every 16
// frame times are the emulated controller's and the channel's defaults.
const overtaking_case overtaking_cases[] = {
  {"control written into the queue overtakes the rest of a bulk packet",
   256, 6, 24, 0, 64, 16, 10, false, true},
  {"control's last frames wait in the backlog while bulk frames queued "
   "before them go out",
   256, 6, 24, 0, 8, 16, 3, false, false},
  {"control's first frame overtakes the bulk packet's first frame",
   100, 6, 40, 0, 16, 16, 0, true, false},
  {"control split around a few bulk frames by a short queue",
   60, 6, 24, 0, 8, 2, 3, false, false},
  {"a unicast overtakes a broadcast of its priority (controller arbitrating "
   "by identifier)",
   256, 7, 24, 6, 64, 16, 10, false, true},
  {"control written after the bulk packet left: no overtaking", 256, 6, 24,
   0, 64, 16, 40, true, true},
};

} // namespace

TEST(reassembly_lanes, a_packet_overtaking_another_with_the_same_tag_loses_neither) {
  for (auto& c : overtaking_cases) {
    SCOPED_TRACE(c.name);
    // One sender, one tag sequence per lane: the first packet of each lane
    // has tag 0, so the two packets collide unless lanes tell them apart.
    fragmenter tx{8};
    auto first = pattern(c.first_size, 1);
    auto second = pattern(c.second_size, 2);
    std::vector<lane_frame> first_frames;
    std::vector<lane_frame> second_frames;
    tx.split(2, c.first_lane, first.data(), first.size(),
             [&](const uint8_t* d, size_t n) {
               first_frames.push_back({byte_buffer(d, d + n), c.first_lane});
             });
    tx.split(2, c.second_lane, second.data(), second.size(),
             [&](const uint8_t* d, size_t n) {
               second_frames.push_back({byte_buffer(d, d + n), c.second_lane});
             });
    ASSERT_EQ(first_frames[0].bytes[0] & 0x30, 0);
    ASSERT_EQ(second_frames[0].bytes[0] & 0x30, 0);
    auto bus = controller_order(first_frames, second_frames, c.queue,
                                c.flush_every, c.written_at);
    auto arrived = [&](bool by_lane) {
      reassembler r;
      std::pair<bool, bool> got{false, false};
      for (auto& f : bus) {
        byte_buffer out;
        auto lane = by_lane ? f.lane : uint8_t{0};
        if (r.push(5, lane, f.bytes.data(), f.bytes.size(), t0, out)
            == result::complete) {
          EXPECT_TRUE(out == first || out == second) << "never corrupted";
          got.first = got.first || out == first;
          got.second = got.second || out == second;
        }
      }
      if (by_lane) {
        EXPECT_EQ(drops(r.stats()), 0u);
        EXPECT_EQ(r.pending(), 0u);
        EXPECT_EQ(r.memory_in_use(), 0u);
      } else if (!got.first || !got.second) {
        EXPECT_GT(r.stats().superseded, 0u);
      }
      return got;
    };
    // Before: one reassembly per sender; this interleaving lost packets.
    EXPECT_EQ(arrived(false),
              std::pair(c.first_in_one_lane, c.second_in_one_lane));
    // Now: one per (sender, lane); both arrive, nothing is dropped.
    EXPECT_EQ(arrived(true), std::pair(true, true));
  }
}

TEST(reassembly_lanes, the_fragmenter_keeps_one_tag_sequence_per_destination_and_lane) {
  fragmenter f{8};
  struct step {
    link_addr dst;
    uint8_t lane;
    uint8_t tag;
  };
  const step steps[] = {{2, 6, 0}, {2, 0, 0}, {2, 6, 1}, {2, 6, 2}, {2, 0, 1},
                        {3, 6, 0}, {2, 7, 0}, {2, 6, 3}, {2, 6, 0}, {2, 0, 2}};
  for (size_t k = 0; k < std::size(steps); ++k) {
    SCOPED_TRACE(k);
    auto p = pattern(30, static_cast<uint32_t>(k));
    f.split(steps[k].dst, steps[k].lane, p.data(), p.size(),
            [&](const uint8_t* d, size_t) {
              EXPECT_EQ(d[0] >> 4 & 3, steps[k].tag);
            });
  }
}

TEST(reassembly_lanes, packets_of_many_lanes_interleaved_frame_by_frame_all_arrive) {
  // Every lane of one sender with one packet in flight at once, frames
  // taken round robin over the lanes: the worst interleaving a controller
  // could produce. All packets have tag 0 (one sequence per lane).
  fragmenter tx{8};
  std::vector<byte_buffer> packets;
  std::vector<std::vector<byte_buffer>> frames(max_lanes);
  for (uint8_t lane = 0; lane < max_lanes; ++lane) {
    packets.push_back(pattern(50 + 7 * lane, lane));
    tx.split(1, lane, packets.back().data(), packets.back().size(),
             [&](const uint8_t* d, size_t n) {
               frames[lane].emplace_back(d, d + n);
             });
  }
  reassembler r;
  std::vector<byte_buffer> got;
  for (size_t i = 0;; ++i) {
    bool any = false;
    for (uint8_t lane = 0; lane < max_lanes; ++lane) {
      if (i >= frames[lane].size())
        continue;
      any = true;
      byte_buffer out;
      if (r.push(9, lane, frames[lane][i].data(), frames[lane][i].size(), t0,
                 out)
          == result::complete)
        got.push_back(out);
    }
    if (!any)
      break;
  }
  std::sort(got.begin(), got.end());
  std::sort(packets.begin(), packets.end());
  EXPECT_EQ(got, packets);
  EXPECT_EQ(drops(r.stats()), 0u);
  EXPECT_EQ(r.memory_in_use(), 0u);
}

TEST(reassembly_lanes, the_per_sender_bound_covers_all_its_lanes) {
  // Lanes give a sender no extra memory: its newest packet in one lane
  // evicts its older packet in another when the two exceed per_sender,
  // and another sender's packets are left alone.
  reassembly_limits limits;
  limits.per_sender = 5000;
  reassembler r{limits};
  fragmenter tx{32};
  auto split_in = [&](link_addr dst, uint8_t lane, const byte_buffer& p) {
    std::vector<byte_buffer> out;
    tx.split(dst, lane, p.data(), p.size(), [&](const uint8_t* d, size_t n) {
      out.emplace_back(d, d + n);
    });
    return out;
  };
  auto other = split_in(1, 0, pattern(3000, 3));
  auto old_frames = split_in(2, 6, pattern(3000, 1));
  auto fresh = pattern(3000, 2);
  auto new_frames = split_in(2, 0, fresh);
  byte_buffer out;
  EXPECT_EQ(r.push(8, 0, other[0].data(), other[0].size(), t0, out),
            result::pending);
  EXPECT_EQ(r.push(7, 6, old_frames[0].data(), old_frames[0].size(), t0, out),
            result::pending);
  auto before = r.stats();
  EXPECT_EQ(r.push(7, 0, new_frames[0].data(), new_frames[0].size(), t0, out),
            result::pending);
  expect_only(before, r.stats(), &reassembly_stats::over_limit);
  EXPECT_EQ(r.pending(), 2u) << "sender 8's packet and sender 7's newest";
  auto res = result::dropped;
  for (size_t i = 1; i < new_frames.size(); ++i)
    res = r.push(7, 0, new_frames[i].data(), new_frames[i].size(), t0, out);
  EXPECT_EQ(res, result::complete);
  EXPECT_EQ(out, fresh);
}

// -- bundles (several small packets in one frame) ---------------------------------

namespace {

std::vector<byte_buffer> unbundle(const byte_buffer& frame, size_t max_packet,
                                  bool* ok = nullptr) {
  std::vector<byte_buffer> packets;
  auto res = bundle_decode(frame.data(), frame.size(), max_packet,
                           [&](const uint8_t* data, size_t size) {
                             packets.emplace_back(data, data + size);
                           });
  if (ok != nullptr)
    *ok = res;
  return packets;
}

} // namespace

TEST(bundle, packets_round_trip_in_order) {
  byte_buffer frame;
  std::vector<byte_buffer> packets{{1, 2, 3}, byte_buffer(200, 0xAB), {9}};
  for (auto& p : packets)
    ASSERT_TRUE(bundle_append(frame, 1472, p.data(), p.size()));
  // Header, then each packet behind its LEB128 length (200 takes 2 bytes).
  EXPECT_EQ(frame.size(), 1u + (1 + 3) + (2 + 200) + (1 + 1));
  EXPECT_EQ(frame[0], bundle_header);
  EXPECT_EQ(frame[1], 3);
  EXPECT_EQ(frame[5], 0xC8); // 200 = 0x48 | 0x80, then 0x01
  EXPECT_EQ(frame[6], 0x01);
  bool ok = false;
  EXPECT_EQ(unbundle(frame, 1024, &ok), packets);
  EXPECT_TRUE(ok);
}

TEST(bundle, the_worked_example_of_the_protocol_document) {
  // docs/protocol.md, "Bundles": "hi" and "abc" in one frame.
  byte_buffer frame;
  ASSERT_TRUE(bundle_append(frame, 256, reinterpret_cast<const uint8_t*>("hi"), 2));
  ASSERT_TRUE(bundle_append(frame, 256, reinterpret_cast<const uint8_t*>("abc"), 3));
  EXPECT_EQ(frame, (byte_buffer{0x01, 0x02, 'h', 'i', 0x03, 'a', 'b', 'c'}));
}

TEST(bundle, append_refuses_what_does_not_fit_and_leaves_the_frame_alone) {
  byte_buffer frame;
  byte_buffer big(250, 1);
  ASSERT_TRUE(bundle_append(frame, 256, big.data(), big.size()));
  auto before = frame;
  byte_buffer small(5, 2);
  EXPECT_FALSE(bundle_append(frame, 256, small.data(), small.size()));
  EXPECT_EQ(frame, before);
  EXPECT_FALSE(bundle_append(frame, 256, small.data(), 0)) << "empty packet";
  EXPECT_EQ(bundle_cost(3), 4u);
  EXPECT_EQ(bundle_cost(200), 202u);
}

TEST(bundle, malformed_bundles_deliver_nothing) {
  struct row {
    const char* what;
    byte_buffer frame;
  };
  std::vector<row> rows{
    {"empty", {}},
    {"not a bundle", {0x00, 0x02, 'h', 'i', 0x01, 'x'}},
    {"header only", {0x01}},
    {"one packet", {0x01, 0x02, 'h', 'i'}},
    {"length past the end", {0x01, 0x02, 'h', 'i', 0x05, 'a', 'b'}},
    {"empty packet", {0x01, 0x02, 'h', 'i', 0x00}},
    {"truncated length", {0x01, 0x02, 'h', 'i', 0x80}},
    {"non-minimal length", {0x01, 0x02, 'h', 'i', 0x82, 0x00, 'a', 'b'}},
    {"above max_packet", {0x01, 0x02, 'h', 'i', 0x04, 'a', 'b', 'c', 'd'}},
  };
  for (auto& r : rows) {
    bool ok = true;
    auto got = unbundle(r.frame, 3, &ok);
    EXPECT_FALSE(ok) << r.what;
    EXPECT_TRUE(got.empty()) << r.what;
  }
}

TEST(bundle, a_bundle_is_malformed_for_the_reassembler) {
  // Receivers that do not bundle (MTU below min_bundle_mtu) drop a bundle
  // frame as malformed rather than deliver it as a packet.
  reassembler r;
  byte_buffer frame{0x01, 0x02, 'h', 'i', 0x03, 'a', 'b', 'c'}, out;
  EXPECT_EQ(r.push(1, frame.data(), frame.size(), {}, out),
            reassembler::result::dropped);
  EXPECT_EQ(r.stats().malformed, 1u);
}
