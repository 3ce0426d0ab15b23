// The "serial" link kind: a point-to-point byte line (RS232C to a
// microcontroller, a USB serial adapter, a USB CDC-ACM device, or a pty in
// tests). Frames are COBS-encoded with a CRC-16 and delimited by 0x00 (see
// serial_framing.hpp and docs/protocol.md (serial framing)); options are resolved in
// serial_settings.hpp.
//
// Addresses: the line has two ends. Frames from the other end carry src 1
// ("peer"); this end is 0 ("local"). send() to 1 or to broadcast_addr goes
// down the line.
//
// Threading (the event-loop contract, channels/event_loop.hpp): the driver
// owns no thread. start() registers the tty with the module's event loop
// (through run_sync, so any thread may call it), for input and, while
// encoded bytes wait for the line, for output. The readiness callback reads
// at most rx_reads_per_turn chunks, feeds the decoder and calls the handler,
// then returns to the loop (level-triggered: it is called again next turn
// while input waits), so one busy line cannot starve other links. Every
// handler call, on_failure included, happens on the loop thread. A hangup
// (pty master closed, USB adapter unplugged: EPOLLHUP, EOF, EIO, ENODEV) is
// reported once with on_failure and the tty is no longer watched.
//
// send() and set_param() may be called from any thread; they hold tx_mtx_,
// which also guards the descriptor against stop(). send() encodes into a
// bounded transmit buffer and makes one non-blocking write() when the buffer
// was empty; what the tty did not take stays buffered and is written from
// the callback on EPOLLOUT, so a short write never splits a frame from its
// successor. Watching for EPOLLOUT is a loop-thread change: send() makes it
// at once on the loop thread, else posts it (the posted task checks a shared
// alive flag, so it does nothing once the driver stopped or died).
//
// stop() is idempotent and may be called from any thread: on the loop
// thread (run_sync) it unwatches the tty, discards what was not sent,
// closes the line and drops the handler; no handler call follows its
// return. Called from a handler it ends delivery at once: the callback sees
// watch_.stopping() and touches the descriptor no more.
//
// Ownership of the line: flock(LOCK_EX | LOCK_NB) on the open tty
// (LOCK_SH with exclusive: false), as picocom and other serial tools do.
// The kernel releases it with the last descriptor of the open file, so it
// dies with its holder, also on SIGKILL: a restarted module gets its line
// back at once. TIOCEXCL is deliberately not used: the flag belongs to the
// tty, not to the process, so a holder killed with SIGKILL leaves it set
// for as long as the line stays open elsewhere (the master of a pty, a
// relay, getty), and then every restart fails with EBUSY, which no one
// can tell from a live holder (it also never stopped root). A live holder
// is named from /proc/locks in the refusal.

#include <fcntl.h>
#include <sys/epoll.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <sstream>
#include <memory>
#include <string>
#include <vector>

#include "channels/error.hpp"
#include "channels/drivers/loop_watch.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/drivers/serial_framing.hpp"
#include "channels/drivers/serial_settings.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"

namespace herm {

namespace {

using posix::errno_text;
using posix::now_ns;
using posix::unique_fd;

// -- constants -------------------------------------------------------------------

/// Address of the other end of the line.
constexpr link_addr peer_addr = 1;

/// Address of this end.
constexpr link_addr self_addr = 0;

/// Frames of MTU size the transmit buffer holds on top of the kernel's.
constexpr size_t tx_buffer_frames = 16;

/// Bytes read per read() call.
constexpr size_t rx_chunk = 4096;

/// read() calls per readiness callback at most.
constexpr int rx_reads_per_turn = 4;

// -- helpers ---------------------------------------------------------------------

/// The termios constant of a standard rate (serial::standard_bauds).
speed_t to_speed(uint64_t baud) {
  switch (baud) {
    case 1200: return B1200;
    case 1800: return B1800;
    case 2400: return B2400;
    case 4800: return B4800;
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 500000: return B500000;
    case 576000: return B576000;
    case 921600: return B921600;
    case 1000000: return B1000000;
    case 1152000: return B1152000;
    case 1500000: return B1500000;
    case 2000000: return B2000000;
    case 2500000: return B2500000;
    case 3000000: return B3000000;
    case 3500000: return B3500000;
    case 4000000: return B4000000;
    default: return B0;
  }
}

/// Nanoseconds one character occupies the line.
int64_t char_time_ns(const serial::char_format& fmt, uint64_t baud) {
  return static_cast<int64_t>((fmt.bits_per_char() * 1'000'000'000ull + baud
                               - 1)
                              / baud);
}

/// Applies raw mode, speed, character format and flow control to `fd`.
/// Returns 0 or an errno value; sets `what` to the setting that did not take.
int apply_termios(int fd, const serial::settings& set, std::string& what) {
  termios tio;
  if (::tcgetattr(fd, &tio) != 0) {
    what = "cannot read the terminal settings";
    return errno;
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CSIZE | PARENB | PARODD | CSTOPB
                                        | CRTSCTS);
  tio.c_cflag |= CS8;
  if (set.format.par != serial::parity::none) {
    tio.c_cflag |= PARENB;
    if (set.format.par == serial::parity::odd)
      tio.c_cflag |= PARODD;
    // A byte with a parity error reads as 0x00 (neither IGNPAR nor PARMRK):
    // it ends the damaged frame, which then fails its CRC.
    tio.c_iflag |= INPCK;
  }
  if (set.format.stop_bits == 2)
    tio.c_cflag |= CSTOPB;
  tio.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  if (set.flow == serial::flow_control::rtscts)
    tio.c_cflag |= CRTSCTS;
  if (set.flow == serial::flow_control::xonxoff) {
    tio.c_iflag |= IXON | IXOFF;
    tio.c_cc[VSTART] = serial::xon;
    tio.c_cc[VSTOP] = serial::xoff;
  }
  // epoll reports input from one byte on; reads never wait (O_NONBLOCK).
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  auto speed = to_speed(set.baud);
  if (::cfsetispeed(&tio, speed) != 0 || ::cfsetospeed(&tio, speed) != 0) {
    what = "cannot set " + std::to_string(set.baud) + " baud";
    return errno;
  }
  if (::tcsetattr(fd, TCSANOW, &tio) != 0) {
    what = "cannot apply the terminal settings";
    return errno;
  }
  // tcsetattr succeeds if any change took: check the ones that matter.
  termios got;
  if (::tcgetattr(fd, &got) != 0) {
    what = "cannot read the terminal settings";
    return errno;
  }
  if (::cfgetospeed(&got) != speed || ::cfgetispeed(&got) != speed) {
    what = "the line does not support " + std::to_string(set.baud) + " baud";
    return EINVAL;
  }
  if ((got.c_cflag & CSIZE) != CS8
      || (got.c_cflag & (PARENB | PARODD)) != (tio.c_cflag & (PARENB | PARODD))
      || (got.c_cflag & CSTOPB) != (tio.c_cflag & CSTOPB)) {
    what = "the line does not support framing " + to_string(set.format);
    return EINVAL;
  }
  if ((got.c_cflag & CRTSCTS) != (tio.c_cflag & CRTSCTS)) {
    what = "the line does not support RTS/CTS flow control";
    return EINVAL;
  }
  return 0;
}

// -- the driver ------------------------------------------------------------------

class serial_driver final : public link_driver {
public:
  /// Takes ownership of `fd` (the configured, non-blocking tty).
  serial_driver(serial::settings set, int fd)
    : set_(std::move(set)),
      prefix_("device '" + set_.device + "': "),
      fd_(fd),
      tx_capacity_(tx_buffer_frames
                   * serial::max_wire_size(set_.profile.mtu, set_.escaped())),
      baud_(set_.baud),
      bandwidth_(set_.profile.bandwidth_bps),
      char_ns_(char_time_ns(set_.format, set_.baud)),
      dec_(set_.profile.mtu, set_.escaped()),
      rx_buf_(rx_chunk) {
    tx_.reserve(tx_capacity_);
  }

  /// Must not run inside a handler call of this driver (i.e. the handler
  /// must not drop the last reference to its driver).
  ~serial_driver() override {
    stop();
  }

  // -- link_driver -------------------------------------------------------------

  /// Watches the tty on `loop`; see the file comment for the contract.
  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop& loop) override {
    return watch_.start(
      loop, fd_, handler != nullptr, "line",
      [this](ec code, const std::string& what) { return fail(code, what); },
      nullptr, [this](uint32_t events) { on_ready(events); },
      [&] {
        handler_ = std::move(handler);
        // Bytes sent before start (or while it ran) wait for the line.
        std::lock_guard<std::mutex> tx_guard{tx_mtx_};
        if (tx_head_ < tx_.size())
          watch_output();
      });
  }

  /// Closes the line. Bytes not yet on the wire (driver buffer and kernel
  /// output queue) are discarded, so that closing never waits for a
  /// stalled line.
  void stop() override {
    watch_.stop([this] {
      close_line();
      handler_.reset();
    });
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > set_.profile.mtu)
      return fail(ec::packet_too_large,
                  "frame of " + std::to_string(size)
                    + " bytes exceeds the MTU of "
                    + std::to_string(set_.profile.mtu) + " bytes");
    if (size == 0)
      return fail(ec::invalid_parameter,
                  "refusing to send an empty frame (receivers take it for "
                  "an idle line)");
    if (dst != peer_addr && dst != broadcast_addr)
      return fail(ec::invalid_address,
                  "a serial line reaches only its peer (1), not "
                    + format_addr(dst));
    std::lock_guard<std::mutex> guard{tx_mtx_};
    if (fd_ < 0)
      return fail(ec::device_failed, "device is stopped");
    if (failed_.load())
      return fail(ec::device_failed, "serial line " + set_.path + " has failed");
    auto pending = tx_.size() - tx_head_;
    auto now = now_ns();
    // Line idle (nothing of ours still being clocked out): lead with a
    // delimiter so that the receiver drops whatever noise came before.
    bool idle = pending == 0 && now >= busy_until_;
    auto old_size = tx_.size();
    auto n = serial::append_frame(tx_, data, size, idle, set_.escaped());
    if (pending + n > tx_capacity_) {
      tx_.resize(old_size);
      ++tx_queue_full_;
      return fail(ec::queue_full, "transmit buffer full ("
                                    + std::to_string(pending)
                                    + " bytes waiting for the line)");
    }
    busy_until_ = std::max(now, busy_until_)
                  + static_cast<int64_t>(n) * char_ns_.load();
    ++tx_frames_;
    tx_bytes_ += n;
    if (pending > 0)
      return caf::none; // EPOLLOUT is watched (or will be) already.
    auto err = write_pending();
    if (err != 0 && err != EAGAIN)
      return fail(ec::device_failed,
                  "serial line " + set_.path + ": " + errno_text(err));
    if (tx_head_ < tx_.size())
      watch_output();
    return caf::none;
  }

  const link_profile& profile() const override {
    return set_.profile;
  }

  link_addr local_addr() const override {
    return self_addr;
  }

  std::string format_addr(link_addr addr) const override {
    switch (addr) {
      case self_addr: return "local";
      case peer_addr: return "peer";
      case broadcast_addr: return "*";
      default: return "invalid(" + std::to_string(addr) + ")";
    }
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    if (str == "peer" || str == "1")
      return peer_addr;
    return fail(ec::invalid_address,
                "'" + str
                  + "' is not an address on a serial line (the other end is "
                    "'peer' or '1')");
  }

  caf::error set_param(const std::string& key,
                       const std::string& value) override {
    if (key != "baud")
      return fail(ec::invalid_parameter,
                  "parameter '" + key
                    + "' cannot be changed on a serial link (changeable: "
                      "baud)");
    // Parse through option_reader so errors read like option errors.
    device_config tmp{set_.device, "serial", set_.path, {{key, value}}};
    option_reader opts{tmp};
    auto baud = serial::read_baud(opts, key, 0);
    if (!baud)
      return baud.error();
    std::lock_guard<std::mutex> guard{tx_mtx_};
    if (fd_ < 0)
      return fail(ec::device_failed, "device is stopped");
    auto copy = set_;
    copy.baud = *baud;
    std::string what;
    if (auto err = apply_termios(fd_, copy, what))
      return fail(ec::device_failed,
                  "serial line " + set_.path + ": " + what + ": "
                    + errno_text(err));
    baud_ = *baud;
    char_ns_ = char_time_ns(set_.format, *baud);
    if (set_.bandwidth_follows_baud)
      bandwidth_ = *baud;
    return caf::none;
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "baud")
      return std::to_string(baud_.load());
    if (key == "bandwidth")
      return std::to_string(bandwidth_.load());
    if (key == "framing")
      return to_string(set_.format);
    if (key == "flow")
      return std::string{to_string(set_.flow)};
    if (key == "path")
      return set_.path;
    if (key == "exclusive")
      return std::string{set_.exclusive ? "true" : "false"};
    if (key == "bits_per_char")
      return std::to_string(set_.format.bits_per_char());
    static constexpr counter_param<serial_driver> counters[] = {
      {"tx_frames", &serial_driver::tx_frames_},
      {"tx_bytes", &serial_driver::tx_bytes_},
      {"tx_queue_full", &serial_driver::tx_queue_full_},
      {"rx_frames", &serial_driver::rx_frames_},
      {"rx_bytes", &serial_driver::rx_bytes_},
      {"rx_idle", &serial_driver::rx_idle_},
    };
    if (auto value = read_counter(*this, counters, key))
      return *value;
    if (key == "tx_queued") {
      std::lock_guard<std::mutex> guard{tx_mtx_};
      return std::to_string(tx_.size() - tx_head_);
    }
    if (key == "rx_malformed") {
      uint64_t sum = 0;
      for (auto& x : rx_errors_)
        sum += x.load();
      return std::to_string(sum);
    }
    static constexpr std::pair<const char*, serial::rx_error> errors[] = {
      {"rx_bad_cobs", serial::rx_error::bad_cobs},
      {"rx_too_short", serial::rx_error::too_short},
      {"rx_oversized", serial::rx_error::oversized},
      {"rx_bad_crc", serial::rx_error::bad_crc},
      {"rx_bad_escape", serial::rx_error::bad_escape},
    };
    for (auto& [name, code] : errors)
      if (key == name)
        return std::to_string(rx_errors_[static_cast<size_t>(code)].load());
    return link_driver::get_param(key);
  }

private:
  caf::error fail(ec code, const std::string& what) const {
    return make_error(code, prefix_ + what);
  }

  /// Discards what was not sent and closes the line (stop). On the loop
  /// thread once started.
  void close_line() {
    *alive_ = false;
    std::lock_guard<std::mutex> tx_guard{tx_mtx_};
    tx_.clear();
    tx_head_ = 0;
    out_armed_ = false;
    // Errors are irrelevant here (e.g. the line hung up already).
    ::tcflush(fd_, TCIOFLUSH);
    ::close(fd_); // also releases the flock
    fd_ = -1;
  }

  /// Has the loop watch for EPOLLOUT while bytes wait. Requires tx_mtx_;
  /// any thread.
  void watch_output() {
    auto* loop = watch_.loop();
    if (out_armed_ || loop == nullptr || failed_)
      return; // no loop before start: start watches EPOLLOUT then.
    out_armed_ = true;
    if (loop->in_loop_thread()) {
      loop->modify(fd_, EPOLLIN | EPOLLOUT);
      return;
    }
    loop->post([this, loop, alive = alive_] {
      if (!*alive)
        return;
      std::lock_guard<std::mutex> guard{tx_mtx_};
      if (out_armed_ && !failed_)
        loop->modify(fd_, EPOLLIN | EPOLLOUT);
    });
  }

  /// Writes buffered bytes until the tty takes no more. Returns 0, EAGAIN
  /// (bytes remain) or the errno of a failed write. Requires tx_mtx_.
  int write_pending() {
    while (tx_head_ < tx_.size()) {
      auto res = ::write(fd_, tx_.data() + tx_head_, tx_.size() - tx_head_);
      if (res < 0) {
        if (errno == EINTR)
          continue;
        return errno == EWOULDBLOCK ? EAGAIN : errno;
      }
      if (res == 0)
        return EAGAIN;
      tx_head_ += static_cast<size_t>(res);
    }
    tx_.clear();
    tx_head_ = 0;
    return 0;
  }

  // -- the loop thread -----------------------------------------------------------

  /// The tty's readiness callback.
  void on_ready(uint32_t events) {
    // Keeps the handler alive should it stop the driver during a call.
    auto keep = handler_;
    // Input first: bytes that arrived before a hangup are delivered.
    if ((events & (EPOLLIN | EPOLLHUP | EPOLLERR)) != 0 && !read_input())
      return;
    if ((events & EPOLLOUT) != 0) {
      int err;
      {
        std::lock_guard<std::mutex> guard{tx_mtx_};
        err = write_pending();
        if (err == 0 && out_armed_) {
          out_armed_ = false;
          watch_.loop()->modify(fd_, EPOLLIN);
        }
      }
      if (err != 0 && err != EAGAIN)
        return report_failure(errno_text(err));
    }
    if ((events & (EPOLLHUP | EPOLLERR)) != 0)
      report_failure("hangup");
  }

  /// Reads what the tty has, at most rx_reads_per_turn chunks. False after a
  /// failure (reported) or when the handler stopped the driver.
  bool read_input() {
    auto on_frame = [this](const uint8_t* data, size_t size) {
      ++rx_frames_;
      if (!watch_.stopping())
        handler_->on_frame(peer_addr, data, size);
    };
    auto on_malformed = [this](serial::rx_error why) {
      ++rx_errors_[static_cast<size_t>(why)];
      if (!watch_.stopping())
        handler_->on_malformed(self_addr, to_string(why));
    };
    for (int i = 0; i < rx_reads_per_turn; ++i) {
      auto n = ::read(fd_, rx_buf_.data(), rx_buf_.size());
      if (n > 0) {
        rx_bytes_ += static_cast<uint64_t>(n);
        dec_.feed(rx_buf_.data(), static_cast<size_t>(n), on_frame,
                  on_malformed);
        rx_idle_.store(dec_.stats().idle);
        if (watch_.stopping())
          return false;
        if (static_cast<size_t>(n) < rx_buf_.size())
          return true; // the tty had no more
        continue;
      }
      if (n == 0) { // a hung-up tty reads as end of file
        report_failure("hangup");
        return false;
      }
      auto err = errno;
      if (err == EAGAIN || err == EWOULDBLOCK)
        return true;
      if (err == EINTR)
        continue;
      report_failure(errno_text(err));
      return false;
    }
    return true;
  }

  /// Reports the end of the line once and stops watching the tty.
  void report_failure(const std::string& what) {
    if (watch_.stopping())
      return;
    {
      std::lock_guard<std::mutex> guard{tx_mtx_};
      if (failed_.exchange(true))
        return;
      out_armed_ = false;
    }
    watch_.unwatch();
    handler_->on_failure(
      fail(ec::device_failed, "serial line " + set_.path + ": " + what));
  }

  // -- state -----------------------------------------------------------------------

  const serial::settings set_;
  const std::string prefix_; // "device 'NAME': "

  /// Guards fd_ against closing, the transmit buffer, the line timing and
  /// whether EPOLLOUT is watched.
  mutable std::mutex tx_mtx_;
  int fd_;
  /// Encoded bytes not yet taken by the tty: tx_[tx_head_ ..).
  std::vector<uint8_t> tx_;
  size_t tx_head_ = 0;
  const size_t tx_capacity_;
  /// When the line will have clocked out everything written so far (an
  /// estimate from the baud rate, CLOCK_MONOTONIC ns).
  int64_t busy_until_ = 0;
  /// EPOLLOUT is watched, or a task that watches it is posted.
  bool out_armed_ = false;

  // Run-time parameters (set_param).
  std::atomic<uint64_t> baud_;
  std::atomic<uint64_t> bandwidth_;
  std::atomic<int64_t> char_ns_;

  // Life cycle (start, stop) on the event loop.
  loop_watch watch_;
  std::atomic<bool> failed_{false};
  /// Cleared by stop; tasks posted to the loop check it first.
  std::shared_ptr<std::atomic<bool>> alive_
    = std::make_shared<std::atomic<bool>>(true);
  std::shared_ptr<frame_handler> handler_;

  // The loop thread's once started.
  serial::decoder dec_;
  std::vector<uint8_t> rx_buf_;

  // Counters (get_param).
  std::atomic<uint64_t> tx_frames_{0};
  std::atomic<uint64_t> tx_bytes_{0};
  std::atomic<uint64_t> tx_queue_full_{0};
  std::atomic<uint64_t> rx_frames_{0};
  std::atomic<uint64_t> rx_bytes_{0};
  std::atomic<uint64_t> rx_idle_{0};
  std::atomic<uint64_t> rx_errors_[serial::rx_error_count] = {};
};

// -- open ----------------------------------------------------------------------

/// Reads at most `limit` bytes of a /proc file (they do not report a size).
std::string read_proc(const char* path, size_t limit) {
  std::string result;
  unique_fd fd{::open(path, O_RDONLY | O_CLOEXEC)};
  if (!fd)
    return result;
  char buf[4096];
  while (result.size() < limit) {
    auto n = ::read(fd.get(), buf, sizeof(buf));
    if (n < 0 && errno == EINTR)
      continue;
    if (n <= 0)
      break;
    result.append(buf, static_cast<size_t>(n));
  }
  return result;
}

/// " by process PID (NAME)" for a process holding an flock on the same file
/// as `fd`, from /proc/locks; empty when none is listed (best effort: the
/// refusal stands either way).
std::string lock_holder(int fd) {
  struct stat st;
  if (::fstat(fd, &st) != 0)
    return {};
  // /proc/locks: "1: FLOCK  ADVISORY  WRITE 1234 00:18:5 0 EOF", the file
  // as MAJOR:MINOR:INODE of its file system (hex, hex, decimal).
  char id[64];
  std::snprintf(id, sizeof(id), "%02x:%02x:%llu", ::major(st.st_dev),
                ::minor(st.st_dev), static_cast<unsigned long long>(st.st_ino));
  std::istringstream in{read_proc("/proc/locks", 1 << 20)};
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields{line};
    std::string num, type, mode, access, pid, file;
    fields >> num >> type;
    if (type == "->") // a waiter, not a holder
      continue;
    fields >> mode >> access >> pid >> file;
    if (type != "FLOCK" || file != id || pid.empty() || pid == "-1")
      continue;
    auto comm = read_proc(("/proc/" + pid + "/comm").c_str(), 64);
    while (!comm.empty() && (comm.back() == '\n' || comm.back() == '\0'))
      comm.pop_back();
    return " by process " + pid + (comm.empty() ? "" : " (" + comm + ")");
  }
  return {};
}

caf::expected<link_driver_ptr> open_serial(const device_config& cfg) {
  auto set = serial::read_settings(cfg);
  if (!set)
    return set.error();
  auto& path = set->path;
  auto fail = [&](const std::string& what) {
    return make_error(ec::device_unavailable, "device '" + cfg.name
                                                + "': serial line " + path
                                                + ": " + what);
  };
  unique_fd fd{::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC)};
  if (fd.get() < 0) {
    auto err = errno;
    if (err == EBUSY)
      return fail("busy: the tty is in exclusive mode (TIOCEXCL), set by "
                  "another program, or left set by one that died while the "
                  "line stayed open elsewhere (HERM does not set it)");
    return fail(errno_text(err));
  }
  if (!::isatty(fd.get()))
    return fail("not a terminal");
  // The lock says who has the line; it dies with its holder.
  if (::flock(fd.get(), (set->exclusive ? LOCK_EX : LOCK_SH) | LOCK_NB) != 0) {
    auto err = errno;
    if (err == EWOULDBLOCK)
      return fail("in use" + lock_holder(fd.get())
                  + " (another live process holds its lock"
                  + (set->exclusive ? "" : " exclusively") + ")");
    return fail("cannot lock: " + errno_text(err));
  }
  std::string what;
  if (auto err = apply_termios(fd.get(), *set, what))
    return fail(what + ": " + errno_text(err));
  // Whatever arrived before the line was configured is noise.
  ::tcflush(fd.get(), TCIOFLUSH);
  auto drv = std::make_shared<serial_driver>(std::move(*set), fd.get());
  fd.release();
  return link_driver_ptr{std::move(drv)};
}

caf::error check_serial(const device_config& cfg) {
  auto x = serial::read_settings(cfg);
  return x ? caf::error{} : std::move(x.error());
}

} // namespace

const link_kind& serial_link_kind() {
  static const link_kind kind{
    "serial",
    "serial line (RS232C, USB serial, USB CDC-ACM): COBS frames with CRC-16",
    open_serial, check_serial};
  return kind;
}

} // namespace herm
