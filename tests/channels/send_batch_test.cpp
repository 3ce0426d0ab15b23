// link_driver::send_batch (channels/link_driver.hpp): the default over
// send() and the udp driver's sendmmsg path on loopback. The conformance
// suite checks send_batch on every kind; the channel's backlog draining
// through it is in channel_backlog_test.cpp.
//
// A full socket buffer cannot be had on loopback UDP (the kernel frees a
// datagram's send-buffer charge as soon as it is queued at the receiver), so
// partial takes are checked over a scripted driver here and over the
// "gate" kind in channel_backlog_test.cpp.
//
// Every wait is bounded; no test asserts speed.

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

#include "channels/error.hpp"
#include "channels/link_driver.hpp"

namespace herm {
namespace {

using namespace std::chrono_literals;

byte_buffer bytes_of(const std::string& text) {
  return byte_buffer(text.begin(), text.end());
}

std::vector<tx_frame> frames_of(const std::vector<byte_buffer>& payloads,
                                link_addr dst) {
  std::vector<tx_frame> result;
  for (auto& p : payloads)
    result.push_back(tx_frame{dst, p.data(), p.size(), prio_normal});
  return result;
}

// -- the default implementation ------------------------------------------------

/// A driver with only send(): it records what it took and answers by the
/// frame's first byte: 'F' queue_full, 'X' packet_too_large, else taken.
class scripted_driver : public link_driver {
public:
  std::vector<std::string> taken;

  caf::error start(std::shared_ptr<frame_handler>, event_loop&) override {
    return caf::none;
  }

  void stop() override {
    // nop
  }

  caf::error send(link_addr, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > 0 && data[0] == 'F')
      return make_error(ec::queue_full, "full");
    if (size > 0 && data[0] == 'X')
      return make_error(ec::packet_too_large, "too large");
    taken.emplace_back(data, data + size);
    return caf::none;
  }

  const link_profile& profile() const override {
    return profile_;
  }

  link_addr local_addr() const override {
    return 1;
  }

  std::string format_addr(link_addr addr) const override {
    return std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string&) const override {
    return make_error(ec::invalid_address, "none");
  }

private:
  link_profile profile_;
};

struct default_case {
  const char* name;
  std::vector<std::string> frames;
  size_t returned;
  std::optional<ec> error;
  std::vector<std::string> taken;
};

TEST(send_batch_default, takes_a_prefix_and_stops_at_the_first_frame_not_taken) {
  std::vector<default_case> cases{
    {"all taken", {"a", "b", "c"}, 3, std::nullopt, {"a", "b", "c"}},
    {"none given", {}, 0, std::nullopt, {}},
    {"full in the middle", {"a", "b", "F", "c"}, 2, ec::queue_full, {"a", "b"}},
    {"full at once", {"F", "a"}, 0, ec::queue_full, {}},
    {"refused in the middle", {"a", "X", "b"}, 1, ec::packet_too_large, {"a"}},
    {"refused last", {"a", "b", "X"}, 2, ec::packet_too_large, {"a", "b"}},
  };
  for (auto& c : cases) {
    scripted_driver drv;
    std::vector<byte_buffer> payloads;
    for (auto& f : c.frames)
      payloads.push_back(bytes_of(f));
    auto frames = frames_of(payloads, 2);
    caf::error err = make_error(ec::device_failed, "stale");
    auto n = drv.send_batch(frames.data(), frames.size(), err);
    EXPECT_EQ(n, c.returned) << c.name;
    if (c.error) {
      EXPECT_TRUE(is(err, *c.error)) << c.name << ": " << render(err);
    } else {
      EXPECT_FALSE(err) << c.name << ": " << render(err);
    }
    EXPECT_EQ(drv.taken, c.taken) << c.name;
  }
}

// -- udp: one sendmmsg per run of unicast frames ---------------------------------

/// A plain UDP socket on 127.0.0.1 that receives what the driver sends.
class receiver {
public:
  receiver() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    int big = 4 << 20;
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &big, sizeof(big));
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) != 0)
      return;
    socklen_t len = sizeof(sa);
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&sa), &len);
    port_ = ntohs(sa.sin_port);
  }

  ~receiver() {
    ::close(fd_);
  }

  uint16_t port() const {
    return port_;
  }

  std::string endpoint() const {
    return "127.0.0.1:" + std::to_string(port_);
  }

  link_addr addr() const {
    return (link_addr{0x7F000001} << 16) | port_;
  }

  /// Datagrams until `n` arrived or none came for 2 s.
  std::vector<byte_buffer> take(size_t n) {
    std::vector<byte_buffer> result;
    byte_buffer buf(65536);
    while (result.size() < n) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 2000) <= 0)
        break;
      auto got = ::recv(fd_, buf.data(), buf.size(), 0);
      if (got < 0)
        break;
      result.emplace_back(buf.begin(), buf.begin() + got);
    }
    return result;
  }

private:
  int fd_ = -1;
  uint16_t port_ = 0;
};

class udp_send_batch : public ::testing::Test {
protected:
  /// A started udp driver on 127.0.0.1 whose broadcast goes to `peers`.
  link_driver_ptr open(const std::string& peers = "") {
    device_config cfg{"eth0", "udp", "127.0.0.1:0", {}};
    if (!peers.empty())
      cfg.options["peers"] = peers;
    auto d = find_link_kind("udp")->open(cfg);
    EXPECT_TRUE(d) << render(d.error());
    if (!d)
      return nullptr;
    auto err = (*d)->start(std::make_shared<null_handler>());
    EXPECT_FALSE(err) << render(err);
    drivers_.push_back(*d);
    return *d;
  }

  void TearDown() override {
    for (auto& d : drivers_)
      d->stop();
  }

  struct null_handler : frame_handler {
    void on_frame(link_addr, const uint8_t*, size_t) override {
    }
    void on_malformed(link_addr, const char*) override {
    }
    void on_event(link_event_kind, link_addr, std::string) override {
    }
    void on_failure(caf::error) override {
    }
  };

  std::vector<link_driver_ptr> drivers_;
};

/// Frame i: its index in the first two bytes, then a pattern; sizes vary
/// from 2 bytes to the MTU.
std::vector<byte_buffer> numbered(size_t n, size_t mtu, size_t first = 0) {
  std::vector<byte_buffer> result;
  for (size_t i = first; i < first + n; ++i) {
    auto size = i % 17 == 16 ? mtu : 2 + (i * 37) % 200;
    byte_buffer f(size);
    for (size_t j = 0; j < size; ++j)
      f[j] = static_cast<uint8_t>(i * 3 + j);
    f[0] = static_cast<uint8_t>(i >> 8);
    f[1] = static_cast<uint8_t>(i);
    result.push_back(std::move(f));
  }
  return result;
}

TEST_F(udp_send_batch, delivers_every_frame_in_order_across_several_sendmmsg_calls) {
  receiver rx;
  ASSERT_NE(rx.port(), 0);
  auto drv = open();
  ASSERT_NE(drv, nullptr);
  // More than two of the driver's 64-frame chunks.
  auto payloads = numbered(150, drv->profile().mtu);
  auto frames = frames_of(payloads, rx.addr());
  caf::error err;
  EXPECT_EQ(drv->send_batch(frames.data(), frames.size(), err), frames.size());
  EXPECT_FALSE(err) << render(err);
  EXPECT_EQ(rx.take(payloads.size()), payloads);
}

struct refusal_case {
  const char* name;
  byte_buffer bad;
  link_addr bad_dst; // 0: the receiver
  ec code;
};

TEST_F(udp_send_batch, a_refused_frame_stops_the_batch_after_the_frames_before_it) {
  receiver rx;
  ASSERT_NE(rx.port(), 0);
  auto drv = open();
  ASSERT_NE(drv, nullptr);
  auto mtu = drv->profile().mtu;
  std::vector<refusal_case> cases{
    {"above the MTU", byte_buffer(mtu + 1, 'x'), 0, ec::packet_too_large},
    {"empty", byte_buffer{}, 0, ec::invalid_parameter},
    {"port 0", bytes_of("x"), link_addr{0x7F000001} << 16, ec::invalid_address},
  };
  for (auto& c : cases) {
    auto before = numbered(5, mtu);
    auto after = numbered(4, mtu, 5);
    auto frames = frames_of(before, rx.addr());
    frames.push_back(tx_frame{c.bad_dst != 0 ? c.bad_dst : rx.addr(),
                              c.bad.data(), c.bad.size(), prio_normal});
    for (auto& f : frames_of(after, rx.addr()))
      frames.push_back(f);
    caf::error err;
    EXPECT_EQ(drv->send_batch(frames.data(), frames.size(), err), 5u) << c.name;
    EXPECT_TRUE(is(err, c.code)) << c.name << ": " << render(err);
    EXPECT_NE(render(err).find("device 'eth0'"), std::string::npos) << render(err);
    // The frames before it left; nothing after it did. The caller drops
    // the refused frame and goes on with the rest.
    EXPECT_EQ(drv->send_batch(frames.data() + 6, frames.size() - 6, err), 4u)
      << c.name;
    EXPECT_FALSE(err) << c.name << ": " << render(err);
    auto want = before;
    want.insert(want.end(), after.begin(), after.end());
    EXPECT_EQ(rx.take(want.size()), want) << c.name;
  }
}

TEST_F(udp_send_batch, broadcast_frames_reach_every_peer_in_order_with_the_unicast_ones) {
  receiver a;
  receiver b;
  ASSERT_TRUE(a.port() != 0 && b.port() != 0);
  auto drv = open(a.endpoint() + "," + b.endpoint());
  ASSERT_NE(drv, nullptr);
  auto one = bytes_of("1");
  auto two = bytes_of("2");
  auto three = bytes_of("3");
  std::vector<tx_frame> frames{{a.addr(), one.data(), 1, prio_normal},
                               {broadcast_addr, two.data(), 1, prio_normal},
                               {a.addr(), three.data(), 1, prio_normal}};
  caf::error err;
  EXPECT_EQ(drv->send_batch(frames.data(), frames.size(), err), 3u);
  EXPECT_FALSE(err) << render(err);
  EXPECT_EQ(a.take(3), (std::vector<byte_buffer>{one, two, three}));
  EXPECT_EQ(b.take(1), std::vector<byte_buffer>{two});
}

TEST_F(udp_send_batch, a_stopped_driver_takes_nothing) {
  receiver rx;
  auto drv = open();
  ASSERT_NE(drv, nullptr);
  drv->stop();
  auto payloads = numbered(3, drv->profile().mtu);
  auto frames = frames_of(payloads, rx.addr());
  caf::error err;
  EXPECT_EQ(drv->send_batch(frames.data(), frames.size(), err), 0u);
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
}

} // namespace
} // namespace herm

// The channel's backlog through send_batch: channel_backlog_test.cpp.
