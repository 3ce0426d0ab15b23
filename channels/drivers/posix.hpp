#pragma once

// Small POSIX helpers shared by the descriptor-based link kinds.

#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <system_error>
#include <thread>
#include <utility>

namespace herm::posix {

/// CLOCK_MONOTONIC in nanoseconds (system-wide: processes agree on it).
inline int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

/// The text of an errno value. (std::strerror is not thread-safe; the
/// generic category is.)
inline std::string errno_text(int err) {
  return std::error_code(err, std::generic_category()).message();
}

/// Owns one file descriptor.
class unique_fd {
public:
  unique_fd() = default;
  explicit unique_fd(int fd) : fd_(fd) {}
  unique_fd(const unique_fd&) = delete;
  unique_fd& operator=(const unique_fd&) = delete;
  unique_fd(unique_fd&& other) noexcept : fd_(other.release()) {}
  unique_fd& operator=(unique_fd&& other) noexcept {
    reset(other.release());
    return *this;
  }
  ~unique_fd() {
    reset();
  }
  int get() const {
    return fd_;
  }
  int release() {
    return std::exchange(fd_, -1);
  }
  void reset(int fd = -1) {
    if (fd_ >= 0)
      ::close(fd_);
    fd_ = fd;
  }
  explicit operator bool() const {
    return fd_ >= 0;
  }

private:
  int fd_ = -1;
};

/// Adds 1 to the eventfd `fd`, waking whoever polls it; does nothing when
/// `fd` < 0. A write of 1 fails only when the counter would overflow
/// (2^64 - 2 wake-ups pending), which no reader lets happen, so nothing is
/// reported. Any thread; never blocks (the eventfd is non-blocking).
inline void signal_eventfd(int fd) {
  if (fd < 0)
    return;
  uint64_t one = 1;
  [[maybe_unused]] auto res = ::write(fd, &one, sizeof(one));
}

/// Starts `thread` (not joinable on entry) running `body`. Returns nullopt
/// when it runs, else the reason, word for word "cannot start the " + `what`
/// + " thread: " + the system's text; `thread` stays not joinable then.
template <class F>
std::optional<std::string>
start_thread(std::thread& thread, const char* what, F&& body) {
  try {
    thread = std::thread{std::forward<F>(body)};
  } catch (const std::system_error& ex) {
    return std::string{"cannot start the "} + what + " thread: " + ex.what();
  }
  return std::nullopt;
}

/// The kernel's receive-buffer drop count of a socket with SO_RXQ_OVFL
/// enabled. The kernel attaches its cumulative count (modulo 2^32) to a
/// datagram or frame received once drops have happened; `drops_since`
/// turns that into the number dropped since the count last seen. One per
/// socket, used by its receiving thread only.
class rxq_overflow {
public:
  /// Frames dropped since the last call that saw a count; 0 when `msg`
  /// carries none.
  uint32_t drops_since(const msghdr& msg) {
    uint32_t delta = 0;
    for (auto* c = CMSG_FIRSTHDR(&msg); c != nullptr;
         c = CMSG_NXTHDR(const_cast<msghdr*>(&msg), c)) {
      if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SO_RXQ_OVFL
          || c->cmsg_len < CMSG_LEN(sizeof(uint32_t)))
        continue;
      uint32_t total;
      std::memcpy(&total, CMSG_DATA(c), sizeof(total));
      delta += static_cast<uint32_t>(total - seen_);
      seen_ = total;
    }
    return delta;
  }

private:
  uint32_t seen_ = 0;
};

} // namespace herm::posix
