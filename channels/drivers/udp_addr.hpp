#pragma once

// Link addresses of the "udp" link kind: an IPv4 address and a UDP port packed
// into a link_addr as (ip << 16) | port, both in host byte order, written
// "10.0.0.2:47000". Header-only so that tests can build raw sockets with the
// same conversions the driver uses.

#include <arpa/inet.h>
#include <netinet/in.h>

#include <cstdint>
#include <cstring>
#include <optional>
#include <string>

#include "channels/messages.hpp"

namespace herm::udp {

/// Largest valid udp link address (48 bits); anything above except
/// broadcast_addr is not an IPv4 endpoint.
constexpr link_addr max_addr = (uint64_t{1} << 48) - 1;

constexpr link_addr make_addr(uint32_t ip, uint16_t port) {
  return (link_addr{ip} << 16) | port;
}

constexpr uint32_t ip_of(link_addr addr) {
  return static_cast<uint32_t>(addr >> 16);
}

constexpr uint16_t port_of(link_addr addr) {
  return static_cast<uint16_t>(addr & 0xFFFF);
}

/// Parses "A.B.C.D:PORT" (dotted-quad decimal, port 0..65535). Port 0 is
/// accepted only when `allow_port_zero` (binding to an ephemeral port); a
/// destination needs a real port. Returns nullopt on any other text,
/// including host names, IPv6, surrounding spaces and signs.
inline std::optional<link_addr> parse_addr(const std::string& text,
                                           bool allow_port_zero) {
  auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size())
    return std::nullopt;
  auto host = text.substr(0, colon);
  auto port_text = text.substr(colon + 1);
  if (port_text.size() > 5)
    return std::nullopt;
  uint32_t port = 0;
  for (char c : port_text) {
    if (c < '0' || c > '9')
      return std::nullopt;
    port = port * 10 + static_cast<uint32_t>(c - '0');
  }
  if (port > 0xFFFF || (port == 0 && !allow_port_zero))
    return std::nullopt;
  in_addr ip{};
  // inet_pton accepts exactly four decimal octets without leading zeros.
  if (inet_pton(AF_INET, host.c_str(), &ip) != 1)
    return std::nullopt;
  return make_addr(ntohl(ip.s_addr), static_cast<uint16_t>(port));
}

/// Formats "A.B.C.D:PORT"; "*" for broadcast_addr and "invalid(N)" for
/// values above max_addr.
inline std::string format_addr(link_addr addr) {
  if (addr == broadcast_addr)
    return "*";
  if (addr > max_addr)
    return "invalid(" + std::to_string(addr) + ")";
  in_addr ip{};
  ip.s_addr = htonl(ip_of(addr));
  char buf[INET_ADDRSTRLEN] = {};
  inet_ntop(AF_INET, &ip, buf, sizeof(buf));
  return std::string{buf} + ':' + std::to_string(port_of(addr));
}

inline sockaddr_in to_sockaddr(link_addr addr) {
  sockaddr_in sa;
  std::memset(&sa, 0, sizeof(sa));
  sa.sin_family = AF_INET;
  sa.sin_addr.s_addr = htonl(ip_of(addr));
  sa.sin_port = htons(port_of(addr));
  return sa;
}

inline link_addr from_sockaddr(const sockaddr_in& sa) {
  return make_addr(ntohl(sa.sin_addr.s_addr), ntohs(sa.sin_port));
}

} // namespace herm::udp
