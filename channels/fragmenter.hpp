#pragma once

// The sending half of fragmentation for small-MTU links (the paper's
// decorator channel, channels/port.hpp): splits packets into frames of at
// most the MTU, in the wire format of channels/fragment_wire.hpp
// (docs/protocol.md, "Fragment header"). Pure code: no clock, no I/O.
//
// Contract: split() takes O(size) time plus O(log max_sequences) for the
// per-destination tag; it calls `emit` once per frame, frames_for(size)
// times. Memory: one scratch buffer of at most MTU bytes (no allocation
// per packet or frame once warmed up) and at most max_sequences tag entries.
// Not thread-safe: one fragmenter per sending channel.

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <type_traits>
#include <utility>

#include "channels/fragment_wire.hpp"
#include "channels/messages.hpp"

namespace herm {

/// What split() calls once per frame: a reference to any callable taking
/// (const uint8_t* frame, size_t len), which must outlive the call it is
/// passed to (a lambda written in the call does). Unlike std::function it
/// never allocates, however much the callable captures: split() runs for
/// every packet a channel sends.
class frame_sink {
public:
  template <class F, class = std::enable_if_t<
                       !std::is_same_v<std::decay_t<F>, frame_sink>>>
  frame_sink(F&& f) noexcept // NOLINT: implicit, like std::function's
    : obj_(const_cast<void*>(static_cast<const void*>(std::addressof(f)))),
      call_([](void* obj, const uint8_t* frame, size_t len) {
        (*static_cast<std::remove_reference_t<F>*>(obj))(frame, len);
      }) {
  }

  void operator()(const uint8_t* frame, size_t len) const {
    call_(obj_, frame, len);
  }

private:
  void* obj_;
  void (*call_)(void*, const uint8_t*, size_t);
};

/// Splits packets into frames of at most `mtu` bytes.
class fragmenter {
public:
  /// @pre mtu >= min_fragment_mtu (release builds clamp to it)
  explicit fragmenter(uint32_t mtu);

  uint32_t mtu() const noexcept {
    return mtu_;
  }

  /// Number of frames `split` produces for a packet of `size` bytes: 1 when
  /// it fits one frame, 0 above 2^21 - 1 bytes (cannot be announced).
  size_t frames_for(size_t size) const noexcept;

  /// Splits one packet and calls `emit(const uint8_t* frame, size_t len)`
  /// once per frame, in order. Advances the 2-bit packet tag. The frame
  /// pointer is valid only during the call. Emits nothing for a packet
  /// above 2^21 - 1 bytes.
  void split(const uint8_t* data, size_t size, frame_sink emit);

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
             frame_sink emit);

  /// split(dst, 0, data, size, emit).
  void split(link_addr dst, const uint8_t* data, size_t size, frame_sink emit);

  /// 256 CAN nodes times 16 lanes.
  static constexpr size_t max_sequences = 4096;

private:
  uint32_t mtu_;
  uint8_t next_tag_ = 0;
  byte_buffer scratch_;
  std::map<std::pair<link_addr, uint8_t>, uint8_t> tags_;
};

} // namespace herm
