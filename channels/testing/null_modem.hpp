#pragma once

// A null-modem cable for tests and benchmarks of the "serial" link kind:
// two pseudo-terminal pairs whose slave paths are the two ends of the cable
// (open one driver on each), and a relay thread that copies bytes from one
// master to the other in both directions, paced like a real line at a
// configured baud rate, optionally with line noise (dropped, flipped and
// inserted bytes, from a seeded generator). unplug() closes the masters, so
// both ends see a hangup, as when a USB adapter is pulled.
//
// Pacing: every byte occupies the line for bits_per_char / baud seconds
// (10 bits for 8N1). Deadlines are absolute: byte k of a busy period is due
// at start + (k + 1) * bits_per_char / baud, so the average rate is exact no
// matter how late the relay wakes; it wakes at most every quantum (1 ms) and
// then hands over every byte that is due, like a UART with a FIFO. A line
// that ran dry starts a new busy period (no credit for idle time). Bytes
// wait in the relay (at most max_in_flight per direction) and, beyond that,
// in the kernel's pty buffers, which is where a writer meets back pressure.
//
// Threading: the public functions may be called from any thread. The
// destructor stops and joins the relay and closes every descriptor.
//
// Header-only and free of GoogleTest, so benchmarks can use it too.

#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <pty.h>
#include <sys/eventfd.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include "channels/drivers/posix.hpp"

namespace herm::test {

/// One pseudo-terminal: the master (non-blocking) and the slave, kept open so
/// that the pair lives until close_pty, in raw mode.
struct pty_pair {
  int master = -1;
  int slave = -1;
  /// Path of the slave, e.g. /dev/pts/3.
  std::string path;
};

inline void close_pty(pty_pair& p) {
  if (p.master >= 0)
    ::close(p.master);
  if (p.slave >= 0)
    ::close(p.slave);
  p.master = -1;
  p.slave = -1;
}

/// Opens a pty pair in raw mode. False and `error` set on failure.
inline bool open_pty(pty_pair& p, std::string& error) {
  termios tio;
  std::memset(&tio, 0, sizeof(tio));
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  ::cfsetispeed(&tio, B115200);
  ::cfsetospeed(&tio, B115200);
  char name[128] = {};
  if (::openpty(&p.master, &p.slave, name, &tio, nullptr) != 0) {
    error = "openpty failed: "
            + std::error_code(errno, std::generic_category()).message();
    return false;
  }
  ::fcntl(p.master, F_SETFD, FD_CLOEXEC);
  ::fcntl(p.slave, F_SETFD, FD_CLOEXEC);
  ::fcntl(p.master, F_SETFL, ::fcntl(p.master, F_GETFL) | O_NONBLOCK);
  p.path = name;
  return true;
}

/// Line noise, each a probability per byte in [0, 1].
struct line_faults {
  /// The byte vanishes.
  double drop = 0;
  /// One random bit of the byte flips.
  double flip = 0;
  /// A random byte follows the byte.
  double insert = 0;
};

class null_modem {
public:
  struct config {
    /// Line rate in bit/s.
    uint64_t baud = 115200;
    /// Bits per byte on the line: start + data + parity + stop.
    unsigned bits_per_char = 10;
    line_faults faults;
    uint64_t seed = 1;
    /// Bytes a direction holds in the relay; the rest waits in the kernel.
    size_t max_in_flight = 1024;
  };

  /// Counters of one direction.
  struct direction_stats {
    uint64_t read = 0;     ///< bytes taken from the sending end
    uint64_t written = 0;  ///< bytes handed to the receiving end
    uint64_t dropped = 0;
    uint64_t flipped = 0;
    uint64_t inserted = 0;
  };

  /// Opens both ptys and starts the relay. nullptr with `error` set when
  /// ptys are unavailable.
  static std::unique_ptr<null_modem> open(const config& cfg,
                                          std::string& error) {
    std::unique_ptr<null_modem> result{new null_modem(cfg)};
    if (!open_pty(result->a_, error) || !open_pty(result->b_, error))
      return nullptr;
    result->wake_fd_ = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (result->wake_fd_ < 0) {
      error = "eventfd failed: "
              + std::error_code(errno, std::generic_category()).message();
      return nullptr;
    }
    if (auto why = posix::start_thread(result->thread_, "relay",
                                       [p = result.get()] { p->run(); })) {
      error = std::move(*why);
      return nullptr;
    }
    return result;
  }

  null_modem(const null_modem&) = delete;
  null_modem& operator=(const null_modem&) = delete;

  ~null_modem() {
    halt();
    close_pty(a_);
    close_pty(b_);
    if (wake_fd_ >= 0)
      ::close(wake_fd_);
  }

  /// Slave path of end A, e.g. /dev/pts/3.
  const std::string& path_a() const {
    return a_.path;
  }

  /// Slave path of end B.
  const std::string& path_b() const {
    return b_.path;
  }

  /// The relay's own descriptor of end A's slave (to inspect its termios).
  int slave_fd_a() const {
    return a_.slave;
  }

  int slave_fd_b() const {
    return b_.slave;
  }

  /// Pulls the cable: stops the relay and closes both masters, so both
  /// slaves hang up. Idempotent.
  void unplug() {
    halt();
    std::lock_guard<std::mutex> guard{mtx_};
    for (auto* p : {&a_, &b_})
      if (p->master >= 0) {
        ::close(p->master);
        p->master = -1;
      }
  }

  /// While paused, the relay reads nothing: the line stalls and the
  /// writers' kernel buffers fill up.
  void pause(bool paused) {
    paused_.store(paused);
    poke();
  }

  void set_faults(const line_faults& faults) {
    std::lock_guard<std::mutex> guard{mtx_};
    cfg_.faults = faults;
  }

  direction_stats a_to_b() const {
    return snapshot(dirs_[0]);
  }

  direction_stats b_to_a() const {
    return snapshot(dirs_[1]);
  }

  /// True when no byte is on its way: none waits in the relay and none in
  /// the masters' input. (The receiving drivers may still be reading.)
  bool drained() const {
    std::lock_guard<std::mutex> guard{mtx_};
    for (auto& d : dirs_)
      if (d.queued.load() != 0)
        return false;
    for (auto* p : {&a_, &b_}) {
      int n = 0;
      if (p->master >= 0 && ::ioctl(p->master, FIONREAD, &n) == 0 && n > 0)
        return false;
    }
    return true;
  }

private:
  struct direction {
    /// Bytes and the time (ns) they are due at the receiving end.
    std::deque<std::pair<int64_t, uint8_t>> queue;
    /// Start of the current busy period and bytes scheduled in it.
    int64_t period_start = 0;
    uint64_t period_bytes = 0;
    int64_t last_due = 0;
    /// The receiving master took only part of the due bytes: wait for
    /// POLLOUT.
    bool blocked = false;
    std::atomic<uint64_t> queued{0};
    std::atomic<uint64_t> read{0};
    std::atomic<uint64_t> written{0};
    std::atomic<uint64_t> dropped{0};
    std::atomic<uint64_t> flipped{0};
    std::atomic<uint64_t> inserted{0};
  };

  static constexpr int64_t quantum_ns = 1'000'000;

  explicit null_modem(const config& cfg) : cfg_(cfg), rng_(cfg.seed) {
  }

  static int64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
  }

  static direction_stats snapshot(const direction& d) {
    direction_stats st;
    st.read = d.read.load();
    st.written = d.written.load();
    st.dropped = d.dropped.load();
    st.flipped = d.flipped.load();
    st.inserted = d.inserted.load();
    return st;
  }

  void poke() {
    posix::signal_eventfd(wake_fd_);
  }

  void halt() {
    stop_.store(true);
    poke();
    if (thread_.joinable())
      thread_.join();
  }

  /// Puts one byte on the line of `d` at `now`.
  void schedule(direction& d, uint8_t x, int64_t now) {
    if (d.queue.empty() && d.last_due <= now) {
      d.period_start = now;
      d.period_bytes = 0;
    }
    ++d.period_bytes;
    d.last_due = d.period_start
                 + static_cast<int64_t>(d.period_bytes * cfg_.bits_per_char
                                        * 1'000'000'000ull / cfg_.baud);
    d.queue.emplace_back(d.last_due, x);
  }

  /// Takes what the sending master has (up to max_in_flight), with noise.
  void take(direction& d, int from, int64_t now) {
    uint8_t buf[512];
    auto room = cfg_.max_in_flight - std::min(cfg_.max_in_flight,
                                              d.queue.size());
    if (room == 0)
      return;
    auto n = ::read(from, buf, std::min(room, sizeof(buf)));
    if (n <= 0)
      return;
    line_faults faults;
    {
      std::lock_guard<std::mutex> guard{mtx_};
      faults = cfg_.faults;
    }
    std::uniform_real_distribution<double> unit{0.0, 1.0};
    d.read += static_cast<uint64_t>(n);
    for (ssize_t i = 0; i < n; ++i) {
      auto x = buf[i];
      if (faults.drop > 0 && unit(rng_) < faults.drop) {
        ++d.dropped;
        continue;
      }
      if (faults.flip > 0 && unit(rng_) < faults.flip) {
        x = static_cast<uint8_t>(x ^ (1u << (rng_() % 8)));
        ++d.flipped;
      }
      schedule(d, x, now);
      if (faults.insert > 0 && unit(rng_) < faults.insert) {
        schedule(d, static_cast<uint8_t>(rng_()), now);
        ++d.inserted;
      }
    }
    d.queued.store(d.queue.size());
  }

  /// Hands every due byte to the receiving master.
  void give(direction& d, int to, int64_t now) {
    uint8_t buf[512];
    for (;;) {
      size_t n = 0;
      while (n < d.queue.size() && n < sizeof(buf) && d.queue[n].first <= now) {
        buf[n] = d.queue[n].second;
        ++n;
      }
      if (n == 0)
        break;
      auto res = ::write(to, buf, n);
      if (res <= 0) {
        d.blocked = res < 0 && (errno == EAGAIN || errno == EWOULDBLOCK);
        break;
      }
      d.blocked = static_cast<size_t>(res) < n;
      d.queue.erase(d.queue.begin(), d.queue.begin() + res);
      d.written += static_cast<uint64_t>(res);
      if (d.blocked)
        break;
    }
    d.queued.store(d.queue.size());
  }

  void run() {
    pthread_setname_np(pthread_self(), "herm-relay");
    // dirs_[0]: A -> B, dirs_[1]: B -> A.
    int masters[2] = {a_.master, b_.master};
    while (!stop_.load()) {
      auto now = now_ns();
      for (int i = 0; i < 2; ++i)
        if (!dirs_[i].blocked)
          give(dirs_[i], masters[1 - i], now);
      int64_t next = -1;
      for (auto& d : dirs_)
        if (!d.blocked && !d.queue.empty())
          next = next < 0 ? d.queue.front().first
                          : std::min(next, d.queue.front().first);
      bool paused = paused_.load();
      pollfd fds[3];
      for (int i = 0; i < 2; ++i) {
        short events = 0;
        if (!paused && dirs_[i].queue.size() < cfg_.max_in_flight)
          events |= POLLIN;
        if (dirs_[1 - i].blocked)
          events |= POLLOUT;
        fds[i] = pollfd{masters[i], events, 0};
      }
      fds[2] = pollfd{wake_fd_, POLLIN, 0};
      timespec ts{};
      timespec* timeout = nullptr;
      if (next >= 0) {
        auto wait = std::max(next - now, quantum_ns);
        ts.tv_sec = static_cast<time_t>(wait / 1'000'000'000);
        ts.tv_nsec = static_cast<long>(wait % 1'000'000'000);
        timeout = &ts;
      }
      if (::ppoll(fds, 3, timeout, nullptr) < 0) {
        if (errno == EINTR)
          continue;
        return;
      }
      if (fds[2].revents != 0) {
        uint64_t count;
        [[maybe_unused]] auto n = ::read(wake_fd_, &count, sizeof(count));
      }
      now = now_ns();
      for (int i = 0; i < 2; ++i) {
        if ((fds[i].revents & POLLOUT) != 0)
          dirs_[1 - i].blocked = false;
        if ((fds[i].revents & POLLIN) != 0)
          take(dirs_[i], masters[i], now);
      }
    }
  }

  /// Guards cfg_.faults and the masters against unplug().
  mutable std::mutex mtx_;
  config cfg_;
  pty_pair a_;
  pty_pair b_;
  int wake_fd_ = -1;
  std::atomic<bool> stop_{false};
  std::atomic<bool> paused_{false};
  std::thread thread_;
  // Relay thread only (but the counters).
  std::mt19937_64 rng_;
  direction dirs_[2];
};

} // namespace herm::test
