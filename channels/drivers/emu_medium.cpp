#include "channels/drivers/emu_medium.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <sys/epoll.h>
#include <sys/file.h>
#include <sys/inotify.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "channels/drivers/medium_dir.hpp"

namespace herm::emu_medium {

using posix::errno_text;
using posix::now_ns;
using posix::unique_fd;
using namespace medium_dir;

// -- pure parts ------------------------------------------------------------------

int copies(dice& d, const impairments& imp) {
  if (d.chance(imp.loss))
    return 0;
  return d.chance(imp.duplicate) ? 2 : 1;
}

copy_fate fate_of_copy(dice& d, const impairments& imp, int64_t end_ns,
                       size_t payload) {
  copy_fate result;
  result.deliver_at_ns = end_ns + imp.latency_ns + d.up_to(imp.jitter_ns);
  if (payload > 0 && d.chance(imp.corrupt))
    result.flipped_bit = static_cast<int64_t>(d.bit_of(payload * 8));
  return result;
}

arbitration arbitrate(contender mine, const contender* rivals, size_t count,
                      int64_t busy) {
  auto earliest = mine.ready_at;
  for (size_t i = 0; i < count; ++i)
    earliest = std::min(earliest, rivals[i].ready_at);
  arbitration result;
  result.point = std::max(busy, earliest);
  if (mine.ready_at > result.point)
    return result;
  for (size_t i = 0; i < count; ++i)
    if (rivals[i].ready_at <= result.point && rivals[i].key < mine.key)
      return result;
  result.wins = true;
  return result;
}

void hold_queue::push(int64_t deliver_at, const uint8_t* data, size_t size) {
  held h;
  h.bytes = copy_reusing(spare_, data, size);
  h.deliver_at = deliver_at;
  h.seq = next_seq_++;
  heap_.push_back(std::move(h));
  std::push_heap(heap_.begin(), heap_.end(), later);
}

std::vector<uint8_t> hold_queue::pop() {
  std::pop_heap(heap_.begin(), heap_.end(), later);
  auto bytes = std::move(heap_.back().bytes);
  heap_.pop_back();
  return bytes;
}

void hold_queue::recycle(std::vector<uint8_t> buf) {
  if (spare_.size() < spare_buffers)
    spare_.push_back(std::move(buf));
}

caf::error tx_gate::admit(size_t queued, size_t capacity,
                          const std::string& prefix) const {
  if (closed_)
    return make_error(ec::device_failed, prefix + "the device is stopped");
  if (queued >= capacity)
    return make_error(ec::queue_full, prefix + "transmit queue full ("
                                        + std::to_string(capacity)
                                        + " frames)");
  return caf::none;
}

// -- station: opening ------------------------------------------------------------

medium_client::~medium_client() = default;

namespace {

/// Holds flock(LOCK_EX) on the state file while a station joins. Unlocks
/// explicitly: the mapping keeps the open file description alive, so
/// close() alone would keep the lock until munmap.
struct state_lock {
  unique_fd fd;
  state_lock() = default;
  state_lock(const state_lock&) = delete;
  state_lock& operator=(const state_lock&) = delete;
  ~state_lock() {
    if (fd)
      ::flock(fd.get(), LOCK_UN);
  }
};

struct state_header {
  uint32_t magic;
  uint32_t version;
};

} // namespace

station::station(std::string dir, std::string prefix, const medium_spec& spec,
                 medium_client& client)
  : dir_(std::move(dir)),
    prefix_(std::move(prefix)),
    spec_(spec),
    state_path_(dir_ + "/" + spec.state_file),
    client_(client) {
}

station::~station() {
  stop_->store(true); // for anything still posted to the loop
  if (state_ != nullptr)
    ::munmap(state_, spec_.state_size);
}

caf::error station::fail(ec code, const std::string& what) const {
  return make_error(code, prefix_ + what);
}

caf::error station::open(bool create) {
  if (auto err = open_directory(create))
    return err;
  state_lock lock;
  if (auto err = open_state(lock.fd))
    return err;
  if (auto err = claim())
    return err;
  generation().fetch_add(1);
  return caf::none; // lock unlocks
}

caf::error station::open_directory(bool create) {
  std::string noun = spec_.texts.noun;
  struct stat st;
  if (::stat(dir_.c_str(), &st) == 0) {
    if (!S_ISDIR(st.st_mode))
      return fail(ec::device_unavailable,
                  noun + " path '" + dir_ + "' is not a directory");
    return caf::none;
  }
  auto err = errno;
  if (err != ENOENT)
    return fail(ec::device_unavailable, "cannot use " + noun + " directory '"
                                          + dir_ + "': " + errno_text(err));
  if (!create)
    return fail(ec::device_unavailable,
                noun + " directory '" + dir_
                  + "' does not exist (and option create=false)");
  if (auto e = make_dirs(dir_))
    return fail(ec::device_unavailable, "cannot create " + noun
                                          + " directory '" + dir_
                                          + "': " + errno_text(e));
  return caf::none;
}

/// Opens, locks, sizes, maps and checks the state file. The lock stays held
/// in `lock_fd` while the station is claimed.
caf::error station::open_state(unique_fd& lock_fd) {
  auto file = std::string{spec_.texts.noun} + " file '" + state_path_ + "'";
  auto failed = [&](const char* what) {
    return fail(ec::device_unavailable, std::string{"cannot "} + what + " "
                                          + file + ": " + errno_text(errno));
  };
  lock_fd.reset(
    ::open(state_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666));
  auto fd = lock_fd.get();
  if (fd < 0)
    return failed("open");
  while (::flock(fd, LOCK_EX) != 0)
    if (errno != EINTR)
      return failed("lock");
  struct stat st;
  if (::fstat(fd, &st) != 0)
    return failed("stat");
  auto size = static_cast<off_t>(spec_.state_size);
  if (st.st_size == 0 && ::ftruncate(fd, size) != 0)
    return failed("size");
  if (st.st_size != 0 && st.st_size != size)
    return fail(ec::device_unavailable,
                "'" + state_path_ + "' is not " + spec_.texts.file_kind + " ("
                  + std::to_string(st.st_size) + " bytes, expected "
                  + std::to_string(spec_.state_size) + ")");
  state_dev_ = st.st_dev;
  state_ino_ = st.st_ino;
  auto* mem = ::mmap(nullptr, spec_.state_size, PROT_READ | PROT_WRITE,
                     MAP_SHARED, fd, 0);
  if (mem == MAP_FAILED)
    return failed("map");
  state_ = mem;
  auto* hdr = static_cast<state_header*>(mem);
  if (hdr->magic == 0 && hdr->version == 0) {
    hdr->magic = spec_.magic;
    hdr->version = spec_.version;
  } else if (hdr->magic != spec_.magic) {
    return fail(ec::device_unavailable,
                "'" + state_path_ + "' is not " + spec_.texts.file_kind);
  } else if (hdr->version != spec_.version) {
    return fail(ec::device_unavailable,
                std::string{spec_.texts.noun} + " file '" + state_path_
                  + "' has version " + std::to_string(hdr->version)
                  + ", this driver speaks version "
                  + std::to_string(spec_.version));
  }
  return caf::none;
}

/// Has the client pick the station, then binds its sockets. Runs under the
/// state file's lock.
caf::error station::claim() {
  std::vector<uint64_t> live;
  std::vector<uint64_t> stale;
  for (auto n : list_stations(dir_, min_station, max_station)) {
    switch (probe_socket(dir_ + "/" + station_file(n))) {
      case probe_result::live: live.push_back(n); break;
      case probe_result::stale: stale.push_back(n); break;
      case probe_result::absent: break;
    }
  }
  auto picked = client_.admit(state_, live);
  if (!picked)
    return picked.error();
  number_ = *picked;
  sock_path_ = dir_ + "/" + station_file(number_);
  if (std::find(stale.begin(), stale.end(), number_) != stale.end())
    ::unlink(sock_path_.c_str()); // left behind by a dead process
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
                  client_.taken(number_) + " (" + sock_path_ + " exists)");
    return fail(ec::device_unavailable,
                "cannot bind " + sock_path_ + ": " + errno_text(err));
  }
  struct stat st;
  if (::stat(sock_path_.c_str(), &st) != 0)
    return fail(ec::device_unavailable,
                "cannot stat " + sock_path_ + ": " + errno_text(errno));
  sock_dev_ = st.st_dev;
  sock_ino_ = st.st_ino;
  if (spec_.rcvbuf > 0)
    ::setsockopt(rx_fd_.get(), SOL_SOCKET, SO_RCVBUF, &spec_.rcvbuf,
                 sizeof(spec_.rcvbuf));
  // Transmit socket, used with MSG_DONTWAIT: a receiver whose queue is
  // full (net.unix.max_dgram_qlen is small) gets a short grace period
  // before its frame counts as an overrun (send_to, retry_stalled).
  tx_fd_.reset(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!tx_fd_)
    return fail(ec::device_unavailable,
                "cannot create socket: " + errno_text(errno));
  if (spec_.sndbuf > 0)
    ::setsockopt(tx_fd_.get(), SOL_SOCKET, SO_SNDBUF, &spec_.sndbuf,
                 sizeof(spec_.sndbuf));
  for (auto n = min_station; n <= max_station; ++n)
    peer_addrs_[n] = unix_addr(dir_ + "/" + station_file(n));
  return caf::none;
}

std::atomic<uint32_t>& station::generation() const {
  return *reinterpret_cast<std::atomic<uint32_t>*>(
    static_cast<uint8_t*>(state_) + spec_.generation_offset);
}

// -- station: transmit side ------------------------------------------------------

station::send_result station::send_to(uint64_t dst, const uint8_t* data,
                                      size_t size) {
  auto& addr = peer_addrs_[dst];
  // Never blocks the loop; keeps the order to a receiver that stalls.
  for (auto& x : stalled_)
    if (x.dst == dst)
      return stall(dst, data, size);
  int flags = MSG_NOSIGNAL | MSG_DONTWAIT;
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
        if (!congested_[dst])
          return stall(dst, data, size);
        // Receiver overrun: the frame is lost for this receiver.
        ++overruns_;
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
                               std::string{"cannot send on "}
                                 + spec_.texts.link_noun + " " + dir_ + ": "
                                 + errno_text(err)));
        return send_result::fatal;
    }
  }
}

void station::refresh_peers() {
  auto gen = generation().load();
  auto now = now_ns();
  if (peers_valid_ && gen == peers_generation_
      && now - peers_scanned_at_ < rescan_period_ns)
    return;
  peers_ = list_stations(dir_, min_station, max_station);
  if (!spec_.self_is_peer)
    peers_.erase(std::remove(peers_.begin(), peers_.end(), number_),
                 peers_.end());
  peers_valid_ = true;
  peers_generation_ = gen;
  peers_scanned_at_ = now;
}

station::send_result station::stall(uint64_t dst, const uint8_t* data,
                                    size_t size) {
  if (stalled_.size() >= max_stalled) {
    ++overruns_;
    congested_[dst] = true;
    return send_result::ok;
  }
  if (stalled_.empty())
    stall_since_ = now_ns();
  stalled_.push_back(stalled_datagram{dst, {data, data + size}});
  return send_result::ok;
}

bool station::retry_stalled(int64_t now) {
  bool blocked[max_station + 1] = {};
  bool progress = false;
  size_t kept = 0;
  for (size_t i = 0; i < stalled_.size(); ++i) {
    auto& x = stalled_[i];
    bool keep = blocked[x.dst];
    while (!keep) {
      auto& addr = peer_addrs_[x.dst];
      if (::sendto(tx_fd_.get(), x.bytes.data(), x.bytes.size(),
                   MSG_NOSIGNAL | MSG_DONTWAIT,
                   reinterpret_cast<const sockaddr*>(&addr), sizeof(addr))
          >= 0) {
        congested_[x.dst] = false;
        progress = true;
        break;
      }
      auto err = errno;
      if (err == EINTR)
        continue;
      if (err == EAGAIN || err == ENOBUFS || err == ENOMEM) {
        blocked[x.dst] = true;
        keep = true;
      } else if (err != ENOENT && err != ECONNREFUSED && err != ENOTDIR
                 && err != EACCES && err != EPERM) {
        stalled_.clear();
        report_tx_failure(fail(ec::device_failed,
                               std::string{"cannot send on "}
                                 + spec_.texts.link_noun + " " + dir_ + ": "
                                 + errno_text(err)));
        return true;
      }
      break; // sent, or nobody there (any more): nothing to keep
    }
    if (keep) {
      if (kept != i)
        stalled_[kept] = std::move(x);
      ++kept;
    }
  }
  stalled_.resize(kept);
  if (progress)
    stall_since_ = now;
  if (!stalled_.empty() && now - stall_since_ >= overrun_wait_ns) {
    // The receivers did not read for the whole grace period: overruns.
    for (auto& x : stalled_) {
      ++overruns_;
      congested_[x.dst] = true;
    }
    stalled_.clear();
  }
  return stalled_.empty();
}

// -- tx_pump ---------------------------------------------------------------------

void tx_pump::start(event_loop& loop, std::function<void()> step) {
  step_ = std::move(step);
  loop_.store(&loop);
  kick();
}

void tx_pump::kick() {
  auto* loop = loop_.load();
  if (loop == nullptr || flags_->stopped.load())
    return;
  if (loop->in_loop_thread()) {
    if (!timer_ && !running_)
      run();
    return;
  }
  if (flags_->posted.exchange(true))
    return; // a task is on its way
  loop->post([this, f = flags_] {
    if (f->stopped.load())
      return;
    f->posted.store(false);
    if (!timer_ && !running_)
      run();
  });
}

void tx_pump::at(int64_t due_ns) {
  auto* loop = loop_.load();
  if (timer_) {
    if (timer_at_ <= due_ns)
      return;
    loop->cancel_timer(timer_);
  }
  timer_at_ = due_ns;
  timer_ = loop->add_timer(due_ns, [this, f = flags_] {
    if (f->stopped.load())
      return;
    timer_ = {};
    run();
  });
}

bool tx_pump::held_back(station& st) {
  if (!st.stalled() || st.retry_stalled(now_ns()))
    return false;
  at(now_ns() + stall_retry_ns);
  return true;
}

void tx_pump::run() {
  running_ = true;
  step_();
  running_ = false;
}

void tx_pump::stop() {
  if (flags_->stopped.exchange(true))
    return;
  if (auto* loop = loop_.load())
    loop->run_sync([this] {
      if (timer_)
        loop_.load()->cancel_timer(timer_);
      timer_ = {};
    });
}

void station::report_tx_failure(caf::error err) {
  event_loop* loop = nullptr;
  {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    if (!tx_failure_)
      tx_failure_ = std::move(err);
    loop = post_to_;
  }
  failed_.store(true);
  // The loop outlives stop(), which joins this thread; the task checks the
  // stop flag before it touches the station.
  if (loop != nullptr)
    loop->post([this, stop = stop_] {
      if (!stop->load())
        on_tx_failure();
    });
}

// -- station: receiving on the event loop ----------------------------------------

caf::error station::start_receiving(event_loop& loop, size_t max_datagram) {
  loop_.store(&loop); // before attach: a concurrent stop_receiving finds it
  caf::error err;
  loop.run_sync([&] { err = attach(loop, max_datagram); });
  return err;
}

void station::stop_receiving() {
  request_stop();
  if (auto* loop = loop_.load()) {
    loop->run_sync([this] { detach(); });
    // Done with the loop: a later stop (the destructor's) must not touch
    // it, it may be gone by then.
    loop_.store(nullptr);
  }
}

void station::request_stop() {
  stop_->store(true);
}

/// Loop thread: watches the socket and arms the liveness timer.
caf::error station::attach(event_loop& loop, size_t max_datagram) {
  if (stopping())
    return fail(ec::device_failed, "the device is stopped");
  rx_buf_.resize(max_datagram);
  auto stop = stop_;
  if (auto err = loop.watch(rx_fd_.get(), EPOLLIN, [this, stop](uint32_t) {
        // `stop` lives in this callback's copy until it returns, so
        // on_readable can check it after the station was destroyed.
        if (!stop->load())
          on_readable(*stop);
      }))
    return fail(ec::device_unavailable,
                std::string{"cannot receive on "} + spec_.texts.socket_noun
                  + " " + sock_path_ + ": " + render(err));
  receiving_ = true;
  if (watch_files(loop)) {
    // A file removed between open and now raised no event: look once.
    if (auto err = check_files())
      loop.post([this, stop, err]() mutable {
        if (!stop->load())
          report_failure(std::move(err));
      });
  } else {
    arm_liveness_timer();
  }
  bool pending = false;
  {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    post_to_ = &loop;
    pending = static_cast<bool>(tx_failure_);
  }
  if (pending) // the transmit step failed before start
    loop.post([this, stop] {
      if (!stop->load())
        on_tx_failure();
    });
  return caf::none;
}

/// Loop thread: unwatches the socket and cancels the timers. Idempotent.
void station::detach() {
  {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    post_to_ = nullptr;
  }
  if (!receiving_)
    return;
  receiving_ = false;
  auto* loop = loop_.load();
  loop->unwatch(rx_fd_.get());
  loop->cancel_timer(hold_timer_);
  hold_timer_ = {};
  loop->cancel_timer(liveness_timer_);
  liveness_timer_ = {};
  if (notify_fd_) {
    loop->unwatch(notify_fd_.get());
    notify_fd_.reset();
  }
}

/// Loop thread: watches the medium's directory, so that a removed or
/// replaced socket or state file is noticed at once and an idle station
/// wakes for nothing else. False (the caller falls back to the liveness
/// timer) when inotify or the loop refuses.
bool station::watch_files(event_loop& loop) {
  posix::unique_fd fd{::inotify_init1(IN_NONBLOCK | IN_CLOEXEC)};
  if (!fd)
    return false;
  constexpr uint32_t mask = IN_DELETE | IN_CREATE | IN_MOVED_FROM
                            | IN_MOVED_TO | IN_DELETE_SELF | IN_MOVE_SELF;
  if (::inotify_add_watch(fd.get(), dir_.c_str(), mask) < 0)
    return false;
  auto stop = stop_;
  if (loop.watch(fd.get(), EPOLLIN, [this, stop](uint32_t) {
        if (!stop->load())
          on_files_changed();
      }))
    return false;
  notify_fd_ = std::move(fd);
  return true;
}

/// Readiness callback of the inotify descriptor: which entry changed does
/// not matter (an overflowed queue neither), the files are checked again.
void station::on_files_changed() {
  alignas(inotify_event) char buf[4096];
  while (::read(notify_fd_.get(), buf, sizeof(buf)) > 0) {
    // Drained; the events themselves are not needed.
  }
  if (!receiving_)
    return;
  if (auto err = check_files())
    report_failure(std::move(err));
}

/// Readiness callback: like one turn of the receive thread it replaces, due
/// datagrams first, then a bounded batch from the socket. Every client call
/// may stop the station (stop from a handler): after one, `stop` is checked
/// before anything of the station is touched again.
void station::on_readable(const std::atomic<bool>& stop) {
  if (!deliver_due(stop))
    return;
  for (int i = 0; i < max_reads_per_wakeup; ++i) {
    auto n = ::recv(rx_fd_.get(), rx_buf_.data(), rx_buf_.size(),
                    MSG_DONTWAIT | MSG_TRUNC);
    if (n < 0) {
      auto err = errno;
      if (err == EAGAIN || err == EWOULDBLOCK)
        break;
      if (err == EINTR)
        continue;
      report_failure(fail(ec::device_failed,
                          std::string{"cannot receive on "}
                            + spec_.texts.socket_noun + " " + sock_path_
                            + ": " + errno_text(err)));
      return;
    }
    auto size = static_cast<size_t>(n); // the real size (MSG_TRUNC)
    auto now = now_ns();
    int64_t deliver_at = 0;
    if (!client_.accept(rx_buf_.data(), size, now, deliver_at)) {
      if (stop.load())
        return;
      continue;
    }
    if (held_.empty() && deliver_at <= now) {
      client_.deliver(rx_buf_.data(), size);
      if (stop.load())
        return;
      continue;
    }
    if (held_.full() && !deliver_front(stop)) // overloaded: early, not lost
      return;
    held_.push(deliver_at, rx_buf_.data(), size);
  }
  arm_hold_timer();
}

/// Delivers up to max_reads_per_wakeup datagrams that are due. False when
/// a client call stopped the station.
bool station::deliver_due(const std::atomic<bool>& stop) {
  auto now = now_ns();
  for (int i = 0; i < max_reads_per_wakeup && held_.due(now); ++i)
    if (!deliver_front(stop))
      return false;
  return true;
}

bool station::deliver_front(const std::atomic<bool>& stop) {
  auto bytes = held_.pop();
  client_.deliver(bytes.data(), bytes.size());
  if (stop.load())
    return false;
  held_.recycle(std::move(bytes));
  return true;
}

void station::on_hold_timer(const std::atomic<bool>& stop) {
  hold_timer_ = {};
  if (receiving_ && deliver_due(stop))
    arm_hold_timer();
}

/// Keeps one loop timer at the earliest held datagram's delivery time (or,
/// when more are due than one callback delivers, at the next turn).
void station::arm_hold_timer() {
  auto* loop = loop_.load();
  if (held_.empty()) {
    loop->cancel_timer(hold_timer_);
    hold_timer_ = {};
    return;
  }
  auto due = std::max(held_.next_due(), now_ns() + 1);
  if (hold_timer_ && hold_timer_at_ == due)
    return;
  loop->cancel_timer(hold_timer_);
  hold_timer_at_ = due;
  hold_timer_ = loop->add_timer(due, [this, stop = stop_] {
    if (!stop->load())
      on_hold_timer(*stop);
  });
}

void station::arm_liveness_timer() {
  liveness_timer_ = loop_.load()->add_timer(now_ns() + liveness_period_ns,
                                            [this, stop = stop_] {
                                              if (!stop->load())
                                                on_liveness_timer();
                                            });
}

void station::on_liveness_timer() {
  liveness_timer_ = {};
  if (!receiving_)
    return;
  if (auto err = check_files()) {
    report_failure(std::move(err));
    return;
  }
  arm_liveness_timer();
}

/// Loop thread: a failure the transmit step posted.
void station::on_tx_failure() {
  if (!receiving_)
    return; // receiving ended (a failure was reported already)
  caf::error err;
  {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    err = std::exchange(tx_failure_, caf::error{});
  }
  if (err)
    report_failure(std::move(err));
}

/// Non-null when our socket file or the state file is gone or replaced.
caf::error station::check_files() const {
  struct stat st;
  auto check = [&](const std::string& path, dev_t dev,
                   ino_t ino) -> caf::error {
    auto file = std::string{spec_.texts.file_noun} + " " + path;
    if (::stat(path.c_str(), &st) == 0) {
      if (st.st_dev == dev && st.st_ino == ino)
        return caf::none;
      return fail(ec::device_failed, file + spec_.texts.replaced);
    }
    auto err = errno;
    if (err == ENOENT || err == ENOTDIR)
      return fail(ec::device_failed, file + spec_.texts.removed);
    return fail(ec::device_failed,
                "cannot check " + file + ": " + errno_text(err));
  };
  if (auto err = check(sock_path_, sock_dev_, sock_ino_))
    return err;
  return check(state_path_, state_dev_, state_ino_);
}

/// Loop thread: ends receiving and reports `err` (once: receiving ends).
void station::report_failure(caf::error err) {
  failed_.store(true);
  detach();
  if (!stopping())
    client_.fail(std::move(err));
}

// -- station: life cycle ----------------------------------------------------------

void station::leave() {
  // Remove our socket file, unless somebody else's replaced it.
  struct stat st;
  if (sock_ino_ != 0 && ::stat(sock_path_.c_str(), &st) == 0
      && st.st_ino == sock_ino_ && st.st_dev == sock_dev_)
    ::unlink(sock_path_.c_str());
  if (state_ != nullptr)
    generation().fetch_add(1);
  rx_fd_.reset();
  tx_fd_.reset();
}

// -- station_life --------------------------------------------------------------

caf::error station_life::start(station& st,
                               std::shared_ptr<frame_handler> handler,
                               event_loop& loop, size_t max_datagram,
                               std::function<void()> step) {
  {
    std::lock_guard<std::mutex> guard{mtx_};
    if (!handler)
      return st.fail(ec::invalid_parameter, "start needs a frame handler");
    if (stopped_ || st.stopping())
      return st.fail(ec::device_unavailable, "already stopped");
    if (started_)
      return st.fail(ec::device_unavailable, "already started");
    started_ = true;
    handler_ = std::move(handler);
  }
  // Not under mtx_: run_sync waits for the loop thread, whose handlers may
  // call stop().
  if (auto err = st.start_receiving(loop, max_datagram)) {
    std::lock_guard<std::mutex> guard{mtx_};
    handler_.reset();
    started_ = false;
    return err;
  }
  pump_.start(loop, std::move(step));
  return caf::none;
}

void station_life::stop(station& st, tx_gate& gate,
                        const std::function<void()>& teardown) {
  // Not under mtx_ either: the pump waits for the loop thread.
  pump_.stop();
  gate.close();
  // Ends delivery first (waits for a callback in progress on another
  // thread), outside mtx_ for the same reason as in start.
  st.stop_receiving();
  std::lock_guard<std::mutex> guard{mtx_};
  if (stopped_)
    return;
  stopped_ = true;
  teardown();
  st.leave();
  // From a handler call, the callback that made it holds its own copy.
  handler_.reset();
}

} // namespace herm::emu_medium
