#pragma once

// A frame_handler for driver tests that records every call: frames (with
// source, lane and arrival time), malformed reports, link events, kernel
// drops and failures. Thread-safe (drivers call it from their receive
// threads); every wait is bounded. An optional hook runs on the driver's
// thread after each frame was recorded, outside the recorder's lock, so a
// test can act from inside a handler (stop the driver, say).

#include <time.h>

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "channels/link_driver.hpp"

namespace herm::test {

class recorder : public frame_handler {
public:
  struct frame {
    link_addr src = 0;
    byte_buffer bytes;
    /// CLOCK_MONOTONIC time of the call, in ns.
    int64_t at_ns = 0;
    uint8_t lane = 0;
  };

  struct malformed {
    link_addr src = 0;
    std::string why;
  };

  struct event {
    link_event_kind kind;
    link_addr peer = 0;
    std::string detail;
  };

  static constexpr std::chrono::milliseconds default_wait{10'000};

  static int64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
  }

  /// Runs `hook` on the driver's thread after every recorded frame. Set it
  /// before the driver starts.
  void on_each_frame(std::function<void(const frame&)> hook) {
    hook_ = std::move(hook);
  }

  void on_frame(link_addr src, const uint8_t* data, size_t size) override {
    on_frame_in_lane(src, 0, data, size);
  }

  void on_frame_in_lane(link_addr src, uint8_t lane, const uint8_t* data,
                        size_t size) override {
    frame f{src, byte_buffer(data, data + size), now_ns(), lane};
    if (hook_)
      hook_(f);
    std::lock_guard<std::mutex> guard{mtx_};
    frames_.push_back(std::move(f));
    cv_.notify_all();
  }

  void on_malformed(link_addr src, const char* why) override {
    std::lock_guard<std::mutex> guard{mtx_};
    malformed_.push_back({src, why});
    cv_.notify_all();
  }

  void on_kernel_drops(uint64_t count) override {
    std::lock_guard<std::mutex> guard{mtx_};
    kernel_drops_ += count;
    cv_.notify_all();
  }

  void on_event(link_event_kind kind, link_addr peer,
                std::string detail) override {
    std::lock_guard<std::mutex> guard{mtx_};
    events_.push_back({kind, peer, std::move(detail)});
    cv_.notify_all();
  }

  void on_failure(caf::error reason) override {
    std::lock_guard<std::mutex> guard{mtx_};
    failures_.push_back(std::move(reason));
    cv_.notify_all();
  }

  // -- bounded waits: false when `timeout` passed first ------------------------

  bool wait_frames(size_t n, std::chrono::milliseconds timeout = default_wait) {
    return wait(timeout, [&] { return frames_.size() >= n; });
  }

  /// Waits for a frame carrying exactly `bytes`.
  bool wait_frame(const byte_buffer& bytes,
                  std::chrono::milliseconds timeout = default_wait) {
    return wait(timeout, [&] {
      for (auto& f : frames_)
        if (f.bytes == bytes)
          return true;
      return false;
    });
  }

  bool wait_malformed(size_t n,
                      std::chrono::milliseconds timeout = default_wait) {
    return wait(timeout, [&] { return malformed_.size() >= n; });
  }

  bool wait_events(size_t n, std::chrono::milliseconds timeout = default_wait) {
    return wait(timeout, [&] { return events_.size() >= n; });
  }

  bool wait_failures(size_t n,
                     std::chrono::milliseconds timeout = default_wait) {
    return wait(timeout, [&] { return failures_.size() >= n; });
  }

  // -- snapshots -------------------------------------------------------------

  std::vector<frame> frames() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return frames_;
  }

  /// The frames' bytes, in arrival order.
  std::vector<byte_buffer> payloads() const {
    std::lock_guard<std::mutex> guard{mtx_};
    std::vector<byte_buffer> result;
    for (auto& f : frames_)
      result.push_back(f.bytes);
    return result;
  }

  /// The frames' sources, in arrival order.
  std::vector<link_addr> sources() const {
    std::lock_guard<std::mutex> guard{mtx_};
    std::vector<link_addr> result;
    for (auto& f : frames_)
      result.push_back(f.src);
    return result;
  }

  /// Sum of the frames' sizes in bytes.
  size_t bytes() const {
    std::lock_guard<std::mutex> guard{mtx_};
    size_t n = 0;
    for (auto& f : frames_)
      n += f.bytes.size();
    return n;
  }

  std::vector<malformed> malformed_frames() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return malformed_;
  }

  std::vector<event> events() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return events_;
  }

  std::vector<caf::error> failures() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return failures_;
  }

  uint64_t kernel_drops() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return kernel_drops_;
  }

  /// Frames plus malformed reports: grows while anything arrives.
  size_t activity() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return frames_.size() + malformed_.size();
  }

private:
  template <class Pred>
  bool wait(std::chrono::milliseconds timeout, Pred pred) {
    std::unique_lock<std::mutex> lk{mtx_};
    return cv_.wait_for(lk, timeout, pred);
  }

  std::function<void(const frame&)> hook_;
  mutable std::mutex mtx_;
  std::condition_variable cv_;
  std::vector<frame> frames_;
  std::vector<malformed> malformed_;
  std::vector<event> events_;
  std::vector<caf::error> failures_;
  uint64_t kernel_drops_ = 0;
};

} // namespace herm::test
