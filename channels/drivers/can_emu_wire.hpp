#pragma once

// Datagram format of the emulated CAN bus (link kind "can" with interface
// "emu:DIR", channels/drivers/can.cpp). Pure functions without clock or I/O.
//
// A station that wins arbitration sends one datagram per frame to every
// other station's unix datagram socket: a 16-byte header followed by the
// frame exactly as SocketCAN hands it to a program, a struct can_frame
// (CAN_MTU = 16 bytes) or a struct canfd_frame (CANFD_MTU = 72 bytes). As
// with SocketCAN, the size alone tells the two apart. The header is the
// emulated medium's datagram head (emu_wire.hpp), little endian; the frame
// behind it is in host byte order, as SocketCAN's is (all stations of a bus
// live on one machine).
//
// Bounds per call: O(1), no allocation; encode and decode touch exactly
// header_size bytes, check reads nothing when the datagram is shorter.

#include <cstddef>
#include <cstdint>
#include <cstring>

#include <linux/can.h>

#include "channels/drivers/emu_wire.hpp"

namespace herm::can::wire {

constexpr uint16_t magic = 0x4843; // "CH" in little-endian memory
constexpr uint8_t version = 1;
constexpr size_t header_size = 16;

/// Flags; a receiver refuses unknown bits.
enum flag : uint8_t {
  /// The frame was destroyed by an error on the bus: receivers report an
  /// error frame and drop the data (the sender retransmits).
  flag_error = 0x01,
  flag_mask = 0x01,
};

/// A receiver refuses a datagram whose delivery time lies further ahead than
/// this (the longest frame at the lowest bit rate plus slack): it would pin
/// a slot for ever.
constexpr int64_t max_hold_ns = 5'000'000'000;

struct header {
  uint16_t magic = wire::magic;
  uint8_t version = wire::version;
  uint8_t flags = 0;
  /// Must be 0.
  uint32_t reserved = 0;
  /// CLOCK_MONOTONIC time in ns at which the frame's transmission ends: the
  /// receiver hands it up then, so every station hears frames in bus order.
  int64_t deliver_at_ns = 0;
};

static_assert(header_size == emu::datagram_head_size);

/// Writes `h` to `out[0..header_size)`.
inline void encode(const header& h, uint8_t* out) {
  emu::put_head({h.magic, h.version, h.flags, h.reserved, h.deliver_at_ns},
                out);
}

/// Reads a header from `in[0..header_size)` without checking it.
inline header decode(const uint8_t* in) {
  auto g = emu::get_head(in);
  header h;
  h.magic = g.magic;
  h.version = g.version;
  h.flags = g.flags;
  h.reserved = g.word;
  h.deliver_at_ns = g.deliver_at_ns;
  return h;
}

enum class status {
  ok,
  too_short,     ///< shorter than the header
  bad_magic,     ///< not an emulated CAN datagram
  bad_version,   ///< another version of this format
  bad_header,    ///< unknown flags or reserved field not 0
  bad_size,      ///< the frame is neither CAN_MTU nor CANFD_MTU bytes
  too_far_ahead, ///< deliver_at more than max_hold_ns in the future
};

static_assert(static_cast<int>(status::bad_header)
              == static_cast<int>(emu::head_status::bad_header));

inline const char* to_string(status x) {
  switch (x) {
    case status::ok: return "ok";
    case status::too_short: return "datagram shorter than the header";
    case status::bad_magic: return "bad magic (not an emulated CAN datagram)";
    case status::bad_version: return "unsupported emulated CAN wire version";
    case status::bad_header: return "unknown flags or reserved bits set";
    case status::bad_size:
      return "frame size is neither CAN_MTU (16) nor CANFD_MTU (72)";
    case status::too_far_ahead: return "delivery time too far in the future";
  }
  return "unknown";
}

/// Checks a datagram of `size` bytes (its real size: receivers use
/// MSG_TRUNC). `data` holds at least min(size, header_size) bytes. Fills
/// `hdr` for every status but too_short.
inline status check(const uint8_t* data, size_t size, int64_t now_ns,
                    header& hdr) {
  auto head = emu::check_head(data, size, magic, version, flag_mask,
                              0xFFFFFFFF);
  if (head == emu::head_status::too_short)
    return status::too_short;
  hdr = decode(data);
  if (head != emu::head_status::ok)
    return static_cast<status>(head);
  if (size != header_size + CAN_MTU && size != header_size + CANFD_MTU)
    return status::bad_size;
  if (emu::held_too_long(hdr.deliver_at_ns, now_ns, max_hold_ns))
    return status::too_far_ahead;
  return status::ok;
}

} // namespace herm::can::wire
