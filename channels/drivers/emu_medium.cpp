#include "channels/drivers/emu_medium.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
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
  // Transmit socket: blocking with a send timeout, so a receiver whose
  // queue is full (net.unix.max_dgram_qlen is small) gets a short grace
  // period before its frame counts as an overrun.
  tx_fd_.reset(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!tx_fd_)
    return fail(ec::device_unavailable,
                "cannot create socket: " + errno_text(errno));
  timeval tv{0, overrun_wait_ns / 1000};
  ::setsockopt(tx_fd_.get(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof(tv));
  if (spec_.sndbuf > 0)
    ::setsockopt(tx_fd_.get(), SOL_SOCKET, SO_SNDBUF, &spec_.sndbuf,
                 sizeof(spec_.sndbuf));
  wake_fd_.reset(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
  if (!wake_fd_)
    return fail(ec::device_unavailable,
                "cannot create eventfd: " + errno_text(errno));
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

void station::report_tx_failure(caf::error err) {
  {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    if (!tx_failure_)
      tx_failure_ = std::move(err);
  }
  failed_.store(true);
  wake_receiver();
}

void station::wake_receiver() {
  if (wake_fd_) {
    uint64_t one = 1;
    [[maybe_unused]] auto n = ::write(wake_fd_.get(), &one, sizeof(one));
  }
}

// -- station: receive side -------------------------------------------------------

void station::receive_loop(size_t max_datagram) {
  ::prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0); // precise wake-ups
  if (spec_.rx_thread_name != nullptr)
    pthread_setname_np(pthread_self(), spec_.rx_thread_name);
  std::vector<uint8_t> buf(max_datagram);
  auto next_check = now_ns() + liveness_period_ns;
  for (;;) {
    if (stopping())
      return;
    auto now = now_ns();
    while (held_.due(now) && !stopping())
      deliver_front();
    if (stopping())
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
      wake_at = std::min(wake_at, held_.next_due());
    auto wait = std::max<int64_t>(0, wake_at - now);
    timespec ts{static_cast<time_t>(wait / 1'000'000'000),
                static_cast<long>(wait % 1'000'000'000)};
    pollfd fds[2] = {{rx_fd_.get(), POLLIN, 0}, {wake_fd_.get(), POLLIN, 0}};
    auto rc = ::ppoll(fds, 2, &ts, nullptr);
    if (rc < 0) {
      if (errno == EINTR)
        continue;
      report_failure(fail(ec::device_failed,
                          std::string{"cannot poll "} + spec_.texts.socket_noun
                            + " " + sock_path_ + ": " + errno_text(errno)));
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

/// Reads what is queued on the socket. False after a fatal error.
bool station::read_datagrams(std::vector<uint8_t>& buf) {
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
                          std::string{"cannot receive on "}
                            + spec_.texts.socket_noun + " " + sock_path_
                            + ": " + errno_text(err)));
      return false;
    }
    auto size = static_cast<size_t>(n); // the real size (MSG_TRUNC)
    auto now = now_ns();
    int64_t deliver_at = 0;
    if (!client_.accept(buf.data(), size, now, deliver_at)) {
      if (stopping())
        return true;
      continue;
    }
    if (held_.empty() && deliver_at <= now) {
      client_.deliver(buf.data(), size);
      if (stopping())
        return true;
      continue;
    }
    if (held_.full()) {
      // Overloaded: hand the earliest up early rather than lose it.
      deliver_front();
      if (stopping())
        return true;
    }
    held_.push(deliver_at, buf.data(), size);
  }
  return true;
}

void station::deliver_front() {
  auto bytes = held_.pop();
  client_.deliver(bytes.data(), bytes.size());
  held_.recycle(std::move(bytes));
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

caf::error station::take_tx_failure() {
  std::lock_guard<std::mutex> guard{failure_mtx_};
  return std::exchange(tx_failure_, caf::error{});
}

void station::report_failure(caf::error err) {
  failed_.store(true);
  if (!stopping())
    client_.fail(std::move(err));
}

// -- station: any thread, life cycle ---------------------------------------------

void station::request_stop() {
  stopping_.store(true);
  wake_receiver();
}

bool station::join_receiver(std::thread& rx) {
  if (!rx.joinable())
    return true;
  if (rx.get_id() == std::this_thread::get_id())
    return false;
  rx.join();
  return true;
}

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

} // namespace herm::emu_medium
