#pragma once

// A host on the same UDP segment as a module, without its key: it crafts
// frames byte by byte (HERM's own encoders for well-formed packets, raw
// bytes for malformed ones) and sends them from as many source addresses as
// it likes. Loopback only. Used by the adversarial suite
// (tests/adversarial/hostile_network_test.cpp).

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <optional>
#include <vector>

#include "actors/asl_wire.hpp"
#include "channels/messages.hpp"
#include "routing/wire.hpp"

namespace herm::test {

/// One UDP socket on 127.0.0.1 (an ephemeral port unless given).
class hostile_socket {
public:
  explicit hostile_socket(uint16_t port = 0) {
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0)
      return;
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    sa.sin_port = htons(port);
    socklen_t len = sizeof(sa);
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) != 0
        || ::getsockname(fd_, reinterpret_cast<sockaddr*>(&sa), &len) != 0) {
      ::close(fd_);
      fd_ = -1;
      return;
    }
    port_ = ntohs(sa.sin_port);
  }

  hostile_socket(hostile_socket&& other) noexcept
    : fd_(other.fd_), port_(other.port_) {
    other.fd_ = -1;
  }

  hostile_socket(const hostile_socket&) = delete;
  hostile_socket& operator=(const hostile_socket&) = delete;
  hostile_socket& operator=(hostile_socket&&) = delete;

  ~hostile_socket() {
    if (fd_ >= 0)
      ::close(fd_);
  }

  bool ok() const {
    return fd_ >= 0;
  }

  uint16_t port() const {
    return port_;
  }

  /// Sends one datagram to 127.0.0.1:`to`; false if the kernel refused it.
  bool send(uint16_t to, const byte_buffer& bytes) const {
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    sa.sin_port = htons(to);
    return ::sendto(fd_, bytes.data(), bytes.size(), 0,
                    reinterpret_cast<sockaddr*>(&sa), sizeof(sa))
           == static_cast<ssize_t>(bytes.size());
  }

  /// The next datagram that arrives within `timeout_ms`, if any.
  std::optional<byte_buffer> receive(int timeout_ms) const {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, timeout_ms) != 1)
      return std::nullopt;
    byte_buffer buf(65536);
    auto n = ::recv(fd_, buf.data(), buf.size(), 0);
    if (n < 0)
      return std::nullopt;
    buf.resize(static_cast<size_t>(n));
    return buf;
  }

  /// Drops whatever the module sent us (its hellos and updates).
  void drain() const {
    while (receive(0)) {
    }
  }

private:
  int fd_ = -1;
  uint16_t port_ = 0;
};

/// A packet as one UDP frame: a "single" fragment header (docs/protocol.md,
/// "Fragment header") and the packet.
inline byte_buffer single_frame(const byte_buffer& packet) {
  byte_buffer frame;
  frame.reserve(packet.size() + 1);
  frame.push_back(0x00);
  frame.insert(frame.end(), packet.begin(), packet.end());
  return frame;
}

inline byte_buffer hello_frame(module_id sender, uint64_t instance,
                               uint16_t seqno, uint16_t interval_ms) {
  byte_buffer packet;
  encode(hello{sender, instance, seqno, interval_ms}, packet);
  return single_frame(packet);
}

/// An update from `sender` advertising destinations [first, first + count)
/// (count <= max_update_entries), each one hop beyond the sender over
/// Ethernet, at a small metric in every class.
inline byte_buffer update_frame(module_id sender, uint64_t instance,
                                module_id first, size_t count,
                                uint16_t seqno = 1) {
  update u;
  u.sender = sender;
  u.instance = instance;
  for (size_t i = 0; i < count; ++i) {
    advertised a;
    a.origin = static_cast<module_id>(first + i);
    a.seqno = seqno;
    for (size_t k = 0; k < size_classes; ++k) {
      a.metrics[k] = 10;
      a.hops[k] = 1;
      a.path[k] = {link_code::ethernet};
    }
    u.entries.push_back(std::move(a));
  }
  byte_buffer packet;
  encode(u, packet);
  return single_frame(packet);
}

/// An update in which `sender` advertises itself (origin = sender, no
/// hops): the receiver then has a route back to it and answers it.
inline byte_buffer self_update_frame(module_id sender, uint64_t instance,
                                     uint16_t seqno = 1) {
  update u;
  u.sender = sender;
  u.instance = instance;
  advertised a;
  a.origin = sender;
  a.seqno = seqno;
  a.metrics.fill(0);
  u.entries.push_back(std::move(a));
  byte_buffer packet;
  encode(u, packet);
  return single_frame(packet);
}

/// A data packet from `src` to `dst` (a flooded broadcast when dst is
/// broadcast_module and flood_id is not 0) carrying `payload`.
inline byte_buffer data_frame(module_id src, module_id dst, uint8_t protocol,
                              const byte_buffer& payload,
                              uint32_t flood_id = 0) {
  data_header h;
  h.src = src;
  h.dst = dst;
  h.protocol = protocol;
  h.flood_id = flood_id;
  byte_buffer packet;
  encode(h, packet);
  packet.insert(packet.end(), payload.begin(), payload.end());
  return single_frame(packet);
}

/// An APO message from `src` to `dst` (docs/protocol.md, "APO messages").
inline byte_buffer asl_frame(module_id src, module_id dst,
                             const asl_message& msg, uint32_t flood_id = 0) {
  byte_buffer payload;
  encode(msg, payload);
  return data_frame(src, dst, asl_protocol, payload, flood_id);
}

} // namespace herm::test
