#pragma once

// Bundling as a port decorator: small packets to one destination that are
// written in one burst leave together in one bundle frame (the bundle codec
// and wire layout: channels/bundle_codec.hpp, docs/protocol.md "Bundles"),
// so that one datagram (one system call, one kernel round) carries several.
//
// When bundles form: a packet is small when bundle_cost(size) + 1 is below
// half the MTU. A small packet written while the wrapped port is not
// congested is held in the bundle being built; the bundle leaves at the
// next flush(), when a packet to another destination or with another
// priority arrives, when the packet does not fit (it then starts the next
// bundle), or before any packet that is not held (so packets keep their
// order). The owner calls flush() once per turn: the channel does so when
// its mailbox runs empty. A bundle of one packet leaves as an ordinary
// packet (inner send), one of two or more as one frame (inner send_frame).
//
// Contract: send() is O(size) plus what the wrapped port's send costs when
// it flushes; memory is one frame buffer of at most the MTU and, on the
// receive side, one copy of the last bundle received (reused, no allocation
// per frame once warmed up). Bad bundles are dropped and counted
// (rx_malformed), never fatal. Not thread-safe: owned by one channel.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "channels/bundle_codec.hpp"
#include "channels/port.hpp"

namespace herm {

/// What a bundling_port counted. The packets and bytes of bundles sent as
/// one frame never reach the wrapped port as packets, so it counts them.
struct bundling_stats {
  uint64_t tx_bundles = 0;  ///< bundle frames sent (two or more packets)
  uint64_t tx_packets = 0;  ///< packets sent inside those frames
  uint64_t tx_bytes = 0;    ///< their bytes
  uint64_t tx_dropped = 0;  ///< packets of bundle frames the link refused
  uint64_t rx_bundles = 0;  ///< bundle frames received and delivered
  uint64_t rx_bad = 0;      ///< bundle frames dropped as malformed
};

/// Decorator: holds small packets until flush() and sends them as one
/// bundle frame; unpacks received bundles. See the top of this file.
class bundling_port : public port_decorator {
public:
  /// @pre mtu >= min_bundle_mtu, the wrapped port's frames are at most
  ///      `mtu` bytes and its packets above `mtu` (it fragments): bundles
  ///      share the fragment header's type "single" (bundle_codec.hpp).
  bundling_port(std::unique_ptr<packet_port> inner, uint32_t mtu);

  /// Holds a small packet (returns 0 frames: it leaves at the next flush)
  /// or, after flushing what is held, hands it to the wrapped port.
  caf::expected<size_t> send(link_addr dst, uint8_t priority,
                             const uint8_t* data, size_t size) override;

  using packet_port::receive;

  /// A bundle frame yields its first packet here and the others through
  /// next_packet(); a malformed bundle is dropped whole. Any other frame
  /// goes to the wrapped port.
  rx receive(link_addr src, uint8_t lane, const uint8_t* data, size_t size,
             time_point now, byte_buffer& out) override;

  bool next_packet(byte_buffer& out) override;

  /// Sends the bundle being built, then flushes the wrapped port.
  void flush() override;

  /// Adds tx_bundles, rx_bundles, the packets of bundle frames (tx_packets,
  /// tx_bytes, tx_frames, tx_dropped) and bad bundles (rx_malformed).
  void add_stats(channel_stats& st) const override;

  const bundling_stats& stats() const noexcept {
    return stats_;
  }

  /// Packets held for the next bundle.
  size_t held() const noexcept {
    return count_;
  }

  /// Whether a packet of `size` bytes is small enough to wait for a bundle
  /// on a link with this MTU.
  static bool is_small(size_t size, uint32_t mtu) noexcept {
    return bundle_cost(size) + 1 < mtu / 2;
  }

  /// Whether a port stack with this MTU and largest packet bundles: only
  /// fragmenting stacks (bundles are a fragment-header type) on links with
  /// an MTU of at least min_bundle_mtu.
  static bool applies(uint32_t mtu, uint32_t max_packet) noexcept {
    return mtu >= min_bundle_mtu && max_packet > mtu;
  }

private:
  void send_held();

  uint32_t mtu_;
  // -- sending --
  byte_buffer frame_;
  link_addr dst_ = 0;
  uint8_t priority_ = 0;
  size_t count_ = 0;
  size_t bytes_ = 0;
  // -- receiving: the packets of the last bundle not yet taken --
  byte_buffer rx_frame_;
  std::vector<std::pair<size_t, size_t>> rx_rest_; // offset, size
  size_t rx_next_ = 0;
  bundling_stats stats_;
};

/// Decorates `inner` with a bundling_port when bundling applies to it
/// (bundling_port::applies(mtu, inner->max_packet())), else returns it.
std::unique_ptr<packet_port> with_bundling(std::unique_ptr<packet_port> inner,
                                           uint32_t mtu);

} // namespace herm
