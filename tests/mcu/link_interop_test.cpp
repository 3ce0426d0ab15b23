// The C client's link layer against HERM's C++ reference, byte for byte:
// serial framing (channels/drivers/serial_framing.hpp), the fragmenter and
// reassembler (channels/fragmenter.hpp, reassembler.hpp) and the CAN
// identifier layout (channels/drivers/can_id.hpp). Random inputs come from
// fixed seeds and bounded counts, so every run checks the same cases.

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "channels/drivers/can_id.hpp"
#include "channels/drivers/serial_framing.hpp"
#include "channels/fragmenter.hpp"
#include "channels/reassembler.hpp"
#include "hermc_can.h"
#include "hermc_link.h"
#include "tests/mcu/mcu_bytes.hpp"

namespace {

using bytes = std::vector<uint8_t>;
using herm::byte_buffer;

using sink = mcu_test::packet_sink;

std::vector<bytes> random_packets(uint32_t seed, size_t count, size_t max) {
  std::mt19937 rng(seed);
  std::vector<bytes> out;
  for (size_t i = 0; i < count; ++i) {
    bytes p(rng() % (max + 1));
    for (auto& b : p)
      // Many zeros and escape-worthy bytes, to exercise COBS and escapes.
      b = rng() % 4 == 0 ? uint8_t{0} : static_cast<uint8_t>(rng() % 8 == 0 ? 0x11 : rng());
    out.push_back(std::move(p));
  }
  return out;
}

// The C++ side of a serial line: its fragmenter at HERMC_MTU, then the
// framing, with a leading delimiter before each packet (the line was idle:
// the test drains the C client between packets, so it sends one too).
bytes cpp_wire(herm::fragmenter& frag, const bytes& pkt, bool escaped) {
  bytes wire;
  bool first = true;
  frag.split(pkt.data(), pkt.size(), [&](const uint8_t* f, size_t n) {
    herm::serial::append_frame(wire, f, n, first, escaped);
    first = false;
  });
  return wire;
}

bytes c_wire(hermc_link_tx& tx, const bytes& pkt) {
  EXPECT_EQ(hermc_link_tx_packet(&tx, pkt.data(), pkt.size()), HERMC_OK);
  bytes out(hermc_link_tx_pending(&tx));
  hermc_link_tx_pop(&tx, out.data(), out.size());
  return out;
}

// The C++ receiving side: decoder, then reassembler.
struct cpp_rx {
  herm::serial::decoder dec;
  herm::reassembler reasm;
  std::vector<bytes> packets;

  explicit cpp_rx(bool escaped)
    : dec(HERMC_MTU, escaped), reasm(herm::reassembly_limits{}) {
  }

  void feed(const bytes& wire) {
    byte_buffer out;
    auto now = std::chrono::steady_clock::time_point{};
    dec.feed(
      wire.data(), wire.size(),
      [&](const uint8_t* f, size_t n) {
        if (reasm.push(1, f, n, now, out) == herm::reassembler::result::complete)
          packets.push_back(out);
      },
      [](herm::serial::rx_error) {});
  }
};

class serial_interop : public testing::TestWithParam<bool> {};

TEST_P(serial_interop, both_sides_put_the_same_bytes_on_the_wire_and_read_each_other) {
  const bool escaped = GetParam();
  // Random bytes with many 0x11 and 0x00: escaped, the largest packets can
  // exceed the ring, so the test keeps to those that fit.
  auto packets = random_packets(17, 400, escaped ? HERMC_MAX_PACKET / 2 : HERMC_MAX_PACKET);
  herm::fragmenter frag(HERMC_MTU);
  hermc_link_tx tx;
  hermc_link_tx_init(&tx, escaped);
  hermc_link_rx rx;
  hermc_link_rx_init(&rx, escaped);
  sink c_out;
  cpp_rx cpp(escaped);
  for (const auto& p : packets) {
    auto from_cpp = cpp_wire(frag, p, escaped);
    auto from_c = c_wire(tx, p);
    ASSERT_EQ(from_c, from_cpp) << "packet of " << p.size() << " bytes";
    hermc_link_rx_feed(&rx, from_cpp.data(), from_cpp.size(), sink::on_packet, &c_out);
    cpp.feed(from_c);
  }
  EXPECT_TRUE(c_out.packets == packets);
  EXPECT_TRUE(cpp.packets == packets);
  EXPECT_EQ(rx.frame_stats.frames, cpp.dec.stats().frames);
}

TEST_P(serial_interop, a_damaged_stream_is_judged_alike_and_nothing_unsent_is_delivered) {
  const bool escaped = GetParam();
  auto packets = random_packets(23, 300, HERMC_MAX_PACKET);
  herm::fragmenter frag(HERMC_MTU);
  bytes wire;
  for (const auto& p : packets) {
    auto w = cpp_wire(frag, p, escaped);
    wire.insert(wire.end(), w.begin(), w.end());
  }
  std::mt19937 rng(99);
  for (size_t i = 0; i < wire.size(); ++i) {
    auto r = rng() % 400;
    if (r == 0)
      wire[i] ^= static_cast<uint8_t>(1u << (rng() % 8));
    else if (r == 1)
      wire[i] = 0; // a delimiter out of place
    else if (r == 2)
      wire[i] = static_cast<uint8_t>(rng());
  }
  hermc_link_rx rx;
  hermc_link_rx_init(&rx, escaped);
  sink c_out;
  hermc_link_rx_feed(&rx, wire.data(), wire.size(), sink::on_packet, &c_out);
  cpp_rx cpp(escaped);
  cpp.feed(wire);
  using herm::serial::rx_error;
  const auto& s = cpp.dec.stats();
  EXPECT_EQ(rx.frame_stats.frames, s.frames);
  EXPECT_EQ(rx.frame_stats.idle, s.idle);
  EXPECT_EQ(rx.frame_stats.bad_cobs, s.count(rx_error::bad_cobs));
  EXPECT_EQ(rx.frame_stats.too_short, s.count(rx_error::too_short));
  EXPECT_EQ(rx.frame_stats.oversized, s.count(rx_error::oversized));
  EXPECT_EQ(rx.frame_stats.bad_crc, s.count(rx_error::bad_crc));
  EXPECT_EQ(rx.frame_stats.bad_escape, s.count(rx_error::bad_escape));
  EXPECT_GT(s.malformed(), 0u);
  // Every delivered packet was sent, in order.
  size_t next = 0;
  for (const auto& p : c_out.packets) {
    while (next < packets.size() && packets[next] != p)
      ++next;
    ASSERT_LT(next, packets.size()) << "delivered a packet that was not sent";
    ++next;
  }
  EXPECT_GT(c_out.packets.size(), packets.size() / 2);
  // The C client delivers every packet the C++ reassembler delivers. It may
  // deliver more: it drops a consecutive frame without its packet at once,
  // where the C++ reassembler stashes it until the timeout (no time passes
  // here) and places it into the next packet with the same tag, four
  // packets later, which then fails its CRC-32 (bad_checksum).
  size_t j = 0;
  for (const auto& p : cpp.packets) {
    while (j < c_out.packets.size() && c_out.packets[j] != p)
      ++j;
    ASSERT_LT(j, c_out.packets.size()) << "the C client missed a packet C++ delivered";
    ++j;
  }
  EXPECT_LE(c_out.packets.size() - cpp.packets.size(), cpp.reasm.stats().bad_checksum);
  std::printf("damaged stream: %zu packets sent, C client delivered %zu, C++ %zu "
              "(C++ bad_checksum %llu, C lost %u orphans %u)\n",
              packets.size(), c_out.packets.size(), cpp.packets.size(),
              static_cast<unsigned long long>(cpp.reasm.stats().bad_checksum),
              rx.reasm.stats.lost, rx.reasm.stats.orphans);
}

INSTANTIATE_TEST_SUITE_P(modes, serial_interop, testing::Values(false, true),
                         [](const auto& p) { return p.param ? "escaped" : "plain"; });

// -- CAN --------------------------------------------------------------------------------

herm::can::id_format cpp_format(uint8_t fmt) {
  return fmt == HERMC_CAN_11BIT ? herm::can::id_format::std11 : herm::can::id_format::ext29;
}

int c_status(herm::can::id_status s) {
  using herm::can::id_status;
  switch (s) {
    case id_status::ok: return HERMC_CAN_ID_OK;
    case id_status::remote_frame: return HERMC_CAN_ID_REMOTE_FRAME;
    case id_status::standard_id: return HERMC_CAN_ID_STANDARD_ID;
    case id_status::extended_id: return HERMC_CAN_ID_EXTENDED_ID;
    case id_status::foreign: return HERMC_CAN_ID_FOREIGN;
    case id_status::bad_source: return HERMC_CAN_ID_BAD_SOURCE;
    case id_status::bad_destination: return HERMC_CAN_ID_BAD_DESTINATION;
    case id_status::bad_length: return HERMC_CAN_ID_BAD_LENGTH;
    case id_status::bad_padding: return HERMC_CAN_ID_BAD_PADDING;
    default: return -1;
  }
}

TEST(can_interop, identifiers_encode_and_decode_as_the_cpp_layout) {
  std::mt19937 rng(5);
  for (uint8_t fmt : {HERMC_CAN_29BIT, HERMC_CAN_11BIT}) {
    auto f = cpp_format(fmt);
    auto max = herm::can::max_node(f);
    for (int i = 0; i < 20000; ++i) {
      // Valid fields: encoding agrees.
      hermc_can_fields x{static_cast<uint8_t>(rng() % 8),
                         static_cast<uint8_t>(rng() % 5 == 0 ? HERMC_CAN_BROADCAST
                                                             : 1 + rng() % max),
                         static_cast<uint8_t>(1 + rng() % max)};
      herm::can::frame_id y;
      y.priority = x.priority;
      y.dst = x.dst == HERMC_CAN_BROADCAST ? herm::can::broadcast_node(f) : x.dst;
      y.src = x.src;
      ASSERT_EQ(hermc_can_encode_id(fmt, &x), herm::can::encode_id(f, y));
      EXPECT_EQ(hermc_can_lane(x.priority, x.dst), herm::can::lane_of(f, y));
      // Any identifier, flags and length: the same verdict and fields.
      hermc_can_frame c{};
      c.extended = rng() % 2;
      c.rtr = rng() % 16 == 0;
      c.dlc = static_cast<uint8_t>(rng() % 10);
      uint32_t raw = rng();
      if (rng() % 2 == 0) // mostly HERM's tag, so the deeper checks run
        raw = (raw & ~0x3F0u) | HERMC_CAN_TAG << 4;
      c.id = raw & (c.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
      canid_t cid = c.id | (c.extended ? CAN_EFF_FLAG : 0u) | (c.rtr ? CAN_RTR_FLAG : 0u);
      herm::can::frame_id got;
      size_t payload = 0;
      auto st = herm::can::decode_frame(f, cid, c.dlc, false, got, payload);
      hermc_can_fields mine{};
      ASSERT_EQ(hermc_can_decode_frame(fmt, &c, &mine), c_status(st)) << std::hex << cid;
      if (st == herm::can::id_status::ok) {
        EXPECT_EQ(mine.priority, got.priority);
        EXPECT_EQ(mine.src, got.src);
        EXPECT_EQ(mine.dst == HERMC_CAN_BROADCAST ? herm::can::broadcast_node(f) : mine.dst,
                  got.dst);
      }
    }
  }
}

TEST(can_interop, fragments_match_the_cpp_fragmenter_and_each_side_reassembles_the_other) {
  static_assert(HERMC_CAN_TX_SEQS >= 4, "four (destination, lane) sequences");
  auto packets = random_packets(31, 300, HERMC_MAX_PACKET);
  std::mt19937 rng(8);
  hermc_can c_node;
  ASSERT_EQ(hermc_can_init(&c_node, HERMC_CAN_29BIT, 3), HERMC_OK);
  hermc_can c_peer;
  ASSERT_EQ(hermc_can_init(&c_peer, HERMC_CAN_29BIT, 4), HERMC_OK);
  herm::fragmenter cpp_frag(8);
  herm::reassembler cpp_reasm{herm::reassembly_limits{}};
  sink c_out;
  std::vector<bytes> cpp_out;
  auto now = std::chrono::steady_clock::time_point{};
  for (const auto& p : packets) {
    uint8_t dst = rng() % 2 == 0 ? 4 : HERMC_CAN_BROADCAST;
    uint8_t prio = static_cast<uint8_t>(rng() % 2 == 0 ? 0 : 3);
    uint8_t lane = hermc_can_lane(prio, dst);
    // C node 3 -> C++ reassembler; frames compared with the C++ fragmenter's.
    ASSERT_EQ(hermc_can_tx_packet(&c_node, dst, prio, p.data(), p.size()), HERMC_OK);
    std::vector<bytes> cpp_frames;
    herm::link_addr cpp_dst = dst == HERMC_CAN_BROADCAST ? herm::broadcast_addr : dst;
    cpp_frag.split(cpp_dst, lane, p.data(), p.size(), [&](const uint8_t* f, size_t n) {
      cpp_frames.emplace_back(f, f + n);
    });
    hermc_can_frame cf;
    size_t i = 0;
    while (hermc_can_tx_pop(&c_node, &cf)) {
      ASSERT_LT(i, cpp_frames.size());
      ASSERT_EQ(bytes(cf.data, cf.data + cf.dlc), cpp_frames[i]) << "frame " << i;
      herm::can::frame_id id;
      size_t payload = 0;
      ASSERT_EQ(herm::can::decode_frame(herm::can::id_format::ext29, cf.id | CAN_EFF_FLAG,
                                        cf.dlc, false, id, payload),
                herm::can::id_status::ok);
      EXPECT_EQ(herm::can::lane_of(herm::can::id_format::ext29, id), lane);
      byte_buffer out;
      if (cpp_reasm.push(id.src, lane, cf.data, cf.dlc, now, out)
          == herm::reassembler::result::complete)
        cpp_out.push_back(out);
      ++i;
    }
    ASSERT_EQ(i, cpp_frames.size());
    // The C++ fragmenter's frames -> C node 4, as if node 3 sent them.
    for (const auto& f : cpp_frames) {
      hermc_can_frame in{};
      hermc_can_fields x{prio, dst, 3};
      in.id = hermc_can_encode_id(HERMC_CAN_29BIT, &x);
      in.extended = 1;
      in.dlc = static_cast<uint8_t>(f.size());
      std::copy(f.begin(), f.end(), in.data);
      hermc_can_rx_frame(&c_peer, &in, sink::on_packet, &c_out);
    }
  }
  EXPECT_TRUE(cpp_out == packets);
  EXPECT_TRUE(c_out.packets == packets);
  EXPECT_EQ(c_node.stats.tag_evictions, 0u);
}

} // namespace
