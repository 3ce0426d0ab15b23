// Raw UDP ping-pong with blocking sockets: the floor every other transport
// is compared with. One datagram each way, no framing.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <iostream>
#include <thread>

#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

void fill_payload(std::vector<uint8_t>& buf, uint32_t seq) {
  for (size_t i = 0; i < buf.size(); ++i)
    buf[i] = static_cast<uint8_t>(i * 31 + seq);
  if (buf.size() >= 4)
    std::memcpy(buf.data(), &seq, 4);
}

uint32_t payload_seq(const uint8_t* data, size_t size) {
  uint32_t seq = 0;
  if (size >= 4)
    std::memcpy(&seq, data, 4);
  return seq;
}

namespace {

sockaddr_in loopback(uint16_t port) {
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  return addr;
}

std::string errno_text(const char* what) {
  return std::string{what} + ": " + std::strerror(errno);
}

} // namespace

int udp_server(const endpoint_params& p) {
  int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  auto addr = loopback(p.port);
  socklen_t len = sizeof(addr);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&addr), len) != 0
      || ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    std::cout << "error " << errno_text("udp bind") << std::endl;
    return 1;
  }
  std::cout << "ready " << ntohs(addr.sin_port) << std::endl;
  std::vector<uint8_t> buf(65536);
  for (;;) {
    sockaddr_in from{};
    socklen_t from_len = sizeof(from);
    auto n = ::recvfrom(fd, buf.data(), buf.size(), 0,
                        reinterpret_cast<sockaddr*>(&from), &from_len);
    if (n < 0)
      continue;
    ::sendto(fd, buf.data(), static_cast<size_t>(n), 0,
             reinterpret_cast<sockaddr*>(&from), from_len);
  }
}

client_result udp_client(const endpoint_params& p) {
  client_result res;
  int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  auto addr = loopback(p.port);
  timeval tv{};
  tv.tv_sec = p.timeout.count() / 1000;
  tv.tv_usec = (p.timeout.count() % 1000) * 1000;
  if (fd < 0
      || ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0
      || ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv)) != 0) {
    res.error = errno_text("udp connect");
    return res;
  }
  std::vector<uint8_t> out(p.size), in(p.size + 64);
  res.rtt_ns.reserve(p.count);
  for (uint32_t i = 0; i < p.warmup + p.count; ++i) {
    fill_payload(out, i);
    auto t0 = now_ns();
    if (::send(fd, out.data(), out.size(), 0) != static_cast<ssize_t>(out.size())) {
      res.error = errno_text("udp send");
      return res;
    }
    ssize_t n;
    do {
      n = ::recv(fd, in.data(), in.size(), 0);
      // A late reply to an earlier request would be a bug in the server:
      // there is none, since every request waits for its reply.
    } while (n >= 0 && payload_seq(in.data(), static_cast<size_t>(n)) != i);
    auto t1 = now_ns();
    if (n != static_cast<ssize_t>(out.size())) {
      res.error = n < 0 ? errno_text("udp recv")
                        : "udp reply of " + std::to_string(n) + " bytes";
      return res;
    }
    if (i >= p.warmup)
      res.rtt_ns.push_back(t1 - t0);
    if (p.gap.count() > 0)
      std::this_thread::sleep_for(p.gap);
  }
  ::close(fd);
  return res;
}

} // namespace herm::bench
