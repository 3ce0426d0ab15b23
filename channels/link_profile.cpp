#include "channels/link_profile.hpp"

#include <cmath>

namespace herm {

bool operator==(const link_profile& x, const link_profile& y) {
  return x.name == y.name && x.bandwidth_bps == y.bandwidth_bps
         && x.mtu == y.mtu && x.multi_access == y.multi_access
         && x.delay_coef == y.delay_coef
         && x.frame_overhead_bits == y.frame_overhead_bits;
}

uint32_t link_cost(uint64_t bandwidth_bps, double delay_coef) {
  if (bandwidth_bps == 0 || !(delay_coef > 0))
    return UINT32_MAX;
  auto raw = 10.0 * delay_coef * std::log10(1e9 / double(bandwidth_bps));
  auto rounded = std::lround(raw);
  return rounded < 1 ? 1u : static_cast<uint32_t>(rounded);
}

uint32_t link_cost(const link_profile& p) {
  return link_cost(p.bandwidth_bps, p.delay_coef);
}

uint64_t message_cost(const link_profile& p, uint64_t size) {
  if (p.mtu == 0)
    return UINT64_MAX;
  auto frames = size == 0 ? 1 : (size + p.mtu - 1) / p.mtu;
  return uint64_t{link_cost(p)} * frames;
}

const std::vector<link_profile>& builtin_profiles() {
  // Frame overheads: USB full/high speed bulk packet (sync, PID, CRC16,
  // EOP: ~ 3 bytes plus token/handshake ~ 10 bytes), IEEE 1394 asynchronous
  // packet header and CRCs (20 bytes), CAN 2.0A worst case without stuffing
  // (47 bits), Ethernet (preamble 8 + header 14 + FCS 4 + gap 12 = 38 bytes
  // plus IPv4/UDP 28), RS232C 8N1 counts start and stop bits per byte
  // separately (see the serial channel), so 0 here.
  static const std::vector<link_profile> profiles{
    {"usb1.1", 12'000'000, 1023, false, 1.0, 13 * 8},
    {"usb2.0", 480'000'000, 1024, false, 1.0, 13 * 8},
    {"ieee1394a", 400'000'000, 4096, true, 1.0, 20 * 8},
    {"ieee1394b", 800'000'000, 8192, true, 1.0, 20 * 8},
    {"can2.0", 1'000'000, 8, true, 1.0, 47},
    {"ethernet", 100'000'000, 1500, true, 1.0, 66 * 8},
    {"rs232c", 19'200, 32, false, 1.0, 0},
  };
  return profiles;
}

const link_profile* find_profile(const std::string& name) {
  for (auto& p : builtin_profiles())
    if (p.name == name)
      return &p;
  return nullptr;
}

} // namespace herm
