#pragma once

// Fragmentation and reassembly for small-MTU links (the paper's decorator
// channel). Pure code: no clock, no I/O; time is passed in. Wire format in
// docs/protocol.md, section "Fragment header".
//
// Frame layout (first byte = header type in bits 7..6, tag in bits 5..4):
//   single       00 TT 0000  | payload                      (packet fits one frame)
//   first        01 TT W000  | LEB128 length | stream bytes (W: wide sequence)
//   consecutive  10 TT SSSS  | stream bytes                 (narrow: seq mod 16)
//   consecutive  11 TT SSSS SSSSSSSS | stream bytes         (wide: seq mod 4096)
// where the fragmented stream is payload || CRC-32(payload), little endian,
// the first frame has index 0 and consecutive frames 1, 2, ... The sender
// uses wide sequence numbers when the MTU is at least 64 bytes.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <memory>
#include <utility>

#include "channels/messages.hpp"

namespace herm {

/// Smallest MTU fragmentation supports (a CAN 2.0 frame).
constexpr uint32_t min_fragment_mtu = 8;

/// MTU from which the sender uses 12-bit (wide) sequence numbers.
constexpr uint32_t wide_fragment_mtu = 64;

/// Splits packets into frames of at most `mtu` bytes.
class fragmenter {
public:
  /// @pre mtu >= min_fragment_mtu
  explicit fragmenter(uint32_t mtu);

  uint32_t mtu() const noexcept {
    return mtu_;
  }

  /// Number of frames `split` produces for a packet of `size` bytes.
  size_t frames_for(size_t size) const noexcept;

  /// Splits one packet and calls `emit(const uint8_t* frame, size_t len)`
  /// once per frame, in order. Advances the 2-bit packet tag. Uses one
  /// internal scratch buffer: no allocation per frame once warmed up.
  void split(const uint8_t* data, size_t size,
             const std::function<void(const uint8_t*, size_t)>& emit);

  /// Like split(), with one packet tag sequence per destination link
  /// address and lane (link_driver.hpp). On a multi-access link a receiver
  /// hears only the packets addressed to it (and broadcasts): with a tag
  /// sequence per destination it still sees every tag of its own stream in
  /// order, which is what tells a new packet from a late duplicate of an
  /// earlier one with the same first frame (short frames make equal first
  /// frames common: on CAN they hold only the routing header). With one
  /// per lane as well, each of the receiver's reassembly lanes sees a whole
  /// sequence too, and packets of different lanes, which may interleave on
  /// the link, are told apart by the lane, not by the tag. Remembers at
  /// most `max_sequences` sequences; beyond that it starts over.
  void split(link_addr dst, uint8_t lane, const uint8_t* data, size_t size,
             const std::function<void(const uint8_t*, size_t)>& emit);

  /// split(dst, 0, data, size, emit).
  void split(link_addr dst, const uint8_t* data, size_t size,
             const std::function<void(const uint8_t*, size_t)>& emit);

  /// 256 CAN nodes times 16 lanes.
  static constexpr size_t max_sequences = 4096;

private:
  uint32_t mtu_;
  uint8_t next_tag_ = 0;
  byte_buffer scratch_;
  std::map<std::pair<link_addr, uint8_t>, uint8_t> tags_;
};

/// Bounds on reassembly. Whatever exceeds them is dropped and counted.
struct reassembly_limits {
  /// Largest packet accepted, bytes (the length field is checked against it
  /// before anything is allocated).
  size_t max_packet = 128 * 1024;
  /// Bytes of incomplete packets held per sender.
  size_t per_sender = 256 * 1024;
  /// Bytes of incomplete packets held in total.
  size_t total = 4 * 1024 * 1024;
  /// An incomplete packet older than this is dropped.
  std::chrono::milliseconds timeout{2000};
};

/// Counters of a reassembler. Each dropped frame or packet is counted once.
struct reassembly_stats {
  uint64_t packets = 0;        ///< complete packets delivered
  uint64_t malformed = 0;      ///< frames that did not decode
  uint64_t duplicates = 0;     ///< duplicate fragments ignored
  uint64_t orphans = 0;        ///< consecutive fragments with no first fragment
  uint64_t timed_out = 0;      ///< incomplete packets expired
  uint64_t over_limit = 0;     ///< packets refused or evicted by memory bounds
  uint64_t bad_checksum = 0;   ///< packets whose CRC-32 did not match
  uint64_t superseded = 0;     ///< incomplete packets replaced by a new first
                               ///< fragment with the same lane and tag
};

/// Reassembles packets from frames of many senders on one link, tolerating
/// loss, duplication and reordering (within 16 frames for narrow sequence
/// numbers, within 4096 for wide). Never delivers a corrupted packet: every
/// fragmented packet is checked against its CRC-32. Single-frame packets
/// carry no sequence number: a duplicated single frame is delivered twice.
/// A packet above 2^21 - 1 bytes cannot be fragmented: frames_for() is 0
/// and split() emits nothing.
///
/// Packets are reassembled per (sender, lane, tag): frames of one sender's
/// different lanes (link_driver.hpp) may interleave in any way, e.g. a CAN
/// control packet's frames overtaking a bulk packet's, whatever their tags.
/// The memory bounds are per sender, over all its lanes.
class reassembler {
public:
  using time_point = std::chrono::steady_clock::time_point;

  enum class result {
    /// `out` holds a complete packet.
    complete,
    /// Frame accepted; the packet is not complete yet.
    pending,
    /// Frame dropped (malformed, duplicate, orphan, over limit, checksum);
    /// the matching counter in stats() went up.
    dropped,
  };

  explicit reassembler(reassembly_limits limits = {});

  ~reassembler();

  reassembler(reassembler&&) noexcept;

  reassembler& operator=(reassembler&&) noexcept;

  /// Feeds one frame from `src` that travelled in `lane`, received at
  /// `now`. On `complete`, the packet is moved into `out` (its previous
  /// contents are discarded).
  result push(link_addr src, uint8_t lane, const uint8_t* data, size_t size,
              time_point now, byte_buffer& out);

  /// push(src, 0, data, size, now, out): for links with one lane.
  result push(link_addr src, const uint8_t* data, size_t size, time_point now,
              byte_buffer& out);

  /// Drops incomplete packets that started before `now - timeout`.
  /// Returns how many were dropped.
  size_t expire(time_point now);

  /// Earliest time at which `expire` would drop something, if anything is
  /// pending.
  std::optional<time_point> next_deadline() const;

  /// Bytes currently held for incomplete packets.
  size_t memory_in_use() const noexcept;

  /// Number of incomplete packets.
  size_t pending() const noexcept;

  const reassembly_stats& stats() const noexcept;

  const reassembly_limits& limits() const noexcept;

private:
  struct impl;
  std::unique_ptr<impl> impl_;
};

// -- bundles: several small packets in one frame -------------------------------

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
/// the packet would make the frame longer than `mtu` or is empty.
bool bundle_append(byte_buffer& frame, uint32_t mtu, const uint8_t* data,
                   size_t size);

/// Bytes bundle_append adds for a packet of `size` bytes.
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
