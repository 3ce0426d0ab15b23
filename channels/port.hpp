#pragma once

// Packet ports: how a channel turns packets into frames on its driver and
// back. `frame_port` sends each packet as one frame; `fragmenting_port` is
// the paper's decorator: it wraps another port and splits packets larger
// than the link MTU into fragments (channels/fragmentation.hpp);
// `bundling_port` (channels/bundling_port.hpp) packs small packets into
// one frame. Plain classes, no actors: the channel actor owns one port
// stack and calls flush() once per turn. Not thread-safe: a stack is used
// by its channel only.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>

#include "caf/error.hpp"

#include "channels/fragmenter.hpp"
#include "channels/link_driver.hpp"
#include "channels/messages.hpp"
#include "channels/reassembler.hpp"

namespace herm {

class packet_port {
public:
  using time_point = std::chrono::steady_clock::time_point;

  virtual ~packet_port();

  /// Largest packet `send` accepts, bytes.
  virtual uint32_t max_packet() const = 0;

  /// Sends one packet. Returns the number of frames put on the link or
  /// ec::packet_too_large / the driver's error. On error, no further
  /// frames of that packet are sent.
  virtual caf::expected<size_t> send(link_addr dst, uint8_t priority,
                                     const uint8_t* data, size_t size)
    = 0;

  enum class rx { packet, pending, dropped };

  /// Feeds one received frame that travelled in `lane` (link_driver.hpp).
  /// On rx::packet, `out` holds the packet.
  virtual rx receive(link_addr src, uint8_t lane, const uint8_t* data,
                     size_t size, time_point now, byte_buffer& out)
    = 0;

  /// Feeds one received frame of lane 0.
  rx receive(link_addr src, const uint8_t* data, size_t size, time_point now,
             byte_buffer& out) {
    return receive(src, 0, data, size, now, out);
  }

  /// The lane in which packets to `dst` with `priority` travel (the
  /// driver's link_driver::lane).
  virtual uint8_t lane(link_addr dst, uint8_t priority) const;

  /// Drops what has waited too long; returns how many packets were dropped.
  virtual size_t expire(time_point now);

  /// When `expire` next has something to do.
  virtual std::optional<time_point> next_deadline() const;

  /// Adds the port's receive-side drop counters to `st`.
  virtual void add_stats(channel_stats& st) const;

  /// Frames a packet of `size` bytes takes on the link.
  virtual size_t frames_for(size_t size) const;

  /// Puts one prepared frame (at most the link MTU) on the link as it is,
  /// bypassing the framing of this port and of those it wraps. Returns 1
  /// or the driver's error.
  virtual caf::expected<size_t> send_frame(link_addr dst, uint8_t priority,
                                           const uint8_t* data, size_t size)
    = 0;

  /// Sends whatever a decorator holds back (bundling_port); nothing by
  /// default. The channel calls it once per turn.
  virtual void flush();

  /// True while frames wait above the driver's queue (the channel's
  /// backlog): a decorator then holds nothing back. False by default.
  virtual bool congested() const;

  /// After receive() returned rx::packet: moves the next further packet
  /// the same frame carried (a bundle) into `out`; false when none is left.
  /// Valid until the next receive(). Nothing by default.
  virtual bool next_packet(byte_buffer& out);
};

/// Base of decorators: forwards everything to the wrapped port, so that a
/// decorator overrides only what it changes.
class port_decorator : public packet_port {
public:
  explicit port_decorator(std::unique_ptr<packet_port> inner);

  uint32_t max_packet() const override;

  caf::expected<size_t> send(link_addr dst, uint8_t priority,
                             const uint8_t* data, size_t size) override;

  using packet_port::receive;

  rx receive(link_addr src, uint8_t lane, const uint8_t* data, size_t size,
             time_point now, byte_buffer& out) override;

  uint8_t lane(link_addr dst, uint8_t priority) const override;

  size_t expire(time_point now) override;

  std::optional<time_point> next_deadline() const override;

  void add_stats(channel_stats& st) const override;

  size_t frames_for(size_t size) const override;

  caf::expected<size_t> send_frame(link_addr dst, uint8_t priority,
                                   const uint8_t* data, size_t size) override;

  void flush() override;

  bool congested() const override;

  bool next_packet(byte_buffer& out) override;

  packet_port& inner() noexcept {
    return *inner_;
  }

protected:
  std::unique_ptr<packet_port> inner_;
};

/// Puts one frame on the link. The channel supplies it, so that it can
/// queue frames when the driver's own queue is full.
using frame_writer = std::function<caf::error(link_addr dst, uint8_t priority,
                                              const uint8_t* data, size_t size)>;

/// One packet per frame; packets above the MTU are refused.
class frame_port : public packet_port {
public:
  /// Writes with `writer`, or straight to the driver when it is empty.
  frame_port(link_driver_ptr driver, frame_writer writer = {});

  uint32_t max_packet() const override;

  caf::expected<size_t> send(link_addr dst, uint8_t priority,
                             const uint8_t* data, size_t size) override;

  using packet_port::receive;

  rx receive(link_addr src, uint8_t lane, const uint8_t* data, size_t size,
             time_point now, byte_buffer& out) override;

  uint8_t lane(link_addr dst, uint8_t priority) const override;

  caf::expected<size_t> send_frame(link_addr dst, uint8_t priority,
                                   const uint8_t* data, size_t size) override;

private:
  link_driver_ptr driver_;
  frame_writer writer_;
};

/// Decorator: fragments packets for the wrapped port's MTU and reassembles.
/// One packet tag sequence per (destination, lane) and one reassembly per
/// (source, lane): packets in different lanes may interleave on the link
/// (CAN: control frames overtake bulk frames) whatever their tags.
class fragmenting_port : public port_decorator {
public:
  fragmenting_port(std::unique_ptr<packet_port> inner, uint32_t inner_mtu,
                   reassembly_limits limits);

  uint32_t max_packet() const override;

  caf::expected<size_t> send(link_addr dst, uint8_t priority,
                             const uint8_t* data, size_t size) override;

  using packet_port::receive;

  rx receive(link_addr src, uint8_t lane, const uint8_t* data, size_t size,
             time_point now, byte_buffer& out) override;

  size_t expire(time_point now) override;

  std::optional<time_point> next_deadline() const override;

  void add_stats(channel_stats& st) const override;

  const reassembler& reassembly() const noexcept {
    return reassembler_;
  }

  size_t frames_for(size_t size) const override {
    return fragmenter_.frames_for(size);
  }

private:
  fragmenter fragmenter_;
  reassembler reassembler_;
  byte_buffer frame_;
};

/// Builds the port stack for a driver: a frame_port, decorated with a
/// fragmenting_port when the MTU is smaller than `limits.max_packet`.
/// Errors: ec::invalid_parameter when the MTU is too small to fragment.
caf::expected<std::unique_ptr<packet_port>>
make_port(link_driver_ptr driver, reassembly_limits limits,
          frame_writer writer = {});

} // namespace herm
