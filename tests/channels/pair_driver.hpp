#pragma once

// The driver of the conformance suite's "pair" link kind
// (tests/channels/driver_conformance_test.cpp, which defines and adds the
// kind; docs/architecture.md, "Adding a link kind"): a link kind written
// outside the library, as a program would.

#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"

namespace herm::test {

/// A point-to-point link between two drivers of one process: the two ends of
/// a socketpair(AF_UNIX, SOCK_SEQPACKET), found by the device's interface
/// name. The first device opened on a name is station 1, the second station
/// 2. Empty frames are refused (a zero-length read is the peer's hangup).
///
/// Like every driver it owns no thread: start() watches its socket on the
/// event loop (run_sync: start may be called from any thread), the
/// readiness callback reads a bounded batch and calls the handler on the
/// loop thread, and stop() unwatches it there. The socket stays open until
/// the destructor, so send() needs no lock against stop().
class pair_driver : public link_driver {
public:
  pair_driver(std::string name, int fd, link_addr self, link_profile profile)
    : prefix_("device '" + name + "': "),
      fd_(fd),
      self_(self),
      profile_(std::move(profile)),
      buf_(profile_.mtu) {
  }

  /// Must not run inside the driver's own handler call (nor may the last
  /// reference be dropped there).
  ~pair_driver() override {
    stop();
    ::close(fd_);
  }

  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop& loop) override {
    caf::error result;
    loop.run_sync([&] {
      std::lock_guard<std::mutex> guard{life_mtx_};
      if (handler == nullptr)
        result = make_error(ec::invalid_parameter, prefix_ + "start needs a handler");
      else if (started_)
        result = make_error(ec::device_unavailable, prefix_ + "cannot start again");
      else if (auto err = loop.watch(fd_, EPOLLIN, [this](uint32_t) { on_ready(); }))
        result = make_error(ec::device_unavailable, prefix_ + render(err));
      else {
        handler_ = std::move(handler);
        loop_ = &loop;
      }
      started_ = true;
    });
    return result;
  }

  void stop() override {
    event_loop* loop;
    {
      std::lock_guard<std::mutex> guard{life_mtx_};
      started_ = true; // a stopped driver never starts
      if (stopping_.exchange(true) || loop_ == nullptr)
        return;
      loop = loop_;
    }
    loop->run_sync([this] {
      std::lock_guard<std::mutex> guard{life_mtx_};
      loop_->unwatch(fd_);
      handler_.reset();
    });
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > profile_.mtu)
      return make_error(ec::packet_too_large,
                        prefix_ + "frame of " + std::to_string(size)
                          + " bytes exceeds the MTU of "
                          + std::to_string(profile_.mtu));
    if (size == 0)
      return make_error(ec::invalid_parameter, prefix_ + "empty frame");
    if (dst != broadcast_addr && dst != peer())
      return make_error(ec::invalid_address,
                        prefix_ + "no station " + std::to_string(dst));
    if (stopping_.load())
      return make_error(ec::device_failed, prefix_ + "the device is stopped");
    if (::send(fd_, data, size, MSG_DONTWAIT | MSG_NOSIGNAL) >= 0)
      return caf::none;
    if (errno == EAGAIN || errno == EWOULDBLOCK)
      return make_error(ec::queue_full, prefix_ + "the socket buffer is full");
    return make_error(ec::device_failed, prefix_ + std::strerror(errno));
  }

  const link_profile& profile() const override {
    return profile_;
  }

  link_addr local_addr() const override {
    return self_;
  }

  std::string format_addr(link_addr addr) const override {
    return addr == broadcast_addr ? "*" : std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    if (str == "1" || str == "2")
      return link_addr{str == "1" ? 1u : 2u};
    return make_error(ec::invalid_address,
                      prefix_ + "'" + str + "' is not a pair station (1, 2)");
  }

private:
  /// Frames read per readiness callback at most.
  static constexpr int reads_per_turn = 16;

  link_addr peer() const {
    return 3 - self_;
  }

  /// The socket's readiness callback (loop thread).
  void on_ready() {
    auto keep = handler_; // alive even if a handler call stops the driver
    for (int i = 0; i < reads_per_turn && !stopping_.load(); ++i) {
      auto n = ::recv(fd_, buf_.data(), buf_.size(), MSG_DONTWAIT | MSG_TRUNC);
      if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
        return; // empty: the loop calls again when more arrives
      if (n < 0 && errno == EINTR)
        continue;
      if (n <= 0) {
        loop_->unwatch(fd_); // a hung-up socket stays ready for ever
        return keep->on_failure(
          make_error(ec::device_failed, prefix_ + "the peer hung up"));
      }
      if (static_cast<size_t>(n) > buf_.size())
        keep->on_malformed(peer(), "pair: frame above the MTU");
      else
        keep->on_frame(peer(), buf_.data(), static_cast<size_t>(n));
    }
  }

  std::string prefix_;
  int fd_;
  link_addr self_;
  link_profile profile_;
  byte_buffer buf_; // the loop thread's
  std::mutex life_mtx_;
  bool started_ = false;
  event_loop* loop_ = nullptr;
  std::atomic<bool> stopping_{false};
  std::shared_ptr<frame_handler> handler_;
};

} // namespace herm::test
