// Specification of the C client's link layer (apps/mcu/client/hermc_link.h,
// hermc_can.h): every codec against the byte strings of docs/protocol.md
// (the ones the C++ tests check), every receiver rule, every bound driven
// past its limit. Links hermc only.

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hermc_can.h"
#include "hermc_link.h"
#include "tests/mcu/mcu_bytes.hpp"

namespace {

using bytes = std::vector<uint8_t>;

bytes iota_bytes(size_t n, uint8_t first = 0) {
  bytes b(n);
  for (size_t i = 0; i < n; ++i)
    b[i] = static_cast<uint8_t>(first + i);
  return b;
}

// Collects delivered packets with their source.
using sink = mcu_test::packet_sink;

// All frames of one packet at `mtu` with `tag`.
std::vector<bytes> frames_of(const bytes& pkt, uint16_t mtu, uint8_t tag = 0) {
  hermc_frag f;
  EXPECT_EQ(hermc_frag_begin(&f, pkt.data(), pkt.size(), mtu, tag), HERMC_OK);
  std::vector<bytes> out;
  bytes frame(mtu);
  size_t n;
  while ((n = hermc_frag_next(&f, frame.data())) != 0)
    out.emplace_back(frame.begin(), frame.begin() + static_cast<long>(n));
  return out;
}

bytes drain(hermc_link_tx& tx) {
  bytes out(hermc_link_tx_pending(&tx));
  EXPECT_EQ(hermc_link_tx_pop(&tx, out.data(), out.size()), out.size());
  return out;
}

// A reassembler with `n` slots of its own.
struct reasm_fixture {
  std::vector<hermc_reasm_slot> slots;
  hermc_reasm r;
  sink out;

  explicit reasm_fixture(uint8_t n = 1) : slots(n) {
    hermc_reasm_init(&r, slots.data(), n);
  }

  int push(const bytes& frame, uint8_t src = 1, uint8_t lane = 0) {
    return hermc_reasm_push(&r, src, lane, frame.data(), frame.size(),
                            sink::on_packet, &out);
  }
};

const bytes worked_payload = iota_bytes(20);
const std::vector<bytes> worked_frames = {
  {0x40, 0x14, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05},
  {0x81, 0x06, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C},
  {0x82, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13},
  {0x83, 0xA4, 0xFF, 0xDD, 0x3B},
};

// -- checksums and codecs --------------------------------------------------------------

TEST(hermc_codec, crc16_has_the_documented_check_values) {
  const std::string check = "123456789";
  auto* p = reinterpret_cast<const uint8_t*>(check.data());
  EXPECT_EQ(hermc_crc16(HERMC_CRC16_INIT, p, check.size()), 0x29B1);
  bytes hi = {0x00, 0x48, 0x69};
  EXPECT_EQ(hermc_crc16(HERMC_CRC16_INIT, hi.data(), hi.size()), 0xB576);
  bytes esc = {0x00, 0x11, 0x13, 0x7D};
  EXPECT_EQ(hermc_crc16(HERMC_CRC16_INIT, esc.data(), esc.size()), 0x0989);
  // Continued in two parts: the same.
  EXPECT_EQ(hermc_crc16(hermc_crc16(HERMC_CRC16_INIT, p, 4), p + 4, 5), 0x29B1);
}

TEST(hermc_codec, crc32_has_the_documented_check_values) {
  const std::string check = "123456789";
  auto* p = reinterpret_cast<const uint8_t*>(check.data());
  EXPECT_EQ(hermc_crc32(p, check.size()), 0xCBF43926u);
  EXPECT_EQ(hermc_crc32(worked_payload.data(), worked_payload.size()), 0x3BDDFFA4u);
  EXPECT_EQ(hermc_crc32(nullptr, 0), 0u);
  auto state = hermc_crc32_update(HERMC_CRC32_INIT, p, 3);
  state = hermc_crc32_update(state, p + 3, 6);
  EXPECT_EQ(state ^ 0xFFFFFFFFu, 0xCBF43926u);
}

TEST(hermc_codec, cobs_encodes_the_documented_examples) {
  struct example {
    bytes raw;
    bytes enc;
  };
  bytes b254 = iota_bytes(254, 1);
  bytes b255 = iota_bytes(255, 1);
  bytes e254 = b254;
  e254.insert(e254.begin(), 0xFF);
  bytes e255 = {0xFF};
  e255.insert(e255.end(), b255.begin(), b255.begin() + 254);
  e255.push_back(0x02);
  e255.push_back(0xFF);
  const std::vector<example> cases = {
    {{}, {0x01}},
    {{0x00}, {0x01, 0x01}},
    {{0x11, 0x22, 0x00, 0x33}, {0x03, 0x11, 0x22, 0x02, 0x33}},
    {{0x11, 0x22, 0x33, 0x44}, {0x05, 0x11, 0x22, 0x33, 0x44}},
    {{0x11, 0x00, 0x00, 0x00}, {0x02, 0x11, 0x01, 0x01, 0x01}},
    {b254, e254},
    {b255, e255},
  };
  for (const auto& c : cases) {
    bytes out(HERMC_COBS_MAX(c.raw.size()));
    auto n = hermc_cobs_encode(c.raw.data(), c.raw.size(), out.data());
    out.resize(n);
    EXPECT_EQ(out, c.enc) << "raw of " << c.raw.size() << " bytes";
  }
}

TEST(hermc_codec, leb128_sizes_follow_the_documented_table) {
  const std::vector<std::pair<uint32_t, size_t>> cases = {
    {0, 1}, {127, 1}, {128, 2}, {300, 2}, {16383, 2}, {16384, 3},
    {65536, 3}, {2097151, 3}, {2097152, 4}};
  for (auto [v, k] : cases)
    EXPECT_EQ(hermc_leb128_size(v), k) << v;
}

// -- fragmenter --------------------------------------------------------------------------

TEST(hermc_fragmenter, splits_a_20_byte_packet_at_mtu_8_as_in_the_protocol_document) {
  EXPECT_EQ(frames_of(worked_payload, 8), worked_frames);
  EXPECT_EQ(hermc_frag_count(20, 8), 4u);
}

TEST(hermc_fragmenter, counts_frames_as_the_efficiency_table) {
  struct row {
    size_t n;
    uint16_t mtu;
    uint32_t frames;
  };
  const std::vector<row> rows = {
    {20, 8, 4},     {64, 8, 10},    {1024, 8, 148},  {2004, 8, 288},
    {4096, 8, 586}, {65536, 8, 9364}, {20, 32, 1},   {64, 32, 3},
    {1024, 32, 34}, {2004, 32, 65}, {4096, 32, 133}, {65536, 32, 2115},
  };
  for (const auto& r : rows) {
    EXPECT_EQ(hermc_frag_count(r.n, r.mtu), r.frames) << r.n << " at " << r.mtu;
    EXPECT_EQ(frames_of(iota_bytes(r.n), r.mtu).size(), r.frames) << r.n;
  }
  EXPECT_EQ(hermc_frag_count(HERMC_MAX_ANNOUNCED + 1, 8), 0u);
  EXPECT_EQ(hermc_frag_count(10, 7), 0u);
}

TEST(hermc_fragmenter, sends_single_frames_with_the_tag_and_the_empty_packet_as_one_byte) {
  EXPECT_EQ(frames_of({}, 8, 0), (std::vector<bytes>{{0x00}}));
  EXPECT_EQ(frames_of({}, 8, 3), (std::vector<bytes>{{0x30}}));
  EXPECT_EQ(frames_of({0xAA, 0xBB}, 8, 1), (std::vector<bytes>{{0x10, 0xAA, 0xBB}}));
  // n + 1 == MTU still fits one frame; n == MTU does not.
  EXPECT_EQ(frames_of(iota_bytes(7), 8).size(), 1u);
  EXPECT_EQ(frames_of(iota_bytes(8), 8).size(), 2u);
}

TEST(hermc_fragmenter, uses_wide_sequence_numbers_from_mtu_64) {
  auto frames = frames_of(iota_bytes(200), 64, 2);
  ASSERT_EQ(frames.size(), 4u);
  EXPECT_EQ(frames[0][0], 0x68); // first, tag 2, W
  EXPECT_EQ(frames[0][1], 0xC8); // 200 = C8 01
  EXPECT_EQ(frames[0][2], 0x01);
  EXPECT_EQ(frames[1][0], 0xE0); // wide consecutive, tag 2, index 1
  EXPECT_EQ(frames[1][1], 0x01);
  EXPECT_EQ(frames[3][1], 0x03);
  // Narrow indexes wrap at 16: frame 16 carries sequence 0.
  auto narrow = frames_of(iota_bytes(150), 8);
  ASSERT_GT(narrow.size(), 17u);
  EXPECT_EQ(narrow[16][0], 0x80);
  EXPECT_EQ(narrow[17][0], 0x81);
}

TEST(hermc_fragmenter, refuses_what_it_cannot_announce_or_cut) {
  hermc_frag f;
  uint8_t b = 0;
  EXPECT_EQ(hermc_frag_begin(&f, &b, 1, 7, 0), HERMC_ERR_ARG);
  if (sizeof(size_t) > 2) {
    EXPECT_EQ(hermc_frag_begin(&f, &b, HERMC_MAX_ANNOUNCED + 1, 8, 0),
              HERMC_ERR_TOO_BIG);
  }
}

// -- reassembler ------------------------------------------------------------------------

TEST(hermc_reassembler, reassembles_the_worked_example) {
  reasm_fixture t;
  for (size_t i = 0; i + 1 < worked_frames.size(); ++i)
    EXPECT_EQ(t.push(worked_frames[i]), HERMC_REASM_PENDING);
  EXPECT_EQ(t.push(worked_frames.back()), HERMC_REASM_COMPLETE);
  ASSERT_EQ(t.out.packets.size(), 1u);
  EXPECT_EQ(t.out.packets[0], worked_payload);
  EXPECT_EQ(t.out.sources[0], 1);
  EXPECT_EQ(t.r.stats.packets, 1u);
  EXPECT_EQ(hermc_reasm_pending(&t.r), 0);
}

TEST(hermc_reassembler, round_trips_every_size_up_to_the_bound_at_several_mtus) {
  for (uint16_t mtu : {8, 9, 32, 64, 255}) {
    reasm_fixture t;
    for (size_t n = 0; n <= HERMC_MAX_PACKET; ++n) {
      auto pkt = iota_bytes(n, static_cast<uint8_t>(n));
      for (const auto& f : frames_of(pkt, mtu, static_cast<uint8_t>(n)))
        t.push(f);
      ASSERT_EQ(t.out.packets.size(), n + 1) << n << " at " << mtu;
      EXPECT_EQ(t.out.packets.back(), pkt);
    }
    EXPECT_EQ(t.r.stats.packets, HERMC_MAX_PACKET + 1u);
    EXPECT_EQ(t.r.stats.malformed + t.r.stats.orphans + t.r.stats.lost
                + t.r.stats.superseded + t.r.stats.duplicates,
              0u);
  }
}

TEST(hermc_reassembler, drops_a_packet_whose_middle_fragment_is_lost_and_counts_it) {
  reasm_fixture t;
  t.push(worked_frames[0]);
  t.push(worked_frames[1]);
  EXPECT_EQ(t.push(worked_frames[3]), HERMC_REASM_DROPPED);
  EXPECT_TRUE(t.out.packets.empty());
  EXPECT_EQ(t.r.stats.lost, 1u);
  EXPECT_EQ(t.r.stats.orphans, 1u);
  EXPECT_EQ(hermc_reasm_pending(&t.r), 0);
  // The next packet is unaffected.
  for (const auto& f : frames_of(worked_payload, 8, 1))
    t.push(f);
  ASSERT_EQ(t.out.packets.size(), 1u);
  EXPECT_EQ(t.out.packets[0], worked_payload);
}

TEST(hermc_reassembler, a_new_packet_supersedes_the_incomplete_one) {
  reasm_fixture t;
  t.push(worked_frames[0]);
  t.push(worked_frames[1]);
  auto next = iota_bytes(30, 100);
  for (const auto& f : frames_of(next, 8, 1))
    t.push(f);
  // The tail of the first one arrives late: it belongs to no packet.
  EXPECT_EQ(t.push(worked_frames[2]), HERMC_REASM_DROPPED);
  ASSERT_EQ(t.out.packets.size(), 1u);
  EXPECT_EQ(t.out.packets[0], next);
  EXPECT_EQ(t.r.stats.superseded, 1u);
  EXPECT_EQ(t.r.stats.orphans, 1u);
}

TEST(hermc_reassembler, ignores_duplicate_first_and_consecutive_frames) {
  reasm_fixture t;
  t.push(worked_frames[0]);
  EXPECT_EQ(t.push(worked_frames[0]), HERMC_REASM_DROPPED);
  t.push(worked_frames[1]);
  EXPECT_EQ(t.push(worked_frames[1]), HERMC_REASM_DROPPED);
  t.push(worked_frames[2]);
  EXPECT_EQ(t.push(worked_frames[1]), HERMC_REASM_DROPPED);
  t.push(worked_frames[3]);
  ASSERT_EQ(t.out.packets.size(), 1u);
  EXPECT_EQ(t.out.packets[0], worked_payload);
  EXPECT_EQ(t.r.stats.duplicates, 3u);
}

TEST(hermc_reassembler, a_corrupted_fragment_fails_the_crc32_and_is_never_delivered) {
  reasm_fixture t;
  auto bad = worked_frames[2];
  bad[3] ^= 0x01;
  t.push(worked_frames[0]);
  t.push(worked_frames[1]);
  t.push(bad);
  EXPECT_EQ(t.push(worked_frames[3]), HERMC_REASM_DROPPED);
  EXPECT_TRUE(t.out.packets.empty());
  EXPECT_EQ(t.r.stats.bad_checksum, 1u);
}

TEST(hermc_reassembler, drops_malformed_frames_and_counts_each_once) {
  reasm_fixture t;
  bytes too_long_single(HERMC_MAX_PACKET + 2, 0x01);
  too_long_single[0] = 0x00;
  const std::vector<bytes> bad = {
    {},                                          // empty
    {0x01, 0x02, 0x03},                          // bundle: reserved bits
    {0x08, 0xAA},                                // single, reserved bit
    {0x41, 0x14, 0x00},                          // first, reserved bit
    {0x40, 0x80},                                // length runs past the frame
    {0x40, 0x80, 0x80, 0x80, 0x01, 0x00},        // length longer than 3 bytes
    {0x40, 0x14},                                // no stream byte
    {0x40, 0x01, 1, 2, 3, 4, 5, 6},              // more than n + 4 stream bytes
    {0x40, static_cast<uint8_t>(0x80 | (HERMC_MAX_PACKET + 1) % 128),
     static_cast<uint8_t>((HERMC_MAX_PACKET + 1) / 128), 0, 1, 2, 3, 4}, // above max
    {0x40, 0x80, 0x80, 0x04, 0, 1, 2, 3},        // 65536: no 16-bit wrap to 0
    {0x40, 0xFF, 0xFF, 0x7F, 0, 1, 2, 3},        // 2^21 - 1, the largest announced
    too_long_single,                             // single above max
    {0x81},                                      // narrow: no stream byte
    {0xC0, 0x01},                                // wide: no stream byte
  };
  for (const auto& f : bad)
    EXPECT_EQ(t.push(f), HERMC_REASM_DROPPED) << f.size();
  EXPECT_EQ(t.r.stats.malformed, bad.size());
  EXPECT_TRUE(t.out.packets.empty());
  // A consecutive frame of the other width than its first frame.
  t.push(worked_frames[0]);
  EXPECT_EQ(t.push({0xC0, 0x01, 0x06}), HERMC_REASM_DROPPED);
  EXPECT_EQ(t.r.stats.malformed, bad.size() + 1);
  // Padded length encodings are accepted (82 80 00 = 2).
  reasm_fixture u;
  auto frames = frames_of(iota_bytes(9), 8);
  bytes padded = {0x40, 0x89, 0x80, 0x00};
  padded.insert(padded.end(), frames[0].begin() + 2, frames[0].end());
  padded.resize(6);
  // The first frame is now 6 bytes: its sender's MTU is 6 for the cut, so
  // just check it is accepted, not malformed.
  EXPECT_EQ(u.push(padded), HERMC_REASM_PENDING);
  EXPECT_EQ(u.r.stats.malformed, 0u);
}

TEST(hermc_reassembler, consecutive_frames_without_their_packet_are_orphans) {
  reasm_fixture t;
  EXPECT_EQ(t.push(worked_frames[1]), HERMC_REASM_DROPPED);
  t.push(worked_frames[0]);
  // Another tag: not this packet's frame.
  EXPECT_EQ(t.push({0x91, 6, 7, 8, 9, 10, 11, 12}), HERMC_REASM_DROPPED);
  // A short frame that is not the last.
  EXPECT_EQ(t.push({0x81, 6, 7, 8}), HERMC_REASM_DROPPED);
  // Beyond the last index.
  EXPECT_EQ(t.push({0x85, 1}), HERMC_REASM_DROPPED);
  EXPECT_EQ(t.r.stats.orphans, 4u);
  EXPECT_EQ(t.r.stats.lost, 0u);
  for (size_t i = 1; i < worked_frames.size(); ++i)
    t.push(worked_frames[i]);
  ASSERT_EQ(t.out.packets.size(), 1u);
}

TEST(hermc_reassembler, a_first_frame_with_the_whole_stream_completes_at_once) {
  reasm_fixture t;
  bytes pkt = {0xAA};
  auto crc = hermc_crc32(pkt.data(), 1);
  bytes frame = {0x40, 0x01, 0xAA, static_cast<uint8_t>(crc), static_cast<uint8_t>(crc >> 8),
                 static_cast<uint8_t>(crc >> 16), static_cast<uint8_t>(crc >> 24)};
  EXPECT_EQ(t.push(frame), HERMC_REASM_COMPLETE);
  ASSERT_EQ(t.out.packets.size(), 1u);
  EXPECT_EQ(t.out.packets[0], pkt);
}

TEST(hermc_reassembler, expires_incomplete_packets_after_the_timeout_across_clock_wrap) {
  reasm_fixture t;
  const uint32_t start = 0xFFFFFF00u;
  hermc_reasm_tick(&t.r, start);
  t.push(worked_frames[0]);
  hermc_reasm_tick(&t.r, start + HERMC_REASSEMBLY_TIMEOUT_MS); // wraps past 0
  EXPECT_EQ(hermc_reasm_pending(&t.r), 1);
  EXPECT_EQ(t.r.stats.timed_out, 0u);
  hermc_reasm_tick(&t.r, start + HERMC_REASSEMBLY_TIMEOUT_MS + 1);
  EXPECT_EQ(hermc_reasm_pending(&t.r), 0);
  EXPECT_EQ(t.r.stats.timed_out, 1u);
  // Its remaining frames are orphans now.
  EXPECT_EQ(t.push(worked_frames[1]), HERMC_REASM_DROPPED);
  EXPECT_EQ(t.r.stats.orphans, 1u);
}

TEST(hermc_reassembler, slots_evict_the_same_senders_oldest_never_another_senders) {
  reasm_fixture t(2);
  hermc_reasm_tick(&t.r, 10);
  t.push(worked_frames[0], 5, 0);
  hermc_reasm_tick(&t.r, 20);
  t.push(worked_frames[0], 6, 0);
  // A third sender finds no slot: refused.
  EXPECT_EQ(t.push(worked_frames[0], 7, 0), HERMC_REASM_DROPPED);
  EXPECT_EQ(t.r.stats.over_limit, 1u);
  // Sender 5 in another lane evicts its own packet of lane 0.
  EXPECT_EQ(t.push(worked_frames[0], 5, 2), HERMC_REASM_PENDING);
  EXPECT_EQ(t.r.stats.over_limit, 2u);
  for (size_t i = 1; i < worked_frames.size(); ++i) {
    t.push(worked_frames[i], 6, 0);
    t.push(worked_frames[i], 5, 2);
    t.push(worked_frames[i], 5, 0); // orphans: evicted
  }
  ASSERT_EQ(t.out.packets.size(), 2u);
  EXPECT_EQ(t.out.sources, (std::vector<uint8_t>{6, 5}));
  EXPECT_EQ(t.r.stats.orphans, 3u);
}

// -- serial link --------------------------------------------------------------------------

struct serial_fixture {
  hermc_link_tx tx;
  hermc_link_rx rx;
  sink out;

  explicit serial_fixture(bool escaped = false) {
    hermc_link_tx_init(&tx, escaped);
    hermc_link_rx_init(&rx, escaped);
  }

  void feed(const bytes& b) {
    hermc_link_rx_feed(&rx, b.data(), b.size(), sink::on_packet, &out);
  }
};

const bytes hi_wire = {0x00, 0x01, 0x05, 0x48, 0x69, 0xB5, 0x76, 0x00};

TEST(hermc_serial, encodes_the_documented_example_byte_by_byte) {
  serial_fixture s;
  bytes hi = {0x48, 0x69};
  ASSERT_EQ(hermc_link_tx_packet(&s.tx, hi.data(), hi.size()), HERMC_OK);
  bytes wire;
  uint8_t b;
  while (hermc_link_tx_pop(&s.tx, &b, 1) == 1)
    wire.push_back(b);
  EXPECT_EQ(wire, hi_wire);
  EXPECT_EQ(hermc_link_tx_pending(&s.tx), 0u);
}

TEST(hermc_serial, escaped_mode_encodes_the_documented_example) {
  serial_fixture s(true);
  bytes pkt = {0x11, 0x13, 0x7D}; // the frame 00 11 13 7D: single, tag 0
  ASSERT_EQ(hermc_link_tx_packet(&s.tx, pkt.data(), pkt.size()), HERMC_OK);
  auto wire = drain(s.tx);
  // The documented bytes, after the leading delimiter of an idle line.
  EXPECT_EQ(wire, (bytes{0x00, 0x01, 0x06, 0x7D, 0x31, 0x7D, 0x33, 0x7D, 0x5D, 0x09, 0x89, 0x00}));
  serial_fixture r(true);
  r.feed(wire);
  ASSERT_EQ(r.out.packets.size(), 1u);
  EXPECT_EQ(r.out.packets[0], pkt);
}

TEST(hermc_serial, escaped_mode_queues_the_exact_size_not_the_worst_case) {
  serial_fixture s(true);
  auto big = iota_bytes(HERMC_MAX_PACKET, 0x20); // few bytes to escape
  ASSERT_GT(hermc_link_tx_wire_bound(big.size(), true), static_cast<size_t>(HERMC_TX_RING));
  ASSERT_EQ(hermc_link_tx_packet(&s.tx, big.data(), big.size()), HERMC_OK);
  serial_fixture r(true);
  r.feed(drain(s.tx));
  ASSERT_EQ(r.out.packets.size(), 1u);
  EXPECT_EQ(r.out.packets[0], big);
  // All bytes to escape: twice the size, more than the ring.
  bytes worst(HERMC_MAX_PACKET, 0x11);
  EXPECT_EQ(hermc_link_tx_packet(&s.tx, worst.data(), worst.size()), HERMC_ERR_TOO_BIG);
  EXPECT_EQ(hermc_link_tx_pending(&s.tx), 0u);
}

TEST(hermc_serial, decodes_the_documented_example_in_any_chunking) {
  for (size_t chunk : {1, 2, 3, 8}) {
    serial_fixture s;
    for (size_t i = 0; i < hi_wire.size(); i += chunk)
      s.feed(bytes(hi_wire.begin() + static_cast<long>(i),
                   hi_wire.begin() + static_cast<long>(std::min(i + chunk, hi_wire.size()))));
    ASSERT_EQ(s.out.packets.size(), 1u);
    EXPECT_EQ(s.out.packets[0], (bytes{0x48, 0x69}));
    EXPECT_EQ(s.out.sources[0], 1);
    EXPECT_EQ(s.rx.frame_stats.frames, 1u);
    EXPECT_EQ(s.rx.frame_stats.idle, 1u);
  }
}

TEST(hermc_serial, round_trips_every_packet_size_through_tx_and_rx) {
  serial_fixture s;
  for (size_t n = 0; n <= HERMC_MAX_PACKET; ++n) {
    auto pkt = iota_bytes(n, static_cast<uint8_t>(3 * n));
    ASSERT_EQ(hermc_link_tx_packet(&s.tx, pkt.data(), pkt.size()), HERMC_OK) << n;
    s.feed(drain(s.tx));
    ASSERT_EQ(s.out.packets.size(), n + 1);
    EXPECT_EQ(s.out.packets.back(), pkt);
  }
  EXPECT_EQ(s.rx.reasm.stats.packets, HERMC_MAX_PACKET + 1u);
  EXPECT_EQ(s.rx.frame_stats.bad_crc + s.rx.frame_stats.bad_cobs
              + s.rx.frame_stats.oversized + s.rx.frame_stats.too_short,
            0u);
}

TEST(hermc_serial, drops_bad_runs_counts_each_once_and_resynchronises) {
  serial_fixture s;
  auto bad_crc = hi_wire;
  bad_crc[4] ^= 0x01;
  s.feed(bad_crc);
  s.feed({0x05, 0x48, 0x69, 0x00});     // a code byte points past the run
  s.feed({0x02, 0x48, 0x00});           // decodes to 1 byte: shorter than its CRC
  bytes garbage(HERMC_RUN_MAX + 40, 0x42);
  s.feed(garbage);                      // no delimiter for too long
  s.feed({0x00});
  EXPECT_EQ(s.rx.frame_stats.bad_crc, 1u);
  EXPECT_EQ(s.rx.frame_stats.bad_cobs, 1u);
  EXPECT_EQ(s.rx.frame_stats.too_short, 1u);
  EXPECT_EQ(s.rx.frame_stats.oversized, 1u);
  EXPECT_TRUE(s.out.packets.empty());
  // The longest valid run is exactly HERMC_RUN_MAX bytes: accepted.
  serial_fixture big;
  auto pkt = iota_bytes(HERMC_MTU - 1, 1);
  hermc_link_tx_packet(&big.tx, pkt.data(), pkt.size());
  auto wire = drain(big.tx);
  EXPECT_EQ(wire.size(), HERMC_RUN_MAX + 2u);
  s.feed(wire);
  ASSERT_EQ(s.out.packets.size(), 1u);
  EXPECT_EQ(s.out.packets[0], pkt);
  EXPECT_EQ(s.rx.frame_stats.frames, 1u);
}

TEST(hermc_serial, escaped_mode_refuses_bad_escapes) {
  serial_fixture s(true);
  s.feed({0x00, 0x7D, 0x41, 0x02, 0x00}); // 7D not followed by 31/33/5D
  s.feed({0x01, 0x7D, 0x00});             // 7D followed by the delimiter
  EXPECT_EQ(s.rx.frame_stats.bad_escape, 2u);
  s.feed(hi_wire);
  EXPECT_EQ(s.out.packets.size(), 1u);
}

TEST(hermc_serial, the_ring_takes_a_packet_whole_or_refuses_it) {
  serial_fixture s;
  auto big = iota_bytes(HERMC_MAX_PACKET);
  auto need = hermc_link_tx_wire_bound(big.size(), false);
  ASSERT_LE(need, static_cast<size_t>(HERMC_TX_RING));
  ASSERT_EQ(hermc_link_tx_packet(&s.tx, big.data(), big.size()), HERMC_OK);
  auto queued = hermc_link_tx_pending(&s.tx);
  EXPECT_LE(queued, need);
  if (hermc_link_tx_free(&s.tx) < need) {
    EXPECT_EQ(hermc_link_tx_packet(&s.tx, big.data(), big.size()), HERMC_ERR_FULL);
    EXPECT_EQ(hermc_link_tx_pending(&s.tx), queued);
    EXPECT_EQ(s.tx.refused, 1u);
    EXPECT_EQ(s.tx.tag, 1); // a refusal does not use a tag
  }
  // Never fits: a packet whose bound exceeds the ring.
  size_t huge = HERMC_TX_RING;
  while (hermc_link_tx_wire_bound(huge, false) <= HERMC_TX_RING)
    huge += 16;
  bytes h(huge);
  EXPECT_EQ(hermc_link_tx_packet(&s.tx, h.data(), h.size()), HERMC_ERR_TOO_BIG);
  // Drained, the ring takes it again, and wraps around its end.
  for (int round = 0; round < 5; ++round) {
    s.feed(drain(s.tx));
    ASSERT_EQ(hermc_link_tx_packet(&s.tx, big.data(), big.size()), HERMC_OK);
  }
  s.feed(drain(s.tx));
  EXPECT_EQ(s.out.packets.size(), 6u);
  for (const auto& p : s.out.packets)
    EXPECT_EQ(p, big);
}

TEST(hermc_serial, a_lost_byte_loses_its_packet_only) {
  serial_fixture tx_side;
  serial_fixture s;
  auto a = iota_bytes(100, 1);
  auto b = iota_bytes(50, 9);
  hermc_link_tx_packet(&tx_side.tx, a.data(), a.size());
  auto wire_a = drain(tx_side.tx);
  hermc_link_tx_packet(&tx_side.tx, b.data(), b.size());
  auto wire_b = drain(tx_side.tx);
  wire_a.erase(wire_a.begin() + 50); // inside the second frame
  s.feed(wire_a);
  s.feed(wire_b);
  ASSERT_EQ(s.out.packets.size(), 1u);
  EXPECT_EQ(s.out.packets[0], b);
  EXPECT_EQ(s.rx.reasm.stats.lost + s.rx.reasm.stats.superseded, 1u);
}

// -- CAN ------------------------------------------------------------------------------------

TEST(hermc_can_id, fields_sit_at_the_documented_bit_positions) {
  hermc_can_fields x{2, 0x12, 0x34};
  EXPECT_EQ(hermc_can_encode_id(HERMC_CAN_29BIT, &x), 0x0848D250u);
  x = {3, 2, 5};
  EXPECT_EQ(hermc_can_encode_id(HERMC_CAN_11BIT, &x), 0x325u);
  x = {3, HERMC_CAN_BROADCAST, 5};
  EXPECT_EQ(hermc_can_encode_id(HERMC_CAN_11BIT, &x), 0x3F5u);
  x = {9, HERMC_CAN_BROADCAST, 1};
  EXPECT_EQ(hermc_can_encode_id(HERMC_CAN_29BIT, &x), 0x1FFC0650u);
}

TEST(hermc_can_id, decodes_and_refuses_as_the_table_says) {
  struct row {
    uint8_t fmt;
    hermc_can_frame f;
    int status;
  };
  auto frame = [](uint32_t id, bool ext, uint8_t dlc = 1, bool rtr = false) {
    hermc_can_frame f{};
    f.id = id;
    f.extended = ext;
    f.dlc = dlc;
    f.rtr = rtr;
    return f;
  };
  const std::vector<row> rows = {
    {HERMC_CAN_29BIT, frame(0x0848D250, true), HERMC_CAN_ID_OK},
    {HERMC_CAN_29BIT, frame(0x0848D250, true, 1, true), HERMC_CAN_ID_REMOTE_FRAME},
    {HERMC_CAN_29BIT, frame(0x325, false), HERMC_CAN_ID_STANDARD_ID},
    {HERMC_CAN_11BIT, frame(0x0848D250, true), HERMC_CAN_ID_EXTENDED_ID},
    {HERMC_CAN_29BIT, frame(0x0848D260, true), HERMC_CAN_ID_FOREIGN},
    {HERMC_CAN_29BIT, frame(0x08480250, true), HERMC_CAN_ID_BAD_SOURCE},
    {HERMC_CAN_29BIT, frame(0x084BFE50, true), HERMC_CAN_ID_BAD_SOURCE},
    {HERMC_CAN_29BIT, frame(0x0800D250, true), HERMC_CAN_ID_BAD_DESTINATION},
    {HERMC_CAN_29BIT, frame(0x0848D250, true, 9), HERMC_CAN_ID_BAD_LENGTH},
    {HERMC_CAN_29BIT, frame(0x0848D253, true), HERMC_CAN_ID_BAD_PADDING},
    {HERMC_CAN_11BIT, frame(0x320, false), HERMC_CAN_ID_BAD_SOURCE},
    {HERMC_CAN_11BIT, frame(0x30F, false), HERMC_CAN_ID_BAD_SOURCE},
    {HERMC_CAN_11BIT, frame(0x305, false), HERMC_CAN_ID_BAD_DESTINATION},
    {HERMC_CAN_11BIT, frame(0x3F5, false), HERMC_CAN_ID_OK},
  };
  for (const auto& r : rows) {
    hermc_can_fields x{};
    EXPECT_EQ(hermc_can_decode_frame(r.fmt, &r.f, &x), r.status) << std::hex << r.f.id;
  }
  hermc_can_fields x{};
  auto f = frame(0x0848D250, true);
  ASSERT_EQ(hermc_can_decode_frame(HERMC_CAN_29BIT, &f, &x), HERMC_CAN_ID_OK);
  EXPECT_EQ(x.priority, 2);
  EXPECT_EQ(x.dst, 0x12);
  EXPECT_EQ(x.src, 0x34);
  f = frame(0x3F5, false);
  ASSERT_EQ(hermc_can_decode_frame(HERMC_CAN_11BIT, &f, &x), HERMC_CAN_ID_OK);
  EXPECT_EQ(x.dst, HERMC_CAN_BROADCAST);
}

TEST(hermc_can_id, lanes_are_twice_the_priority_plus_broadcast) {
  EXPECT_EQ(hermc_can_lane(0, 4), 0);
  EXPECT_EQ(hermc_can_lane(0, HERMC_CAN_BROADCAST), 1);
  EXPECT_EQ(hermc_can_lane(3, 4), 6);
  EXPECT_EQ(hermc_can_lane(9, HERMC_CAN_BROADCAST), 15);
}

struct can_fixture {
  hermc_can node;
  sink out;

  explicit can_fixture(uint8_t id, uint8_t fmt = HERMC_CAN_29BIT) {
    EXPECT_EQ(hermc_can_init(&node, fmt, id), HERMC_OK);
  }

  std::vector<hermc_can_frame> send(uint8_t dst, uint8_t prio, const bytes& pkt) {
    EXPECT_EQ(hermc_can_tx_packet(&node, dst, prio, pkt.data(), pkt.size()), HERMC_OK);
    std::vector<hermc_can_frame> frames;
    hermc_can_frame f;
    while (hermc_can_tx_pop(&node, &f))
      frames.push_back(f);
    return frames;
  }

  void receive(const std::vector<hermc_can_frame>& frames) {
    for (const auto& f : frames)
      hermc_can_rx_frame(&node, &f, sink::on_packet, &out);
  }
};

TEST(hermc_can, sends_the_worked_example_and_the_addressed_node_reassembles_it) {
  can_fixture a(3), b(4), c(5);
  auto frames = a.send(4, 2, worked_payload);
  ASSERT_EQ(frames.size(), worked_frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(bytes(frames[i].data, frames[i].data + frames[i].dlc), worked_frames[i]);
    EXPECT_EQ(frames[i].id, 0x08100E50u);
    EXPECT_TRUE(frames[i].extended);
  }
  b.receive(frames);
  c.receive(frames);
  ASSERT_EQ(b.out.packets.size(), 1u);
  EXPECT_EQ(b.out.packets[0], worked_payload);
  EXPECT_EQ(b.out.sources[0], 3);
  EXPECT_TRUE(c.out.packets.empty());
  EXPECT_EQ(c.node.stats.rx_filtered, 4u);
  // A frame claiming to come from the node itself is malformed.
  a.receive(a.send(HERMC_CAN_BROADCAST, 0, {1, 2}));
  EXPECT_EQ(a.node.stats.rx_malformed, 1u);
  EXPECT_TRUE(a.out.packets.empty());
}

TEST(hermc_can, eleven_bit_nodes_exchange_broadcasts) {
  can_fixture a(2, HERMC_CAN_11BIT), b(14, HERMC_CAN_11BIT);
  auto pkt = iota_bytes(HERMC_MAX_PACKET, 7);
  auto frames = a.send(HERMC_CAN_BROADCAST, 1, pkt);
  EXPECT_EQ(frames.size(), hermc_frag_count(pkt.size(), 8));
  EXPECT_EQ(frames[0].id, 0x1F2u);
  EXPECT_FALSE(frames[0].extended);
  b.receive(frames);
  ASSERT_EQ(b.out.packets.size(), 1u);
  EXPECT_EQ(b.out.packets[0], pkt);
}

TEST(hermc_can, keeps_one_tag_sequence_per_destination_and_lane) {
  if (HERMC_CAN_TX_SEQS < 3)
    GTEST_SKIP() << "needs room for three sequences";
  can_fixture a(3);
  auto tag = [](const std::vector<hermc_can_frame>& f) { return f[0].data[0] >> 4 & 3; };
  EXPECT_EQ(tag(a.send(4, 0, {1})), 0);
  EXPECT_EQ(tag(a.send(4, 0, {1})), 1);
  EXPECT_EQ(tag(a.send(HERMC_CAN_BROADCAST, 0, {1})), 0);
  EXPECT_EQ(tag(a.send(4, 1, {1})), 0);
  EXPECT_EQ(tag(a.send(4, 0, {1})), 2);
  EXPECT_EQ(a.node.stats.tag_evictions, 0u);
  // More sequences than HERMC_CAN_TX_SEQS: the least recently used restarts.
  for (uint8_t d = 5; d < 5 + HERMC_CAN_TX_SEQS; ++d)
    a.send(d, 0, {1});
  // Three sequences were in use, so three were forgotten, (4, 0) among them.
  EXPECT_EQ(a.node.stats.tag_evictions, 3u);
  EXPECT_EQ(tag(a.send(4, 0, {1})), 0);
}

TEST(hermc_can, refuses_bad_arguments_and_a_second_packet_while_sending) {
  hermc_can n;
  EXPECT_EQ(hermc_can_init(&n, HERMC_CAN_29BIT, 0), HERMC_ERR_ARG);
  EXPECT_EQ(hermc_can_init(&n, HERMC_CAN_29BIT, 255), HERMC_ERR_ARG);
  EXPECT_EQ(hermc_can_init(&n, HERMC_CAN_11BIT, 15), HERMC_ERR_ARG);
  EXPECT_EQ(hermc_can_init(&n, 7, 1), HERMC_ERR_ARG);
  ASSERT_EQ(hermc_can_init(&n, HERMC_CAN_29BIT, 3), HERMC_OK);
  bytes pkt(HERMC_MAX_PACKET + 1);
  EXPECT_EQ(hermc_can_tx_packet(&n, 4, 0, pkt.data(), pkt.size()), HERMC_ERR_TOO_BIG);
  EXPECT_EQ(hermc_can_tx_packet(&n, 0, 0, pkt.data(), 1), HERMC_ERR_ARG);
  EXPECT_EQ(hermc_can_tx_packet(&n, 3, 0, pkt.data(), 1), HERMC_ERR_ARG);
  EXPECT_EQ(hermc_can_tx_packet(&n, 4, 0, pkt.data(), 20), HERMC_OK);
  EXPECT_EQ(hermc_can_tx_packet(&n, 4, 0, pkt.data(), 20), HERMC_ERR_FULL);
  EXPECT_EQ(n.stats.tx_refused, 4u);
  hermc_can_frame f;
  while (hermc_can_tx_pop(&n, &f)) {
  }
  EXPECT_FALSE(hermc_can_tx_pop(&n, &f));
  EXPECT_EQ(hermc_can_tx_packet(&n, 4, 0, pkt.data(), 20), HERMC_OK);
}

TEST(hermc_can, counts_refused_frames_by_verdict) {
  can_fixture a(4);
  hermc_can_frame f{};
  f.id = 0x0848D260; // foreign tag
  f.extended = 1;
  hermc_can_rx_frame(&a.node, &f, sink::on_packet, &a.out);
  f.extended = 0;
  hermc_can_rx_frame(&a.node, &f, sink::on_packet, &a.out);
  EXPECT_EQ(a.node.stats.rx_malformed, 2u);
  EXPECT_EQ(a.node.stats.rx_by_status[HERMC_CAN_ID_FOREIGN], 1u);
  EXPECT_EQ(a.node.stats.rx_by_status[HERMC_CAN_ID_STANDARD_ID], 1u);
  EXPECT_EQ(a.node.stats.rx_frames, 0u);
}

} // namespace
