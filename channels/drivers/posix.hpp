#pragma once

// Small POSIX helpers shared by the descriptor-based link kinds.

#include <time.h>
#include <unistd.h>

#include <cstdint>
#include <string>
#include <system_error>
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

} // namespace herm::posix
