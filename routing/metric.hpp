#pragma once

// Routing metrics per packet-size class.
//
// Formula (1) of the paper makes a path's cost depend on the message size:
// each hop costs cost(B, c) * ceil(D / M). HERM computes routes for a few
// fixed size classes, each its own distance-vector topology with its own
// metric, feasibility distance and selected route. A packet carries its size
// class and every hop routes it in that class, so each class is loop-free on
// its own (Babel's feasibility condition) and the choice of path still
// follows the size (a 1,000-byte message avoids the CAN path that an 8-byte
// one takes). Class 0 (8 bytes) reproduces the paper's static costs: ceil(D/M)
// is 1 on every Table 1 link.

#include <array>
#include <cstdint>

#include "channels/link_profile.hpp"

namespace herm {

/// Number of packet-size classes.
constexpr size_t size_classes = 4;

/// Largest packet (bytes of network payload) of each class.
constexpr std::array<uint32_t, size_classes> size_class_bytes{8, 64, 1024,
                                                              65536};

/// The class of a packet of `bytes`: the smallest whose bound holds it (the
/// last class for anything larger).
uint8_t size_class_of(size_t bytes);

using metric = uint32_t;

/// Unreachable. Also the retraction of a route.
constexpr metric infinite_metric = 0xFFFFFFFF;

/// A route's (or link's) metric in every class.
using metric_vector = std::array<metric, size_classes>;

/// All classes unreachable.
constexpr metric_vector infinite_metrics{infinite_metric, infinite_metric,
                                         infinite_metric, infinite_metric};

/// Saturating sum: infinite if either is, or if the sum would reach it.
metric add_metric(metric x, metric y);

metric_vector add_metrics(const metric_vector& x, const metric_vector& y);

/// A link's metric in each class: link_cost(p) * ceil(size_class_bytes[k] /
/// p.mtu), saturating.
metric_vector link_metrics(const link_profile& p);

/// One-byte code of a link kind for forwarding lists ("CAN2.0-Ethernet").
enum class link_code : uint8_t {
  unknown = 0,
  usb11 = 1,
  usb20 = 2,
  ieee1394a = 3,
  ieee1394b = 4,
  can20 = 5,
  ethernet = 6,
  rs232c = 7,
};

/// The code of a profile name ("can2.0" -> can20); unknown otherwise.
link_code link_code_of(const std::string& profile_name);

/// The paper's spelling: "CAN2.0", "Ethernet", "IEEE1394a", "USB1.1",
/// "RS232C", "?" for unknown.
const char* to_string(link_code x);

} // namespace herm
