#pragma once

// Identifier layout of HERM frames on CAN (link kind "can",
// channels/drivers/can.cpp). Pure code: no clock, no I/O, so the driver,
// its tests and fuzzers share one definition. Specified in
// docs/protocol.md, section "CAN identifier layout".
//
// 29-bit (CAN 2.0B extended) identifier, the default:
//
//   bits 28..26  priority      0..7, the message priority (lower is more
//                              urgent: it wins arbitration)
//   bits 25..18  destination   node 1..254, 0xFF = broadcast
//   bits 17..10  source        node 1..254
//   bits  9..4   protocol tag  0b100101 = HERM version 1; anything else is
//                              another protocol on a shared bus
//   bits  3..0   padding       CAN FD only: bytes of padding at the end of
//                              the data field (0 in classic frames)
//
// 11-bit (CAN 2.0A standard) identifier, option id_format=11bit, for buses
// that take standard identifiers only. It has no room for a protocol tag, so
// the bus must carry HERM alone, and no room for padding, so no CAN FD:
//
//   bits 10..8   priority      0..7
//   bits  7..4   destination   node 1..14, 0xF = broadcast
//   bits  3..0   source        node 1..14
//
// Because priority sits in the most significant bits and CAN arbitration
// lets the numerically lowest identifier win, a lower priority value always
// wins; between equal priorities the lower destination, then the lower
// source wins. The source in the identifier makes identifiers of different
// nodes distinct, as CAN requires.

#include <cstddef>
#include <cstdint>

#include <linux/can.h>

namespace herm::can {

// -- formats and limits ----------------------------------------------------------

enum class id_format : uint8_t {
  /// 29-bit extended identifiers (CAN 2.0B), the default.
  ext29,
  /// 11-bit standard identifiers (CAN 2.0A).
  std11,
};

constexpr const char* to_string(id_format f) {
  return f == id_format::ext29 ? "29bit" : "11bit";
}

/// Largest priority value; larger values travel as this one.
constexpr uint8_t max_priority = 7;

/// Largest node id (node ids start at 1).
constexpr uint8_t max_node(id_format f) {
  return f == id_format::ext29 ? 254 : 14;
}

/// The destination field value that addresses every node.
constexpr uint8_t broadcast_node(id_format f) {
  return f == id_format::ext29 ? 0xFF : 0x0F;
}

/// Protocol tag of HERM version 1 (bits 9..4 of a 29-bit identifier).
constexpr uint32_t herm_tag = 0x25; // 0b100101

/// Largest classic data field, bytes.
constexpr size_t classic_max_len = 8;

/// Largest CAN FD data field, bytes.
constexpr size_t fd_max_len = 64;

// -- the identifier fields -------------------------------------------------------

/// The fields HERM puts into an identifier.
struct frame_id {
  uint8_t priority = 0; ///< 0..7
  uint8_t dst = 0;      ///< 1..max_node or broadcast_node
  uint8_t src = 0;      ///< 1..max_node
  uint8_t pad = 0;      ///< CAN FD padding bytes, 0..15; 0 for 11-bit ids

  friend constexpr bool operator==(const frame_id& x, const frame_id& y) {
    return x.priority == y.priority && x.dst == y.dst && x.src == y.src
           && x.pad == y.pad;
  }
};

/// True when every field is in range for `f` (see the layout above).
constexpr bool valid(id_format f, const frame_id& x) {
  auto node_ok = [f](uint8_t n) { return n >= 1 && n <= max_node(f); };
  return x.priority <= max_priority
         && (node_ok(x.dst) || x.dst == broadcast_node(f)) && node_ok(x.src)
         && x.pad <= (f == id_format::ext29 ? 15 : 0);
}

/// The raw identifier (29 or 11 bits, no flags). @pre valid(f, x)
constexpr uint32_t encode_id(id_format f, const frame_id& x) {
  if (f == id_format::ext29)
    return uint32_t{x.priority} << 26 | uint32_t{x.dst} << 18
           | uint32_t{x.src} << 10 | herm_tag << 4 | uint32_t{x.pad};
  return uint32_t{x.priority} << 8 | uint32_t{x.dst} << 4 | uint32_t{x.src};
}

/// The identifier as struct can_frame carries it: with CAN_EFF_FLAG for
/// 29-bit identifiers. @pre valid(f, x)
constexpr canid_t to_can_id(id_format f, const frame_id& x) {
  return f == id_format::ext29 ? encode_id(f, x) | CAN_EFF_FLAG
                               : encode_id(f, x);
}

/// Verdict on a received identifier or frame.
enum class id_status : uint8_t {
  ok,
  error_frame,     ///< CAN_ERR_FLAG set: a controller status, not data
  remote_frame,    ///< RTR: HERM never sends remote frames
  standard_id,     ///< an 11-bit id where 29-bit ids are expected
  extended_id,     ///< a 29-bit id where 11-bit ids are expected
  foreign,         ///< protocol tag is not HERM's: another protocol's frame
  bad_source,      ///< source node 0, broadcast or above max_node
  bad_destination, ///< destination node 0 or above max_node
  bad_length,      ///< data length impossible for the frame type
  bad_padding,     ///< padding in a classic frame, or not what a sender
                   ///< rounding up to a CAN FD length would produce
};

/// Short reason for people, e.g. for frame_handler::on_malformed.
constexpr const char* to_string(id_status x) {
  switch (x) {
    case id_status::ok: return "ok";
    case id_status::error_frame: return "error frame";
    case id_status::remote_frame: return "remote (RTR) frame";
    case id_status::standard_id: return "standard 11-bit identifier";
    case id_status::extended_id: return "extended 29-bit identifier";
    case id_status::foreign: return "not a HERM identifier (protocol tag)";
    case id_status::bad_source: return "source node out of range";
    case id_status::bad_destination: return "destination node out of range";
    case id_status::bad_length: return "impossible data length";
    case id_status::bad_padding: return "inconsistent CAN FD padding";
  }
  return "unknown";
}

/// Decodes the identifier of a received frame (`can_id` with its flags, as in
/// struct can_frame). Fills `out` on ok.
constexpr id_status decode_id(id_format f, canid_t can_id, frame_id& out) {
  if ((can_id & CAN_ERR_FLAG) != 0)
    return id_status::error_frame;
  if ((can_id & CAN_RTR_FLAG) != 0)
    return id_status::remote_frame;
  bool ext = (can_id & CAN_EFF_FLAG) != 0;
  frame_id x;
  if (f == id_format::ext29) {
    if (!ext)
      return id_status::standard_id;
    auto id = can_id & CAN_EFF_MASK;
    if (((id >> 4) & 0x3F) != herm_tag)
      return id_status::foreign;
    x.priority = static_cast<uint8_t>(id >> 26);
    x.dst = static_cast<uint8_t>(id >> 18);
    x.src = static_cast<uint8_t>(id >> 10);
    x.pad = static_cast<uint8_t>(id & 0x0F);
  } else {
    if (ext)
      return id_status::extended_id;
    auto id = can_id & CAN_SFF_MASK;
    x.priority = static_cast<uint8_t>(id >> 8);
    x.dst = static_cast<uint8_t>((id >> 4) & 0x0F);
    x.src = static_cast<uint8_t>(id & 0x0F);
  }
  if (x.src < 1 || x.src > max_node(f))
    return id_status::bad_source;
  if (x.dst < 1 || (x.dst > max_node(f) && x.dst != broadcast_node(f)))
    return id_status::bad_destination;
  out = x;
  return id_status::ok;
}

// -- data lengths ----------------------------------------------------------------

/// True for the data lengths a CAN FD frame can have: 0..8, 12, 16, 20, 24,
/// 32, 48, 64.
constexpr bool is_fd_len(size_t n) {
  return n <= 8 || n == 12 || n == 16 || n == 20 || n == 24 || n == 32
         || n == 48 || n == 64;
}

/// The smallest CAN FD data length that holds `n` bytes. @pre n <= 64
constexpr size_t fd_round_up(size_t n) {
  if (n <= 8)
    return n;
  if (n <= 24)
    return (n + 3) / 4 * 4;
  if (n <= 32)
    return 32;
  return n <= 48 ? 48 : 64;
}

/// Checks a whole received frame: its identifier (see decode_id), its data
/// length `len` (the len field of struct can_frame / canfd_frame) and the
/// padding. `fd` tells whether it arrived as a CAN FD frame. On ok, `out`
/// holds the fields and `payload` the number of HERM bytes (len - pad).
constexpr id_status decode_frame(id_format f, canid_t can_id, size_t len,
                                 bool fd, frame_id& out, size_t& payload) {
  frame_id x;
  auto st = decode_id(f, can_id, x);
  if (st != id_status::ok)
    return st;
  if (fd ? !is_fd_len(len) || len > fd_max_len : len > classic_max_len)
    return id_status::bad_length;
  if (x.pad != 0 && (!fd || x.pad > len || fd_round_up(len - x.pad) != len))
    return id_status::bad_padding;
  out = x;
  payload = len - x.pad;
  return id_status::ok;
}

/// True when a node `self` takes a frame addressed to `dst` (its own id or
/// broadcast), like a controller's acceptance filter.
constexpr bool accepts(id_format f, uint8_t self, uint8_t dst) {
  return dst == self || dst == broadcast_node(f);
}

/// The lane (link_driver.hpp) of a frame: 2 * priority, plus 1 for a
/// broadcast; 0..15. Frames of one sender in one lane have one identifier
/// (but for CAN FD padding), so they leave in order from a FIFO queue (the
/// kernel's, the emulated controller's) and from a controller whose
/// mailboxes arbitrate by identifier alike; frames of different lanes may
/// overtake each other in either. The sender and the receiver compute the
/// lane from the same fields, so each of a receiver's lanes from one sender
/// carries exactly one of the sender's packet tag sequences.
constexpr uint8_t lane_of(id_format f, const frame_id& x) {
  auto prio = x.priority < max_priority ? x.priority : max_priority;
  return static_cast<uint8_t>(prio << 1 | (x.dst == broadcast_node(f) ? 1 : 0));
}

static_assert(lane_of(id_format::ext29, {max_priority, 0xFF, 1, 0}) == 15);

/// A kernel receive filter (struct can_filter fields) that passes the frames
/// whose destination field is `dst`. Its mask includes CAN_EFF_FLAG so that
/// frames of the other identifier length do not pass. It leaves out the
/// protocol tag and CAN_RTR_FLAG on purpose: foreign and remote frames that
/// happen to carry our destination bits reach the driver and are counted.
struct id_filter {
  canid_t id;
  canid_t mask;
};

constexpr id_filter destination_filter(id_format f, uint8_t dst) {
  if (f == id_format::ext29)
    return {CAN_EFF_FLAG | uint32_t{dst} << 18, CAN_EFF_FLAG | 0xFFu << 18};
  return {uint32_t{dst} << 4, CAN_EFF_FLAG | 0x0Fu << 4};
}

// -- arbitration -----------------------------------------------------------------

/// Orders identifiers (with CAN_EFF_FLAG, as in can_id) the way bitwise
/// arbitration does for data frames: the numerically lower key wins. The key
/// holds the arbitration field as transmitted, most significant bit first:
/// the 11 base bits, then RTR/SRR and IDE (dominant 0 for a standard data
/// frame, recessive 1 1 for an extended one), then the 18 extension bits. So
/// a standard frame beats an extended frame with the same base bits.
constexpr uint32_t arbitration_key(canid_t can_id) {
  if ((can_id & CAN_EFF_FLAG) != 0) {
    auto id = can_id & CAN_EFF_MASK;
    return (id >> 18) << 20 | 3u << 18 | (id & 0x3FFFFu);
  }
  return (can_id & CAN_SFF_MASK) << 20;
}

// -- bit timing ------------------------------------------------------------------

/// Bits one data frame of `len` data bytes occupies on the bus, interframe
/// space included: 67 + 8 * len for 29-bit identifiers, 47 + 8 * len for
/// 11-bit ones (SOF, arbitration, control, data, CRC, delimiters, ACK, EOF,
/// 3-bit intermission). With `stuffing`, adds the worst case of stuff bits:
/// one per 4 bits of the 54 + 8 * len (34 + 8 * len) bits from SOF to the
/// end of the CRC, i.e. floor((g + 8 * len - 1) / 4) (Davis et al., 2007).
/// CAN FD frames are counted the same way at one bit rate (an
/// approximation: no bit-rate switch, classic CRC length).
constexpr uint32_t frame_bits(id_format f, size_t len, bool stuffing) {
  auto g = uint32_t{f == id_format::ext29 ? 54u : 34u};
  auto stuffed = g + 8 * static_cast<uint32_t>(len);
  return stuffed + 13 + (stuffing ? (stuffed - 1) / 4 : 0);
}

/// Nanoseconds `bits` take at `bitrate` bit/s, rounded up so that the bus
/// never carries more than the bit rate allows. @pre bitrate > 0
constexpr int64_t bits_time_ns(uint64_t bits, uint64_t bitrate) {
  return static_cast<int64_t>((bits * 1'000'000'000ull + bitrate - 1)
                              / bitrate);
}

static_assert(frame_bits(id_format::std11, 8, false) == 111);
static_assert(frame_bits(id_format::ext29, 8, false) == 131);
static_assert(frame_bits(id_format::std11, 8, true) == 135);
static_assert(frame_bits(id_format::ext29, 8, true) == 160);

} // namespace herm::can
