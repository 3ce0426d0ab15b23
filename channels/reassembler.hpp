#pragma once

// The receiving half of fragmentation: reassembles packets from the frames
// of many senders on one link (wire format: channels/fragment_wire.hpp,
// docs/protocol.md "Fragment header"). Pure code: no clock, no I/O; time
// is passed in.
//
// Contract per call: push() takes O(frame size) time plus O(log lanes) to
// find the sender's lane, and at worst O(lanes of the sender * 4 + stash)
// when it must evict to stay within the limits; a packet's frames cost one
// allocation, made by its first fragment. expire() and next_deadline() are
// O(pending packets + stashed fragments). Memory: at most limits.total
// bytes for incomplete packets and stashed fragments (memory_in_use(),
// bookkeeping included), plus the duplicate-detection history (bounded at
// 4096 lanes of 4 tags times 17 hashes). Bad input (any bytes) is dropped
// and counted, never fatal. Not thread-safe: one reassembler per channel.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>

#include "channels/messages.hpp"

namespace herm {

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

} // namespace herm
