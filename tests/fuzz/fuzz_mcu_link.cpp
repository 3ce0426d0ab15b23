// Fuzz target: the receive path of the C client's link layer
// (apps/mcu/client/hermc_link.h, hermc_can.h): line bytes -> COBS/CRC-16
// frames -> fragment reassembly -> packets, and CAN frames -> packets.
//
// Input: options (1 byte: bit 0 escaped mode, bits 1..7 a chunk size), then
// the line bytes; the same bytes are also read as CAN frames (4 bytes of
// identifier, 1 byte flags and length, up to 8 data bytes each).
//
// Properties checked for every input:
// 1. The frame decoder judges every run exactly as HERM's C++ decoder
//    (channels/drivers/serial_framing.hpp) does: the same counts of frames,
//    idle runs and each error.
// 2. Decoding does not depend on how the bytes are cut into feeds: whole and
//    in chunks give the same packets and counters.
// 3. Every packet delivered has at most HERMC_MAX_PACKET bytes, reassembly
//    never holds more packets than it has slots, and a delivered packet sent
//    back through hermc_link_tx reaches a fresh receiver unchanged.
// 4. CAN: every packet has at most HERMC_MAX_PACKET bytes and comes from a
//    valid source other than the node itself; every frame is counted once.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "channels/drivers/serial_framing.hpp"
#include "hermc_can.h"
#include "hermc_link.h"
#include "tests/fuzz/fuzz_support.hpp"
#include "tests/mcu/mcu_bytes.hpp"

namespace {

using bytes = std::vector<uint8_t>;

using sink = mcu_test::packet_sink;

bool same_stats(const hermc_link_rx& a, const hermc_link_rx& b) {
  return std::memcmp(&a.frame_stats, &b.frame_stats, sizeof a.frame_stats) == 0
         && std::memcmp(&a.reasm.stats, &b.reasm.stats, sizeof a.reasm.stats) == 0;
}

void check_serial(bool escaped, size_t chunk, const uint8_t* data, size_t size) {
  static hermc_link_rx whole;
  static hermc_link_rx cut;
  hermc_link_rx_init(&whole, escaped);
  hermc_link_rx_init(&cut, escaped);
  sink a;
  sink b;
  hermc_link_rx_feed(&whole, data, size, sink::on_packet, &a);
  for (size_t pos = 0; pos < size; pos += chunk) {
    size_t n = size - pos < chunk ? size - pos : chunk;
    hermc_link_rx_feed(&cut, data + pos, n, sink::on_packet, &b);
    HERM_FUZZ_CHECK(hermc_reasm_pending(&cut.reasm) <= HERMC_RX_SLOTS);
  }
  HERM_FUZZ_CHECK(a.packets == b.packets);
  HERM_FUZZ_CHECK(same_stats(whole, cut));

  herm::serial::decoder ref(HERMC_MTU, escaped);
  ref.feed(data, size, [](const uint8_t*, size_t) {}, [](herm::serial::rx_error) {});
  using herm::serial::rx_error;
  const auto& s = ref.stats();
  const auto& f = whole.frame_stats;
  HERM_FUZZ_CHECK(f.frames == s.frames && f.idle == s.idle);
  HERM_FUZZ_CHECK(f.bad_cobs == s.count(rx_error::bad_cobs));
  HERM_FUZZ_CHECK(f.too_short == s.count(rx_error::too_short));
  HERM_FUZZ_CHECK(f.oversized == s.count(rx_error::oversized));
  HERM_FUZZ_CHECK(f.bad_crc == s.count(rx_error::bad_crc));
  HERM_FUZZ_CHECK(f.bad_escape == s.count(rx_error::bad_escape));
  HERM_FUZZ_CHECK(whole.reasm.stats.packets == a.packets.size());

  for (const auto& p : a.packets) {
    HERM_FUZZ_CHECK(p.size() <= HERMC_MAX_PACKET);
    static hermc_link_tx tx;
    static hermc_link_rx back;
    hermc_link_tx_init(&tx, escaped);
    hermc_link_rx_init(&back, escaped);
    int rc = hermc_link_tx_packet(&tx, p.data(), p.size());
    if (rc == HERMC_ERR_TOO_BIG)
      continue; // escaped and full of bytes to escape: refused, not sent
    HERM_FUZZ_CHECK(rc == HERMC_OK);
    bytes wire(hermc_link_tx_pending(&tx));
    hermc_link_tx_pop(&tx, wire.data(), wire.size());
    sink c;
    hermc_link_rx_feed(&back, wire.data(), wire.size(), sink::on_packet, &c);
    HERM_FUZZ_CHECK(c.packets.size() == 1 && c.packets[0] == p);
  }
}

void check_can(bool eleven, const uint8_t* data, size_t size) {
  static hermc_can node;
  const uint8_t fmt = eleven ? HERMC_CAN_11BIT : HERMC_CAN_29BIT;
  const uint8_t self = 3;
  HERM_FUZZ_CHECK(hermc_can_init(&node, fmt, self) == HERMC_OK);
  sink out;
  size_t frames = 0;
  size_t pos = 0;
  uint32_t now = 0;
  while (size - pos >= 5) {
    hermc_can_frame f{};
    f.id = static_cast<uint32_t>(data[pos]) | static_cast<uint32_t>(data[pos + 1]) << 8
           | static_cast<uint32_t>(data[pos + 2]) << 16
           | static_cast<uint32_t>(data[pos + 3]) << 24;
    uint8_t flags = data[pos + 4];
    pos += 5;
    f.extended = flags & 0x01;
    f.rtr = (flags & 0x02) != 0 && (flags & 0x04) != 0;
    f.id &= f.extended ? 0x1FFFFFFFu : 0x7FFu;
    f.dlc = static_cast<uint8_t>(flags >> 4 & 0x0F);
    size_t n = f.dlc < 8 ? f.dlc : 8;
    if (n > size - pos)
      n = size - pos;
    std::memcpy(f.data, data + pos, n);
    pos += n;
    if (f.dlc <= 8)
      f.dlc = static_cast<uint8_t>(n);
    hermc_can_rx_frame(&node, &f, sink::on_packet, &out);
    ++frames;
    if ((flags & 0x08) != 0)
      hermc_can_tick(&node, now += 1000);
    HERM_FUZZ_CHECK(hermc_reasm_pending(&node.reasm) <= HERMC_CAN_RX_SLOTS);
  }
  const auto& s = node.stats;
  HERM_FUZZ_CHECK(s.rx_frames + s.rx_filtered + s.rx_malformed == frames);
  HERM_FUZZ_CHECK(node.reasm.stats.packets == out.packets.size());
  for (size_t i = 0; i < out.packets.size(); ++i) {
    HERM_FUZZ_CHECK(out.packets[i].size() <= HERMC_MAX_PACKET);
    HERM_FUZZ_CHECK(out.sources[i] >= 1 && out.sources[i] <= hermc_can_max_node(fmt));
    HERM_FUZZ_CHECK(out.sources[i] != self);
  }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1)
    return 0;
  const bool escaped = (data[0] & 0x01) != 0;
  size_t chunk = data[0] >> 1;
  if (chunk == 0)
    chunk = 1;
  check_serial(escaped, chunk, data + 1, size - 1);
  check_can(escaped, data + 1, size - 1);
  return 0;
}
