// Link kind "emu": an emulated medium for interfaces without hardware here
// (IEEE 1394, USB, CAN without kernel support) and for building topologies
// across processes on one machine.
//
// A medium is a directory. Each station binds an AF_UNIX datagram socket at
// <dir>/<station>.sock; <dir>/medium is a shared, mmapped state file whose
// slots hold "medium busy until" times in CLOCK_MONOTONIC ns (system-wide,
// so every process agrees). A bus shares slot 0 among all stations, a
// point-to-point link gives each of its two stations its own slot (full
// duplex). Opening a station serializes on flock(<dir>/medium).
//
// Threads per driver: a transmit thread (paces frames, applies loss,
// duplication, corruption and jitter, sends datagrams) and, after start(), a
// receive thread (validates datagrams, holds them until their delivery time,
// watches that the socket file still exists, calls the frame_handler).

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>
#include <random>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "channels/error.hpp"
#include "channels/drivers/emu_wire.hpp"
#include "channels/drivers/medium_dir.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"

namespace herm {

namespace {

using posix::errno_text;
using posix::now_ns;
using posix::unique_fd;
using namespace medium_dir;

/// Stations of this kind with a socket file in `dir`.
std::vector<uint64_t> list_stations_in(const std::string& dir) {
  return list_stations(dir, emu::min_station, emu::max_station);
}


// -- constants -------------------------------------------------------------------

constexpr uint32_t medium_magic = 0x48454d55; // "HEMU"
constexpr uint32_t medium_version = 1;
constexpr size_t medium_slots = 256;

enum medium_form : uint32_t { form_unset = 0, form_bus = 1, form_p2p = 2 };

/// How often the receive thread checks that its files still exist.
constexpr int64_t liveness_period_ns = 100'000'000;
/// Broadcast destinations are rescanned at least this often (and whenever a
/// station joins or leaves through a driver, see medium_layout::generation).
constexpr int64_t rescan_period_ns = 100'000'000;
/// Bound of the back-to-back credit (see emu::transmission_start).
constexpr int64_t max_credit_ns = 50'000'000;
/// How long the transmitter waits for a receiver whose socket queue is full
/// before it drops the frame for that receiver (an overrun).
constexpr int64_t overrun_wait_ns = 25'000'000;
/// Frames held by a receiver for later delivery; above this, the earliest is
/// handed up early rather than dropped.
constexpr size_t max_held_frames = 4096;
/// Datagrams read per wake-up before due frames are delivered again.
constexpr int max_reads_per_wakeup = 64;

/// Layout of <dir>/medium. Lives in MAP_SHARED memory of several processes:
/// only lock-free atomics, no pointers.
struct medium_layout {
  uint32_t magic;
  uint32_t version;
  /// medium_form of the stations currently on the medium.
  std::atomic<uint32_t> form;
  /// Bumped whenever a station binds or unbinds, so transmitters rescan.
  std::atomic<uint32_t> generation;
  uint8_t reserved[48];
  /// "Busy until" per slot, CLOCK_MONOTONIC ns.
  std::atomic<int64_t> busy_until[medium_slots];
};

static_assert(std::atomic<int64_t>::is_always_lock_free,
              "the medium file needs address-free 64-bit atomics");
static_assert(std::atomic<uint32_t>::is_always_lock_free,
              "the medium file needs address-free 32-bit atomics");
static_assert(sizeof(medium_layout) == 64 + 8 * medium_slots,
              "the medium file layout is part of the wire format");

// -- small helpers ---------------------------------------------------------------

/// Holds flock(LOCK_EX) on the medium file. Unlocks explicitly: the
/// mapping keeps the open file description alive, so close() alone would
/// keep the lock until munmap.
struct medium_lock {
  unique_fd fd;
  medium_lock() = default;
  medium_lock(const medium_lock&) = delete;
  medium_lock& operator=(const medium_lock&) = delete;
  ~medium_lock() {
    if (fd)
      ::flock(fd.get(), LOCK_UN);
  }
};

// -- configuration ---------------------------------------------------------------

struct emu_config {
  std::string name;
  std::string dir;
  link_profile profile;
  uint64_t station = 0; // 0: lowest free
  bool p2p = false;
  uint64_t latency_us = 0;
  uint64_t jitter_us = 0;
  double loss = 0;
  double duplicate = 0;
  double corrupt = 0;
  uint64_t seed = 0;
  uint64_t queue = 256;
  bool create = true;
  /// Like Ethernet's FCS and the CRCs of IEEE 1394 and USB: a frame the
  /// medium corrupted is dropped by the receiver and counted as malformed.
  /// false: delivered as it is (to test what the layers above catch).
  bool frame_check = true;
};

caf::expected<emu_config> read_config(const device_config& cfg) {
  option_reader r{cfg};
  emu_config result;
  result.name = cfg.name;
  auto prof = r.profile("ieee1394a");
  if (!prof)
    return prof.error();
  result.profile = std::move(*prof);
  if (r.has("station")) {
    auto x = r.u64("station", 0, emu::min_station, emu::max_station);
    if (!x)
      return x.error();
    result.station = *x;
  }
  auto form = r.str("form", result.profile.multi_access ? "bus" : "p2p");
  if (form != "bus" && form != "p2p")
    return r.fail(ec::invalid_parameter,
                  "option 'form' expects bus or p2p, got '" + form + "'");
  result.p2p = form == "p2p";
  auto latency = r.u64("latency_us", 0, 0, emu::max_latency_us);
  if (!latency)
    return latency.error();
  result.latency_us = *latency;
  auto jitter = r.u64("jitter_us", 0, 0, emu::max_jitter_us);
  if (!jitter)
    return jitter.error();
  result.jitter_us = *jitter;
  for (auto [key, dst] : {std::pair{"loss", &result.loss},
                          std::pair{"duplicate", &result.duplicate},
                          std::pair{"corrupt", &result.corrupt}}) {
    auto x = r.real(key, 0.0, 0.0, 1.0);
    if (!x)
      return x.error();
    *dst = *x;
  }
  if (r.has("seed")) {
    auto seed = r.u64("seed", 0, 0, UINT64_MAX);
    if (!seed)
      return seed.error();
    result.seed = *seed;
  } else {
    std::random_device rd;
    result.seed = (uint64_t{rd()} << 32) ^ rd();
  }
  auto queue = r.u64("queue", 256, 1, 65'536);
  if (!queue)
    return queue.error();
  result.queue = *queue;
  auto create = r.flag("create", true);
  if (!create)
    return create.error();
  result.create = *create;
  auto fcs = r.flag("frame_check", true);
  if (!fcs)
    return fcs.error();
  result.frame_check = *fcs;
  if (auto err = r.finish())
    return err;
  result.dir = cfg.interface;
  while (result.dir.size() > 1 && result.dir.back() == '/')
    result.dir.pop_back();
  if (result.dir.empty())
    return r.fail(ec::invalid_parameter,
                  "no medium directory given (the interface of an emu device "
                  "is a directory path)");
  // Longest socket path: <dir>/254.sock.
  auto longest = result.dir.size() + 1 + station_file(254).size();
  if (longest >= sizeof(sockaddr_un::sun_path))
    return r.fail(ec::invalid_parameter,
                  "medium directory '" + result.dir + "' is too long: socket "
                    + "paths in it would take " + std::to_string(longest)
                    + " bytes, unix sockets allow "
                    + std::to_string(sizeof(sockaddr_un::sun_path) - 1));
  return result;
}

// -- the driver ------------------------------------------------------------------

class emu_driver final : public link_driver {
public:
  explicit emu_driver(emu_config cfg)
    : cfg_(std::move(cfg)),
      prefix_("device '" + cfg_.name + "': "),
      medium_path_(cfg_.dir + "/medium"),
      loss_(cfg_.loss),
      latency_ns_(int64_t(cfg_.latency_us) * 1000),
      jitter_ns_(int64_t(cfg_.jitter_us) * 1000),
      bandwidth_(cfg_.profile.bandwidth_bps),
      rng_(cfg_.seed) {
  }

  ~emu_driver() override {
    stop();
    if (medium_ != nullptr)
      ::munmap(medium_, sizeof(medium_layout));
  }

  /// Joins the medium: directory, medium file, station, socket. Starts the
  /// transmit thread.
  caf::error open() {
    if (auto err = open_directory())
      return err;
    medium_lock lock_fd;
    if (auto err = open_medium(lock_fd))
      return err;
    if (auto err = claim_station())
      return err;
    medium_->generation.fetch_add(1);
    return caf::none; // lock_fd unlocks
  }

  void start_transmitter() {
    tx_thread_ = std::thread{[this] { transmit_loop(); }};
  }

  // -- link_driver ---------------------------------------------------------------

  caf::error start(std::shared_ptr<frame_handler> handler) override {
    std::lock_guard<std::mutex> guard{lifecycle_mtx_};
    if (handler == nullptr)
      return make_error(ec::invalid_parameter, prefix_ + "start without handler");
    if (stopped_)
      return make_error(ec::device_failed, prefix_ + "start after stop");
    if (rx_thread_.joinable())
      return make_error(ec::already_exists, prefix_ + "already started");
    handler_ = std::move(handler);
    rx_thread_ = std::thread{[this] { receive_loop(); }};
    return caf::none;
  }

  void stop() override {
    std::lock_guard<std::mutex> guard{lifecycle_mtx_};
    if (stopped_)
      return;
    stopped_ = true;
    {
      std::lock_guard<std::mutex> lk{mtx_};
      stopping_ = true;
    }
    tx_cv_.notify_all();
    stopped_rx_.store(true);
    wake_receiver();
    if (tx_thread_.joinable())
      tx_thread_.join();
    if (rx_thread_.joinable()) {
      // Calling stop from a handler callback (on the receive thread) would
      // join the thread with itself; the handler contract forbids blocking
      // calls there, but do not deadlock: the loop exits when it returns.
      if (rx_thread_.get_id() == std::this_thread::get_id())
        rx_thread_.detach();
      else
        rx_thread_.join();
    }
    // Remove our socket file, unless somebody else's replaced it.
    struct stat st;
    if (sock_ino_ != 0 && ::stat(sock_path_.c_str(), &st) == 0
        && st.st_ino == sock_ino_ && st.st_dev == sock_dev_)
      ::unlink(sock_path_.c_str());
    if (medium_ != nullptr)
      medium_->generation.fetch_add(1);
    rx_fd_.reset();
    tx_fd_.reset();
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > cfg_.profile.mtu)
      return make_error(ec::packet_too_large,
                        prefix_ + "frame of " + std::to_string(size)
                          + " bytes exceeds the MTU of "
                          + std::to_string(cfg_.profile.mtu) + " bytes");
    if (dst != broadcast_addr
        && (dst < emu::min_station || dst > emu::max_station))
      return make_error(ec::invalid_address,
                        prefix_ + "no station " + std::to_string(dst)
                          + " on an emu link (stations are 1..254)");
    if (failed_.load())
      return make_error(ec::device_failed, prefix_ + "the link has failed");
    auto enqueued_at = now_ns();
    std::lock_guard<std::mutex> guard{mtx_};
    if (stopping_)
      return make_error(ec::device_failed, prefix_ + "the device is stopped");
    if (queue_.size() >= cfg_.queue)
      return make_error(ec::queue_full,
                        prefix_ + "transmit queue full ("
                          + std::to_string(cfg_.queue) + " frames)");
    tx_frame f;
    if (!spare_.empty()) {
      f.bytes = std::move(spare_.back());
      spare_.pop_back();
    }
    f.bytes.assign(data, data + size);
    f.dst = dst;
    f.enqueued_at = enqueued_at;
    queue_.push_back(std::move(f));
    if (tx_idle_)
      tx_cv_.notify_one();
    return caf::none;
  }

  const link_profile& profile() const override {
    return cfg_.profile;
  }

  link_addr local_addr() const override {
    return station_;
  }

  std::string format_addr(link_addr addr) const override {
    if (addr == broadcast_addr)
      return "*";
    return std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    uint64_t n = 0;
    bool ok = !str.empty() && str.size() <= 3;
    for (auto c : str) {
      if (c < '0' || c > '9') {
        ok = false;
        break;
      }
      n = n * 10 + static_cast<uint64_t>(c - '0');
    }
    if (!ok || n < emu::min_station || n > emu::max_station)
      return make_error(ec::invalid_address,
                        prefix_ + "'" + str
                          + "' is not an emu station (expected 1..254)");
    return n;
  }

  caf::error set_param(const std::string& key,
                       const std::string& value) override {
    // Parse through option_reader so errors read like option errors.
    device_config tmp{cfg_.name, "emu", cfg_.dir, {{key, value}}};
    option_reader r{tmp};
    if (key == "loss") {
      auto x = r.real(key, 0, 0, 1);
      if (!x)
        return x.error();
      loss_.store(*x);
    } else if (key == "latency_us") {
      auto x = r.u64(key, 0, 0, emu::max_latency_us);
      if (!x)
        return x.error();
      latency_ns_.store(int64_t(*x) * 1000);
    } else if (key == "jitter_us") {
      auto x = r.u64(key, 0, 0, emu::max_jitter_us);
      if (!x)
        return x.error();
      jitter_ns_.store(int64_t(*x) * 1000);
    } else if (key == "bandwidth") {
      auto x = r.u64(key, 0, 1, 100'000'000'000ull);
      if (!x)
        return x.error();
      bandwidth_.store(*x);
    } else {
      return make_error(ec::invalid_parameter,
                        prefix_ + "parameter '" + key
                          + "' cannot be changed on an emu link (changeable: "
                            "loss, latency_us, jitter_us, bandwidth)");
    }
    return caf::none;
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "bandwidth")
      return std::to_string(bandwidth_.load());
    if (key == "loss")
      return format_double(loss_.load());
    if (key == "latency_us")
      return std::to_string(latency_ns_.load() / 1000);
    if (key == "jitter_us")
      return std::to_string(jitter_ns_.load() / 1000);
    if (key == "duplicate")
      return format_double(cfg_.duplicate);
    if (key == "corrupt")
      return format_double(cfg_.corrupt);
    if (key == "station")
      return std::to_string(station_);
    if (key == "form")
      return std::string{cfg_.p2p ? "p2p" : "bus"};
    if (key == "medium")
      return cfg_.dir;
    // Counters, for tests and diagnostics.
    if (key == "tx_frames")
      return std::to_string(tx_frames_.load());
    if (key == "tx_lost")
      return std::to_string(tx_lost_.load());
    if (key == "tx_overruns")
      return std::to_string(tx_overruns_.load());
    if (key == "rx_frames")
      return std::to_string(rx_frames_.load());
    if (key == "rx_malformed")
      return std::to_string(rx_malformed_.load());
    return link_driver::get_param(key);
  }

private:
  struct tx_frame {
    int64_t enqueued_at = 0;
    link_addr dst = 0;
    std::vector<uint8_t> bytes;
  };

  struct held_frame {
    int64_t deliver_at = 0;
    uint64_t seq = 0;
    link_addr src = 0;
    std::vector<uint8_t> bytes;
  };

  /// Orders a std::*_heap as a min-heap by (deliver_at, seq).
  static bool later(const held_frame& x, const held_frame& y) {
    return x.deliver_at != y.deliver_at ? x.deliver_at > y.deliver_at
                                        : x.seq > y.seq;
  }

  caf::error fail(ec code, const std::string& what) const {
    return make_error(code, prefix_ + what);
  }

  // -- opening -------------------------------------------------------------------

  caf::error open_directory() {
    struct stat st;
    if (::stat(cfg_.dir.c_str(), &st) == 0) {
      if (!S_ISDIR(st.st_mode))
        return fail(ec::device_unavailable,
                    "medium path '" + cfg_.dir + "' is not a directory");
      return caf::none;
    }
    auto err = errno;
    if (err != ENOENT)
      return fail(ec::device_unavailable, "cannot use medium directory '"
                                            + cfg_.dir + "': " + errno_text(err));
    if (!cfg_.create)
      return fail(ec::device_unavailable,
                  "medium directory '" + cfg_.dir
                    + "' does not exist (and option create=false)");
    if (auto e = make_dirs(cfg_.dir))
      return fail(ec::device_unavailable, "cannot create medium directory '"
                                            + cfg_.dir + "': " + errno_text(e));
    return caf::none;
  }

  /// Opens, locks, sizes and maps <dir>/medium. The lock stays held in
  /// `lock_fd` while the station is claimed.
  caf::error open_medium(medium_lock& lock_fd) {
    lock_fd.fd.reset(
      ::open(medium_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666));
    auto fd = lock_fd.fd.get();
    if (fd < 0)
      return fail(ec::device_unavailable, "cannot open medium file '"
                                            + medium_path_
                                            + "': " + errno_text(errno));
    while (::flock(fd, LOCK_EX) != 0)
      if (errno != EINTR)
        return fail(ec::device_unavailable, "cannot lock medium file '"
                                              + medium_path_
                                              + "': " + errno_text(errno));
    struct stat st;
    if (::fstat(fd, &st) != 0)
      return fail(ec::device_unavailable, "cannot stat medium file '"
                                            + medium_path_
                                            + "': " + errno_text(errno));
    if (st.st_size == 0 && ::ftruncate(fd, sizeof(medium_layout)) != 0)
      return fail(ec::device_unavailable, "cannot size medium file '"
                                            + medium_path_
                                            + "': " + errno_text(errno));
    else if (st.st_size != 0 && st.st_size != off_t{sizeof(medium_layout)})
      return fail(ec::device_unavailable,
                  "'" + medium_path_ + "' is not an emu medium file ("
                    + std::to_string(st.st_size) + " bytes, expected "
                    + std::to_string(sizeof(medium_layout)) + ")");
    medium_dev_ = st.st_dev;
    medium_ino_ = st.st_ino;
    auto* mem = ::mmap(nullptr, sizeof(medium_layout), PROT_READ | PROT_WRITE,
                       MAP_SHARED, fd, 0);
    if (mem == MAP_FAILED)
      return fail(ec::device_unavailable, "cannot map medium file '"
                                            + medium_path_
                                            + "': " + errno_text(errno));
    medium_ = static_cast<medium_layout*>(mem);
    if (medium_->magic == 0 && medium_->version == 0) {
      medium_->magic = medium_magic;
      medium_->version = medium_version;
    } else if (medium_->magic != medium_magic) {
      return fail(ec::device_unavailable,
                  "'" + medium_path_ + "' is not an emu medium file");
    } else if (medium_->version != medium_version) {
      return fail(ec::device_unavailable,
                  "medium file '" + medium_path_ + "' has version "
                    + std::to_string(medium_->version)
                    + ", this driver speaks version "
                    + std::to_string(medium_version));
    }
    return caf::none;
  }

  /// Picks the station number, checks the medium's form and binds the
  /// socket. Runs under the medium lock.
  caf::error claim_station() {
    std::vector<uint64_t> live;
    std::vector<uint64_t> stale;
    for (auto n : list_stations_in(cfg_.dir)) {
      switch (probe_socket(cfg_.dir + "/" + station_file(n))) {
        case probe_result::live: live.push_back(n); break;
        case probe_result::stale: stale.push_back(n); break;
        case probe_result::absent: break;
      }
    }
    auto my_form = cfg_.p2p ? form_p2p : form_bus;
    if (live.empty()) {
      // First station on the medium: it defines the form, and busy times
      // left behind by earlier users (maybe at another bandwidth) go away.
      medium_->form.store(my_form);
      for (auto& slot : medium_->busy_until)
        slot.store(0);
    } else if (medium_->form.load() != my_form) {
      return fail(ec::device_unavailable,
                  "medium '" + cfg_.dir + "' is in use as a "
                    + (cfg_.p2p ? "bus" : "point-to-point link")
                    + " (stations " + join_numbers(live)
                    + "), this device is configured as a "
                    + (cfg_.p2p ? "point-to-point link" : "bus"));
    }
    if (cfg_.p2p && live.size() >= 2)
      return fail(ec::device_unavailable,
                  "medium '" + cfg_.dir
                    + "' is a point-to-point link and already has two "
                      "stations ("
                    + join_numbers(live) + ")");
    auto is_live = [&](uint64_t n) {
      return std::find(live.begin(), live.end(), n) != live.end();
    };
    if (cfg_.station != 0) {
      if (is_live(cfg_.station))
        return fail(ec::already_exists,
                    "station " + std::to_string(cfg_.station)
                      + " is already taken on medium '" + cfg_.dir + "'");
      station_ = cfg_.station;
    } else {
      for (auto n = emu::min_station; n <= emu::max_station && station_ == 0;
           ++n)
        if (!is_live(n))
          station_ = n;
      if (station_ == 0)
        return fail(ec::device_unavailable,
                    "medium '" + cfg_.dir + "' has no free station");
    }
    sock_path_ = cfg_.dir + "/" + station_file(station_);
    if (std::find(stale.begin(), stale.end(), station_) != stale.end())
      ::unlink(sock_path_.c_str()); // left behind by a dead process
    if (cfg_.p2p)
      medium_->busy_until[station_].store(0);
    // Receive socket: bound, non-blocking.
    rx_fd_.reset(
      ::socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (!rx_fd_)
      return fail(ec::device_unavailable,
                  "cannot create socket: " + errno_text(errno));
    auto addr = unix_addr(sock_path_);
    if (::bind(rx_fd_.get(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr))
        != 0) {
      auto err = errno;
      if (err == EADDRINUSE)
        return fail(ec::already_exists,
                    "station " + std::to_string(station_)
                      + " is already taken on medium '" + cfg_.dir + "' ("
                      + sock_path_ + " exists)");
      return fail(ec::device_unavailable,
                  "cannot bind " + sock_path_ + ": " + errno_text(err));
    }
    struct stat st;
    if (::stat(sock_path_.c_str(), &st) != 0)
      return fail(ec::device_unavailable, "cannot stat " + sock_path_ + ": "
                                            + errno_text(errno));
    sock_dev_ = st.st_dev;
    sock_ino_ = st.st_ino;
    // Transmit socket: blocking with a send timeout, so a receiver whose
    // queue is full (net.unix.max_dgram_qlen is small) gets a short grace
    // period before its frame counts as an overrun.
    tx_fd_.reset(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
    if (!tx_fd_)
      return fail(ec::device_unavailable,
                  "cannot create socket: " + errno_text(errno));
    timeval tv{0, overrun_wait_ns / 1000};
    ::setsockopt(tx_fd_.get(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof(tv));
    int sndbuf = 4 << 20; // best effort; capped at net.core.wmem_max
    ::setsockopt(tx_fd_.get(), SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof(sndbuf));
    wake_fd_.reset(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!wake_fd_)
      return fail(ec::device_unavailable,
                  "cannot create eventfd: " + errno_text(errno));
    for (auto n = emu::min_station; n <= emu::max_station; ++n)
      peer_addrs_[n] = unix_addr(cfg_.dir + "/" + station_file(n));
    return caf::none;
  }

  // -- transmit thread -----------------------------------------------------------

  void transmit_loop() {
    ::prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0); // precise wake-ups
    std::vector<uint8_t> buf(emu::wire_header_size + cfg_.profile.mtu);
    auto& slot = medium_->busy_until[cfg_.p2p ? station_ : 0];
    std::unique_lock<std::mutex> lk{mtx_};
    for (;;) {
      tx_idle_ = true;
      tx_cv_.wait(lk, [this] { return stopping_ || !queue_.empty(); });
      tx_idle_ = false;
      if (stopping_)
        return;
      auto f = std::move(queue_.front());
      queue_.pop_front();
      lk.unlock();
      // Reserve medium time. Reservations never overlap: each one starts at
      // or after the busy time it replaces.
      auto ft = emu::frame_time_ns(f.bytes.size(),
                                   cfg_.profile.frame_overhead_bits,
                                   bandwidth_.load());
      auto busy = slot.load();
      int64_t end = 0;
      do {
        end = emu::transmission_start(busy, f.enqueued_at, now_ns(),
                                      max_credit_ns)
              + ft;
      } while (!slot.compare_exchange_weak(busy, end));
      // Wait for the end of transmission on an absolute deadline, so errors
      // do not add up; stop() interrupts.
      lk.lock();
      auto deadline = std::chrono::steady_clock::time_point{
        std::chrono::nanoseconds{end}};
      while (!stopping_ && now_ns() < end)
        tx_cv_.wait_until(lk, deadline);
      if (stopping_)
        return;
      lk.unlock();
      if (!failed_.load() && !transmit(f, end, buf))
        return;
      lk.lock();
      if (spare_.size() < std::min<uint64_t>(cfg_.queue, 64))
        spare_.push_back(std::move(f.bytes));
    }
  }

  /// Puts one frame on the medium. False after a fatal error.
  bool transmit(const tx_frame& f, int64_t end, std::vector<uint8_t>& buf) {
    ++tx_frames_;
    if (f.dst != broadcast_addr)
      return f.dst == station_
             || transmit_to(f.dst, f, end, buf, 0) != send_result::fatal;
    refresh_peers();
    for (size_t i = 0; i < peers_.size();) {
      auto result = transmit_to(peers_[i], f, end, buf, emu::flag_broadcast);
      if (result == send_result::fatal)
        return false;
      if (result == send_result::gone)
        peers_.erase(peers_.begin() + static_cast<ptrdiff_t>(i));
      else
        ++i;
    }
    return true;
  }

  enum class send_result { ok, gone, fatal };

  send_result transmit_to(uint64_t dst, const tx_frame& f, int64_t end,
                          std::vector<uint8_t>& buf, uint8_t flags) {
    std::uniform_real_distribution<double> coin{0.0, 1.0};
    auto loss = loss_.load();
    if (loss > 0 && coin(rng_) < loss) {
      ++tx_lost_;
      return send_result::ok;
    }
    int copies = cfg_.duplicate > 0 && coin(rng_) < cfg_.duplicate ? 2 : 1;
    auto latency = latency_ns_.load();
    auto jitter = jitter_ns_.load();
    auto size = f.bytes.size();
    for (int copy = 0; copy < copies; ++copy) {
      emu::wire_header hdr;
      hdr.flags = static_cast<uint8_t>(flags
                                       | (copy > 0 ? emu::flag_duplicate : 0));
      hdr.src = static_cast<uint16_t>(station_);
      hdr.deliver_at_ns = end + latency;
      if (jitter > 0)
        hdr.deliver_at_ns
          += std::uniform_int_distribution<int64_t>{0, jitter}(rng_);
      if (size > 0)
        std::memcpy(buf.data() + emu::wire_header_size, f.bytes.data(), size);
      if (size > 0 && cfg_.corrupt > 0 && coin(rng_) < cfg_.corrupt) {
        auto bit = std::uniform_int_distribution<size_t>{0, size * 8 - 1}(rng_);
        buf[emu::wire_header_size + bit / 8] ^= uint8_t(1u << (bit % 8));
        hdr.flags |= emu::flag_corrupted;
      }
      emu::encode(hdr, buf.data());
      auto result = send_datagram(dst, buf.data(),
                                  emu::wire_header_size + size);
      if (result != send_result::ok)
        return result;
    }
    return send_result::ok;
  }

  send_result send_datagram(uint64_t dst, const uint8_t* data, size_t size) {
    auto& addr = peer_addrs_[dst];
    // A receiver that already overran once gets no grace period until it
    // takes a frame again: a stuck station must not stall the whole bus.
    int flags = MSG_NOSIGNAL | (congested_[dst] ? MSG_DONTWAIT : 0);
    for (;;) {
      if (::sendto(tx_fd_.get(), data, size, flags,
                   reinterpret_cast<const sockaddr*>(&addr), sizeof(addr))
          >= 0) {
        congested_[dst] = false;
        return send_result::ok;
      }
      auto err = errno;
      switch (err) {
        case EINTR:
          continue;
        case EAGAIN:
        case ENOBUFS:
        case ENOMEM:
          // Receiver overrun: the frame is lost for this receiver.
          ++tx_overruns_;
          congested_[dst] = true;
          return send_result::ok;
        case ENOENT:
        case ECONNREFUSED:
        case ENOTDIR:
          // Nobody there (any more): a medium just carries the frame nowhere.
          return send_result::gone;
        case EACCES:
        case EPERM:
          return send_result::ok; // somebody else's socket: not for us
        default:
          report_tx_failure(fail(ec::device_failed,
                                 "cannot send on emulated link " + cfg_.dir
                                   + ": " + errno_text(err)));
          return send_result::fatal;
      }
    }
  }

  /// Rescans the broadcast destinations when a station joined or left, or
  /// every rescan_period_ns (stations of crashed processes).
  void refresh_peers() {
    auto gen = medium_->generation.load();
    auto now = now_ns();
    if (peers_valid_ && gen == peers_generation_
        && now - peers_scanned_at_ < rescan_period_ns)
      return;
    peers_ = list_stations_in(cfg_.dir);
    peers_.erase(std::remove(peers_.begin(), peers_.end(), station_),
                 peers_.end());
    peers_valid_ = true;
    peers_generation_ = gen;
    peers_scanned_at_ = now;
  }

  void report_tx_failure(caf::error err) {
    {
      std::lock_guard<std::mutex> guard{failure_mtx_};
      if (!tx_failure_)
        tx_failure_ = std::move(err);
    }
    failed_.store(true);
    wake_receiver();
  }

  void wake_receiver() {
    if (wake_fd_) {
      uint64_t one = 1;
      [[maybe_unused]] auto n = ::write(wake_fd_.get(), &one, sizeof(one));
    }
  }

  // -- receive thread ------------------------------------------------------------

  void receive_loop() {
    ::prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
    std::vector<uint8_t> buf(emu::wire_header_size + cfg_.profile.mtu);
    auto next_check = now_ns() + liveness_period_ns;
    for (;;) {
      if (stopping_rx())
        return;
      auto now = now_ns();
      deliver_due(now);
      if (stopping_rx())
        return;
      if (now >= next_check) {
        if (auto err = check_files()) {
          report_failure(std::move(err));
          return;
        }
        next_check = now + liveness_period_ns;
      }
      if (auto err = take_tx_failure()) {
        report_failure(std::move(err));
        return;
      }
      auto wake_at = next_check;
      if (!held_.empty())
        wake_at = std::min(wake_at, held_.front().deliver_at);
      auto wait = std::max<int64_t>(0, wake_at - now);
      timespec ts{static_cast<time_t>(wait / 1'000'000'000),
                  static_cast<long>(wait % 1'000'000'000)};
      pollfd fds[2] = {{rx_fd_.get(), POLLIN, 0}, {wake_fd_.get(), POLLIN, 0}};
      auto rc = ::ppoll(fds, 2, &ts, nullptr);
      if (rc < 0) {
        if (errno == EINTR)
          continue;
        report_failure(fail(ec::device_failed,
                            "cannot poll emulated link socket " + sock_path_
                              + ": " + errno_text(errno)));
        return;
      }
      if (fds[1].revents != 0) {
        uint64_t count;
        [[maybe_unused]] auto n = ::read(wake_fd_.get(), &count, sizeof(count));
      }
      if (fds[0].revents != 0 && !read_datagrams(buf))
        return;
    }
  }

  bool stopping_rx() const {
    return stopped_rx_.load();
  }

  /// Reads what is queued on the socket. False after a fatal error.
  bool read_datagrams(std::vector<uint8_t>& buf) {
    for (int i = 0; i < max_reads_per_wakeup; ++i) {
      auto n = ::recv(rx_fd_.get(), buf.data(), buf.size(),
                      MSG_DONTWAIT | MSG_TRUNC);
      if (n < 0) {
        auto err = errno;
        if (err == EAGAIN || err == EWOULDBLOCK)
          return true;
        if (err == EINTR)
          continue;
        report_failure(fail(ec::device_failed,
                            "cannot receive on emulated link socket "
                              + sock_path_ + ": " + errno_text(err)));
        return false;
      }
      auto size = static_cast<size_t>(n); // the real size (MSG_TRUNC)
      auto now = now_ns();
      emu::wire_header hdr;
      hdr.src = 0;
      auto status = emu::check(buf.data(), size, cfg_.profile.mtu, now, hdr);
      if (status != emu::wire_status::ok) {
        ++rx_malformed_;
        auto src = hdr.src >= emu::min_station && hdr.src <= emu::max_station
                     ? link_addr{hdr.src}
                     : link_addr{0};
        auto why = std::string{"emu: "} + emu::to_string(status) + " ("
                   + std::to_string(size) + "-byte datagram, MTU "
                   + std::to_string(cfg_.profile.mtu) + ")";
        handler_->on_malformed(src, why.c_str());
        if (stopping_rx())
          return true;
        continue;
      }
      if ((hdr.flags & emu::flag_corrupted) != 0 && cfg_.frame_check) {
        // The receiving interface's frame check fails: the frame never
        // reaches software, as on the real medium.
        ++rx_malformed_;
        handler_->on_malformed(hdr.src,
                               "emu: frame check failed (a bit was flipped "
                               "on the medium)");
        if (stopping_rx())
          return true;
        continue;
      }
      auto payload = buf.data() + emu::wire_header_size;
      auto payload_size = size - emu::wire_header_size;
      if (held_.empty() && hdr.deliver_at_ns <= now) {
        deliver(hdr.src, payload, payload_size);
        if (stopping_rx())
          return true;
        continue;
      }
      if (held_.size() >= max_held_frames) {
        // Overloaded: hand the earliest up early rather than lose it.
        deliver_front();
        if (stopping_rx())
          return true;
      }
      held_frame h;
      if (!spare_rx_.empty()) {
        h.bytes = std::move(spare_rx_.back());
        spare_rx_.pop_back();
      }
      h.bytes.assign(payload, payload + payload_size);
      h.deliver_at = hdr.deliver_at_ns;
      h.seq = rx_seq_++;
      h.src = hdr.src;
      held_.push_back(std::move(h));
      std::push_heap(held_.begin(), held_.end(), later);
    }
    return true;
  }

  void deliver_due(int64_t now) {
    while (!held_.empty() && held_.front().deliver_at <= now
           && !stopping_rx())
      deliver_front();
  }

  void deliver_front() {
    std::pop_heap(held_.begin(), held_.end(), later);
    auto h = std::move(held_.back());
    held_.pop_back();
    deliver(h.src, h.bytes.data(), h.bytes.size());
    if (spare_rx_.size() < 64)
      spare_rx_.push_back(std::move(h.bytes));
  }

  void deliver(link_addr src, const uint8_t* data, size_t size) {
    ++rx_frames_;
    handler_->on_frame(src, data, size);
  }

  /// Non-null when our socket file or the medium file is gone or replaced.
  caf::error check_files() const {
    struct stat st;
    auto check = [&](const std::string& path, dev_t dev,
                     ino_t ino) -> caf::error {
      if (::stat(path.c_str(), &st) == 0) {
        if (st.st_dev == dev && st.st_ino == ino)
          return caf::none;
        return fail(ec::device_failed,
                    "emulated link file " + path + " removed (replaced)");
      }
      auto err = errno;
      if (err == ENOENT || err == ENOTDIR)
        return fail(ec::device_failed,
                    "emulated link file " + path + " removed");
      return fail(ec::device_failed, "cannot check emulated link file " + path
                                        + ": " + errno_text(err));
    };
    if (auto err = check(sock_path_, sock_dev_, sock_ino_))
      return err;
    return check(medium_path_, medium_dev_, medium_ino_);
  }

  caf::error take_tx_failure() {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    return std::exchange(tx_failure_, caf::error{});
  }

  /// Reports a fatal error once; the receive thread ends right after.
  void report_failure(caf::error err) {
    failed_.store(true);
    if (!stopping_rx())
      handler_->on_failure(std::move(err));
  }

  // -- state ---------------------------------------------------------------------

  const emu_config cfg_;
  const std::string prefix_; // "device 'NAME': "
  const std::string medium_path_;
  std::string sock_path_;
  link_addr station_ = 0;
  medium_layout* medium_ = nullptr;
  dev_t medium_dev_ = 0;
  ino_t medium_ino_ = 0;
  dev_t sock_dev_ = 0;
  ino_t sock_ino_ = 0;
  unique_fd rx_fd_;
  unique_fd tx_fd_;
  unique_fd wake_fd_;

  // Run-time parameters (set_param).
  std::atomic<double> loss_;
  std::atomic<int64_t> latency_ns_;
  std::atomic<int64_t> jitter_ns_;
  std::atomic<uint64_t> bandwidth_;

  // Lifecycle.
  std::mutex lifecycle_mtx_;
  bool stopped_ = false;
  std::atomic<bool> failed_{false};
  /// Set by stop(): the receive thread calls the handler no more.
  std::atomic<bool> stopped_rx_{false};
  std::shared_ptr<frame_handler> handler_;
  std::thread tx_thread_;
  std::thread rx_thread_;

  // Transmit queue, guarded by mtx_.
  std::mutex mtx_;
  std::condition_variable tx_cv_;
  std::deque<tx_frame> queue_;
  std::vector<std::vector<uint8_t>> spare_;
  bool stopping_ = false;
  bool tx_idle_ = false;

  // Transmit thread only.
  std::mt19937_64 rng_;
  sockaddr_un peer_addrs_[emu::max_station + 1] = {};
  bool congested_[emu::max_station + 1] = {};
  std::vector<uint64_t> peers_;
  bool peers_valid_ = false;
  uint32_t peers_generation_ = 0;
  int64_t peers_scanned_at_ = 0;

  // Failure handed from the transmit thread to the receive thread.
  std::mutex failure_mtx_;
  caf::error tx_failure_;

  // Receive thread only.
  std::vector<held_frame> held_;
  std::vector<std::vector<uint8_t>> spare_rx_;
  uint64_t rx_seq_ = 0;

  // Counters (get_param).
  std::atomic<uint64_t> tx_frames_{0};
  std::atomic<uint64_t> tx_lost_{0};
  std::atomic<uint64_t> tx_overruns_{0};
  std::atomic<uint64_t> rx_frames_{0};
  std::atomic<uint64_t> rx_malformed_{0};
};

caf::expected<link_driver_ptr> open_emu(const device_config& cfg) {
  auto conf = read_config(cfg);
  if (!conf)
    return conf.error();
  auto driver = std::make_shared<emu_driver>(std::move(*conf));
  if (auto err = driver->open())
    return err;
  driver->start_transmitter();
  return link_driver_ptr{std::move(driver)};
}

} // namespace

const link_kind& emu_link_kind() {
  static const link_kind kind{
    "emu",
    "emulated medium between processes on this machine: a directory of unix "
    "datagram sockets with bandwidth pacing, MTU, latency, jitter and loss",
    open_emu};
  return kind;
}

} // namespace herm
