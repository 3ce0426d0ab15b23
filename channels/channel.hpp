#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "caf/fwd.hpp"

#include "channels/channel_actor.hpp"
#include "channels/device_actor.hpp"
#include "channels/fragmentation.hpp"
#include "channels/link_driver.hpp"
#include "channels/packet_tap.hpp"

namespace herm {

/// Counters a device shares with its channels (updated from driver threads).
struct device_counters {
  std::atomic<uint64_t> unclaimed{0};
  std::atomic<uint64_t> malformed{0};
  /// Frames the kernel dropped for a full receive buffer (SO_RXQ_OVFL).
  std::atomic<uint64_t> kernel_dropped{0};
};

/// Bound of a channel's inbound queue: received frames the driver handed to
/// the channel (they wait in its mailbox) that it has not processed yet,
/// each charged its size plus rx_queue_frame_overhead. A flood faster than
/// the channel (a busy scheduler, a slow subscriber) meets this bound in
/// the driver's thread: the excess is dropped there and counted
/// (channel_stats::rx_queue_dropped), so memory stays bounded however fast
/// frames arrive.
constexpr size_t default_rx_queue_bytes = 2 * 1024 * 1024;

/// What one queued frame costs beyond its bytes (message and buffer
/// headers), so that a flood of tiny frames is bounded too.
constexpr size_t rx_queue_frame_overhead = 128;

/// The inbound queue's account, shared by a channel and its device's
/// demultiplexer. Thread-safe.
class rx_queue_account {
public:
  explicit rx_queue_account(size_t limit = default_rx_queue_bytes)
    : limit_(limit) {
  }

  /// Charges a frame of `size` bytes; false (and counted as dropped) when
  /// that would exceed the bound.
  bool charge(size_t size) {
    auto cost = size + rx_queue_frame_overhead;
    auto cur = bytes_.load(std::memory_order_relaxed);
    do {
      if (cost > limit_ || cur > limit_ - cost) {
        dropped_.fetch_add(1, std::memory_order_relaxed);
        return false;
      }
    } while (!bytes_.compare_exchange_weak(cur, cur + cost,
                                           std::memory_order_relaxed));
    return true;
  }

  /// Credits back a processed frame of `size` bytes.
  void release(size_t size) {
    bytes_.fetch_sub(size + rx_queue_frame_overhead,
                     std::memory_order_relaxed);
  }

  size_t bytes() const {
    return bytes_.load(std::memory_order_relaxed);
  }

  size_t limit() const {
    return limit_;
  }

  uint64_t dropped() const {
    return dropped_.load(std::memory_order_relaxed);
  }

private:
  const size_t limit_;
  std::atomic<size_t> bytes_{0};
  std::atomic<uint64_t> dropped_{0};
};

/// Everything a device hands a new channel.
struct channel_setup {
  channel_info info;
  link_driver_ptr driver;
  std::shared_ptr<device_counters> counters;
  /// The channel's inbound queue, charged by the device's demultiplexer.
  std::shared_ptr<rx_queue_account> rx_queue
    = std::make_shared<rx_queue_account>();
  /// The peer of a point-to-point channel; broadcast_addr for "*".
  link_addr peer = broadcast_addr;
  reassembly_limits limits;
  /// The device, monitored: the channel ends with it.
  device_actor device;
  /// Sees each packet before the reader does (channels/packet_tap.hpp).
  packet_tap_ptr tap;
};

/// Spawns a channel actor. Used by device actors only; clients open channels
/// through the IO manager.
channel_actor spawn_channel(caf::actor_system& sys, channel_setup setup);

} // namespace herm
