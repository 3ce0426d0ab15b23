// Raw UDP ping-pong with blocking sockets: the floor every other transport
// is compared with. One datagram each way, no framing. oneway: a plain
// `send` loop (or `sendmmsg` batches) on one blocking socket under the
// credit window; the receiver acknowledges to the sender's address.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <algorithm>
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

using result_datagram = oneway_result_msg;
using ack_datagram = oneway_ack_msg;

/// Receives datagrams of up to 64 KiB on the blocking socket `fd` forever,
/// calling `on(data, n, from, from_len)` for each: `n` is recvfrom's result
/// (negative on a failed receive), `from` the sender's address.
template <class OnDatagram>
[[noreturn]] void for_each_datagram(int fd, OnDatagram on) {
  std::vector<uint8_t> buf(65536);
  for (;;) {
    sockaddr_in from{};
    socklen_t from_len = sizeof(from);
    auto n = ::recvfrom(fd, buf.data(), buf.size(), 0,
                        reinterpret_cast<sockaddr*>(&from), &from_len);
    on(buf.data(), n, reinterpret_cast<const sockaddr*>(&from), from_len);
  }
}

/// oneway receiver: counts data datagrams, acknowledges to their sender,
/// answers a done datagram with the figures.
[[noreturn]] void udp_count(int fd, const endpoint_params& p) {
  auto c = oneway_counter_for(p);
  for_each_datagram(fd, [&](const uint8_t* data, ssize_t n, const sockaddr* from,
                            socklen_t from_len) {
    auto reply = [&](const auto& msg) {
      ::sendto(fd, &msg, sizeof(msg), 0, from, from_len);
    };
    count_payload(c, data, n, reply, reply);
  });
}

/// oneway sender (see transport.hpp): one send per message, or batches of
/// up to 64 with sendmmsg.
client_result udp_oneway_client(int fd, const endpoint_params& p) {
  timeval tv{};
  tv.tv_sec = p.stall.count() / 1000;
  tv.tv_usec = (p.stall.count() % 1000) * 1000;
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  uint32_t sent = 0; // data datagrams sent so far
  constexpr size_t max_batch = 64;
  std::vector<std::vector<uint8_t>> bufs(p.batch ? max_batch : 1,
                                         std::vector<uint8_t>(p.size));
  std::vector<mmsghdr> msgs(max_batch);
  std::vector<iovec> iovs(max_batch);
  auto send_some = [&](uint32_t first, uint32_t room, uint32_t& n) -> std::string {
    if (!p.batch) {
      fill_payload(bufs[0], first);
      if (::send(fd, bufs[0].data(), p.size, 0) != static_cast<ssize_t>(p.size))
        return errno_text("udp send");
      n = 1;
    } else {
      size_t k = std::min<size_t>(room, max_batch);
      for (size_t i = 0; i < k; ++i) {
        fill_payload(bufs[i], first + static_cast<uint32_t>(i));
        iovs[i] = {bufs[i].data(), p.size};
        msgs[i] = {};
        msgs[i].msg_hdr.msg_iov = &iovs[i];
        msgs[i].msg_hdr.msg_iovlen = 1;
      }
      auto m = ::sendmmsg(fd, msgs.data(), static_cast<unsigned>(k), 0);
      if (m <= 0)
        return errno_text("udp sendmmsg");
      n = static_cast<uint32_t>(m);
    }
    sent = first + n;
    return {};
  };
  uint8_t in[64];
  auto read_acks = [&](bool block, uint32_t& acked) {
    for (;;) {
      auto n = ::recv(fd, in, sizeof(in), block ? 0 : MSG_DONTWAIT);
      if (n < 0)
        return;
      block = false;
      if (n == sizeof(ack_datagram) && payload_seq(in, 4) == oneway_ack) {
        ack_datagram a;
        std::memcpy(&a, in, sizeof(a));
        if (a.acked > acked && a.acked <= sent)
          acked = a.acked;
      }
    }
  };
  auto get_result = [&](client_result& res) -> std::string {
    for (int tries = 0; tries < 20; ++tries) {
      uint32_t done = oneway_done;
      ::send(fd, &done, sizeof(done), 0);
      uint8_t r_buf[64];
      ssize_t n;
      while ((n = ::recv(fd, r_buf, sizeof(r_buf), 0)) >= 0)
        if (n == sizeof(result_datagram) && payload_seq(r_buf, 4) == oneway_result)
          break;
      if (n == sizeof(result_datagram)) {
        result_datagram r;
        std::memcpy(&r, r_buf, sizeof(r));
        res.received = r.received;
        res.elapsed_ns = r.elapsed_ns;
        res.server_allocs = r.allocs;
        return {};
      }
    }
    return "udp: no result from the receiver";
  };
  return run_oneway_batch_sender(p, send_some, read_acks, get_result);
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
  if (p.mode == "oneway")
    udp_count(fd, p);
  for_each_datagram(fd, [fd](const uint8_t* data, ssize_t n, const sockaddr* from,
                             socklen_t from_len) {
    if (n >= 0)
      ::sendto(fd, data, static_cast<size_t>(n), 0, from, from_len);
  });
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
  if (p.mode == "oneway")
    return udp_oneway_client(fd, p);
  std::vector<uint8_t> out(p.size), in(p.size + 64);
  run_round_trips(p, out, res, [&](uint32_t seq) {
    if (::send(fd, out.data(), out.size(), 0) != static_cast<ssize_t>(out.size())) {
      res.error = errno_text("udp send");
      return round_trip::failed;
    }
    ssize_t n;
    do {
      n = ::recv(fd, in.data(), in.size(), 0);
      // A late reply to an earlier request would be a bug in the server:
      // there is none, since every request waits for its reply.
    } while (n >= 0 && payload_seq(in.data(), static_cast<size_t>(n)) != seq);
    if (n != static_cast<ssize_t>(out.size())) {
      res.error = n < 0 ? errno_text("udp recv")
                        : "udp reply of " + std::to_string(n) + " bytes";
      return round_trip::failed;
    }
    return round_trip::replied;
  });
  ::close(fd);
  return res;
}

} // namespace herm::bench
