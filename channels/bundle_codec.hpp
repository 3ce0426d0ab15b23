#pragma once

// The bundle codec: several small packets in one frame (docs/protocol.md,
// "Bundles"). Pure code, no state. The sender's policy (which packets wait
// for a bundle and when it leaves) is channels/bundling_port.hpp's.
//
// Contract: bundle_append is O(size) time and appends at most
// bundle_cost(size) + 1 bytes to the caller's buffer (never past `mtu`);
// bundle_decode is O(frame size) time, allocates nothing, reads only
// within the frame and emits nothing at all for a malformed bundle.

#include <cstddef>
#include <cstdint>
#include <functional>

#include "channels/messages.hpp"

namespace herm {

/// First byte of a bundle frame: type "single" with its reserved low bits
/// set to 0001 (tag 0). A bundle holds two or more packets, each as a
/// LEB128 length (1 to 3 bytes) and its bytes: `01 | len1 | pkt1 | len2 |
/// pkt2 ...`. A sender bundles small packets to one destination that are
/// waiting at the same time, so that one datagram (one system call, one
/// kernel round) carries several: docs/protocol.md, "Bundles".
constexpr uint8_t bundle_header = 0x01;

/// Smallest MTU on which a channel bundles (CAN's 8 and 64 bytes and
/// serial's 32 would gain nothing).
constexpr uint32_t min_bundle_mtu = 256;

/// Appends one packet to a bundle being built in `frame` (starting it with
/// the header when empty). Returns false, leaving `frame` unchanged, when
/// the packet would make the frame longer than `mtu` or is empty (or above
/// 2^21 - 1 bytes, which a length field cannot announce).
bool bundle_append(byte_buffer& frame, uint32_t mtu, const uint8_t* data,
                   size_t size);

/// Bytes bundle_append adds for a packet of `size` bytes (length field and
/// packet; the header byte of an empty frame not included).
size_t bundle_cost(size_t size) noexcept;

/// Decodes a bundle frame (its first byte is bundle_header) and calls
/// `emit(const uint8_t*, size_t)` for each packet, in order. Checks the
/// whole frame before the first call: on a malformed bundle (a length
/// running past the end, an empty packet, a packet above `max_packet`,
/// fewer than two packets, a non-minimal length) nothing is emitted and
/// the result is false.
bool bundle_decode(const uint8_t* data, size_t size, size_t max_packet,
                   const std::function<void(const uint8_t*, size_t)>& emit);

} // namespace herm
