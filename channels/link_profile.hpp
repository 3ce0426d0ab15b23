#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "caf/meta/type_name.hpp"

namespace herm {

/// Physical characteristics of one link, as the upper layers see them.
/// Units: bandwidth in bit/s, MTU in bytes of frame payload.
struct link_profile {
  /// Profile name, e.g. "can2.0", "ethernet", "ieee1394a".
  std::string name;
  /// Nominal bit rate in bit/s; must be > 0.
  uint64_t bandwidth_bps = 0;
  /// Largest frame payload the link carries, in bytes; must be > 0.
  uint32_t mtu = 0;
  /// True for buses and segments (CAN, Ethernet, IEEE 1394) where a channel
  /// hears many peers; false for point-to-point lines (RS232C, USB).
  bool multi_access = false;
  /// The per-link delay coefficient c of the paper's formula (1).
  double delay_coef = 1.0;
  /// Per-frame overhead on the medium in bits (headers, CRC, gaps); used by
  /// emulated media for pacing and by benchmarks for efficiency figures.
  uint32_t frame_overhead_bits = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, link_profile& x) {
  return f(caf::meta::type_name("link_profile"), x.name, x.bandwidth_bps,
           x.mtu, x.multi_access, x.delay_coef, x.frame_overhead_bits);
}

bool operator==(const link_profile& x, const link_profile& y);

/// Static routing cost of a link: round(10 * c * log10(10^9 / B)), at least 1.
/// Reproduces Table 1 of the HERM paper exactly for c = 1 (19, 3, 4, 1, 30,
/// 10, 47). See docs/architecture.md for how this reconciles with formula (1).
uint32_t link_cost(uint64_t bandwidth_bps, double delay_coef = 1.0);

/// Static cost of the profile's link (see link_cost).
uint32_t link_cost(const link_profile& p);

/// Cost of carrying a message of `size` bytes over the link: the static cost
/// times the number of frames, ceil(size / mtu), with at least one frame.
uint64_t message_cost(const link_profile& p, uint64_t size);

/// The built-in profiles of Table 1 (usb1.1, usb2.0, ieee1394a, ieee1394b,
/// can2.0, ethernet, rs232c), in the paper's order.
const std::vector<link_profile>& builtin_profiles();

/// Looks up a built-in profile by name; returns nullptr if unknown.
const link_profile* find_profile(const std::string& name);

} // namespace herm
