#pragma once

// Wire format and pacing arithmetic of the emulated medium (link kind "emu",
// channels/drivers/emu.cpp). Pure functions without clock or I/O: time goes
// in as an argument, so the driver and its tests share one definition.
//
// Every datagram a station sends to another station's socket is one
// wire_header followed by the frame's payload (0..MTU bytes). Fields are
// little endian (channels/le_codec.hpp); all stations of a medium live on
// one machine, where that is also the host's order.
//
// Bounds per call: everything here is O(1) (the header has a fixed size),
// allocates nothing and reads or writes exactly wire_header_size bytes;
// check reads nothing when the datagram is shorter than that.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "channels/le_codec.hpp"

namespace herm::emu {

// -- limits -------------------------------------------------------------------

/// Station numbers on an emulated medium are 1..254.
constexpr uint64_t min_station = 1;
constexpr uint64_t max_station = 254;

/// Upper bounds of the latency_us and jitter_us options, in microseconds.
constexpr uint64_t max_latency_us = 10'000'000;
constexpr uint64_t max_jitter_us = 10'000'000;

/// A receiver refuses a datagram that asks to be held longer than any sender
/// can ask for (latency + jitter + 1 s slack): it would pin a slot for ever.
constexpr int64_t max_hold_ns
  = int64_t(max_latency_us + max_jitter_us) * 1000 + 1'000'000'000;

// -- wire header --------------------------------------------------------------

constexpr uint16_t wire_magic = 0x4D45; // "EM" in little-endian memory
constexpr uint8_t wire_version = 1;
constexpr size_t wire_header_size = 16;

/// Informational flags; a receiver refuses unknown bits.
enum wire_flag : uint8_t {
  /// The frame was sent to every station.
  flag_broadcast = 0x01,
  /// The medium duplicated the frame (option "duplicate").
  flag_duplicate = 0x02,
  /// The medium flipped one payload bit (option "corrupt").
  flag_corrupted = 0x04,
  flag_mask = 0x07,
};

struct wire_header {
  uint16_t magic = wire_magic;
  uint8_t version = wire_version;
  uint8_t flags = 0;
  /// Sending station, 1..254.
  uint16_t src = 0;
  /// Must be 0.
  uint16_t reserved = 0;
  /// CLOCK_MONOTONIC time in ns at which the receiver hands the frame up:
  /// end of transmission + latency + jitter.
  int64_t deliver_at_ns = 0;
};

// -- datagram head, shared with the emulated CAN bus (can_emu_wire.hpp) ------

/// The 16 bytes both emulated media put before a frame:
///
///   magic (2) | version (1) | flags (1) | word (4) | deliver_at_ns (8)
///
/// `word` is src | reserved << 16 here, the reserved field on CAN.
struct datagram_head {
  uint16_t magic = 0;
  uint8_t version = 0;
  uint8_t flags = 0;
  uint32_t word = 0;
  int64_t deliver_at_ns = 0;
};

constexpr size_t datagram_head_size = 16;

/// Writes `h` to `out[0..datagram_head_size)`.
inline void put_head(const datagram_head& h, uint8_t* out) {
  store_le(h.magic, out);
  out[2] = h.version;
  out[3] = h.flags;
  store_le(h.word, out + 4);
  store_le(static_cast<uint64_t>(h.deliver_at_ns), out + 8);
}

/// Reads `in[0..datagram_head_size)` without checking it.
inline datagram_head get_head(const uint8_t* in) {
  datagram_head h;
  h.magic = load_le<uint16_t>(in);
  h.version = in[2];
  h.flags = in[3];
  h.word = load_le<uint32_t>(in + 4);
  h.deliver_at_ns = static_cast<int64_t>(load_le<uint64_t>(in + 8));
  return h;
}

/// The checks both media make of a head, in this order; each medium's
/// status enum starts with these five values.
enum class head_status { ok, too_short, bad_magic, bad_version, bad_header };

/// Reads and checks the head of a datagram of `size` bytes: long enough,
/// `magic`, `version`, no flag outside `flag_mask`, reserved bits
/// (`reserved_mask` of the word) zero. `data` holds at least
/// min(size, datagram_head_size) bytes.
inline head_status check_head(const uint8_t* data, size_t size,
                              uint16_t magic, uint8_t version,
                              uint8_t flag_mask, uint32_t reserved_mask) {
  if (size < datagram_head_size)
    return head_status::too_short;
  auto h = get_head(data);
  if (h.magic != magic)
    return head_status::bad_magic;
  if (h.version != version)
    return head_status::bad_version;
  if ((h.flags & ~flag_mask) != 0 || (h.word & reserved_mask) != 0)
    return head_status::bad_header;
  return head_status::ok;
}

/// Whether a datagram to be delivered at `deliver_at_ns` asks to be held
/// more than `max_hold` ns after `now_ns` (it would pin a slot for ever).
constexpr bool held_too_long(int64_t deliver_at_ns, int64_t now_ns,
                             int64_t max_hold) {
  return deliver_at_ns > now_ns && deliver_at_ns - now_ns > max_hold;
}

// -- this medium's header ----------------------------------------------------------

static_assert(wire_header_size == datagram_head_size);

/// Writes `h` to `out[0..wire_header_size)`.
inline void encode(const wire_header& h, uint8_t* out) {
  put_head({h.magic, h.version, h.flags,
            uint32_t{h.src} | uint32_t{h.reserved} << 16, h.deliver_at_ns},
           out);
}

/// Reads a header from `in[0..wire_header_size)` without checking it.
inline wire_header decode(const uint8_t* in) {
  auto g = get_head(in);
  wire_header h;
  h.magic = g.magic;
  h.version = g.version;
  h.flags = g.flags;
  h.src = static_cast<uint16_t>(g.word);
  h.reserved = static_cast<uint16_t>(g.word >> 16);
  h.deliver_at_ns = g.deliver_at_ns;
  return h;
}

/// Verdict on one received datagram.
enum class wire_status {
  ok,
  too_short,     ///< shorter than the header
  bad_magic,     ///< not an emu datagram
  bad_version,   ///< another version of the wire format
  bad_header,    ///< unknown flag bits or reserved field not 0
  bad_source,    ///< source station outside 1..254
  oversized,     ///< payload larger than the receiver's MTU
  too_far_ahead, ///< deliver_at more than max_hold_ns in the future
};

static_assert(static_cast<int>(wire_status::bad_header)
              == static_cast<int>(head_status::bad_header));

/// Short reason for people, e.g. for frame_handler::on_malformed.
inline const char* to_string(wire_status x) {
  switch (x) {
    case wire_status::ok: return "ok";
    case wire_status::too_short: return "datagram shorter than the emu header";
    case wire_status::bad_magic: return "bad magic (not an emu datagram)";
    case wire_status::bad_version: return "unsupported emu wire version";
    case wire_status::bad_header: return "unknown flags or reserved bits set";
    case wire_status::bad_source: return "source station outside 1..254";
    case wire_status::oversized: return "payload larger than the MTU";
    case wire_status::too_far_ahead:
      return "delivery time too far in the future";
  }
  return "unknown";
}

/// Checks a datagram of `size` bytes as it was sent (the real size, which
/// may exceed what was read: receivers use MSG_TRUNC). `data` must hold at
/// least min(size, wire_header_size) bytes. Fills `hdr` when the header could
/// be read (every status but too_short).
inline wire_status check(const uint8_t* data, size_t size, uint32_t mtu,
                         int64_t now_ns, wire_header& hdr) {
  auto head = check_head(data, size, wire_magic, wire_version, flag_mask,
                         0xFFFF0000);
  if (head == head_status::too_short)
    return wire_status::too_short;
  hdr = decode(data);
  if (head != head_status::ok)
    return static_cast<wire_status>(head);
  if (hdr.src < min_station || hdr.src > max_station)
    return wire_status::bad_source;
  if (size - wire_header_size > mtu)
    return wire_status::oversized;
  if (held_too_long(hdr.deliver_at_ns, now_ns, max_hold_ns))
    return wire_status::too_far_ahead;
  return wire_status::ok;
}

// -- pacing -------------------------------------------------------------------

/// Nanoseconds the medium is busy with one frame of `payload` bytes:
/// (payload * 8 + overhead_bits) bits at `bandwidth_bps`, rounded up so the
/// average rate never exceeds the configured one. `bandwidth_bps` > 0.
inline int64_t frame_time_ns(size_t payload, uint32_t overhead_bits,
                             uint64_t bandwidth_bps) {
  // At most 65,507 * 8 + 65,536 bits: times 1e9 fits in 64 bits.
  auto bits = uint64_t{payload} * 8 + overhead_bits;
  return static_cast<int64_t>((bits * 1'000'000'000ull + bandwidth_bps - 1)
                              / bandwidth_bps);
}

/// When a frame starts occupying the medium: not before the medium is free
/// (`busy_until`), not before the frame was handed to the driver
/// (`enqueued_at`). A transmitter that woke up late does not lose the time it
/// overslept: frames queued back to back start back to back, even if that
/// lies in the past, and then go out at once (that keeps the average rate
/// exact despite sleep granularity). The credit is bounded: a start never
/// lies more than `max_credit` before `now`, so a stalled process cannot
/// release an unbounded burst afterwards. All times in ns.
inline int64_t transmission_start(int64_t busy_until, int64_t enqueued_at,
                                  int64_t now, int64_t max_credit) {
  return std::max(busy_until, std::max(enqueued_at, now - max_credit));
}

} // namespace herm::emu
