// The "udp" link kind: UDP/IPv4 on an Ethernet segment (the paper's
// "Ethernet" row of Table 1). Unicast goes to one IP:PORT; broadcast_addr fans
// out to the configured broadcast address and to every configured peer, which
// is how modules find each other on a segment (broadcast) or on loopback
// (peers list). With neither configured, broadcast_addr sends nothing and
// succeeds (nobody to reach).
//
// Threading (the event-loop contract, channels/event_loop.hpp): the driver
// owns no thread. start() registers the socket with the module's event loop
// (through run_sync, so any thread may call it); the readiness callback
// reads one recvmmsg batch (buffers allocated once in start()) per call and
// returns to the loop, which calls it again next turn while datagrams wait
// (level-triggered), so one busy link cannot starve the others. Every
// handler call, on_failure included (at most once), happens on the loop
// thread from that callback. stop() is idempotent and may be called from any
// thread: it unwatches the socket on the loop thread (run_sync), closes it
// and drops the handler; no handler call follows its return. Called from a
// handler (on the loop thread, run_sync runs inline) it ends delivery at
// once: the callback sees watch_.stopping() and touches nothing more. send() and
// send_batch() may be called from any thread; they hold a shared lock so that
// stop() cannot close the socket under them. send_batch() hands runs of
// unicast frames to the kernel with one sendmmsg per 64 frames. Datagrams from our own port and one of this host's
// (namespace's) IPv4 addresses, snapshotted by getifaddrs in start(), are
// our own broadcasts looped back by the kernel and are ignored. Datagrams
// the kernel dropped because the receive buffer was full are counted through
// SO_RXQ_OVFL (the drop count rides on the next datagram received) and
// reported with frame_handler::on_kernel_drops.

#include <ifaddrs.h>
#include <net/if.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstring>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <vector>

#include "channels/error.hpp"
#include "channels/drivers/loop_watch.hpp"
#include "channels/drivers/params.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/drivers/udp_addr.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"

namespace herm {

namespace {

using posix::errno_text;
using posix::unique_fd;

/// IPv4 (20) and UDP (8) headers inside a 1500-byte Ethernet payload.
constexpr uint32_t default_udp_mtu = 1500 - 20 - 8;

/// Datagrams read per readiness callback (one recvmmsg call) at most.
constexpr size_t max_batch = 32;

/// Frames per sendmmsg call in send_batch at most (stack arrays of this
/// size; the kernel takes up to UIO_MAXIOV = 1024).
constexpr size_t max_send_batch = 64;

/// recvmmsg calls per callback that fail with a transient error (ICMP
/// unreachable reported on the socket, a signal) before it returns anyway.
constexpr int max_transient_retries = 4;

/// Upper bound of the preallocated receive memory (batch * MTU) in bytes.
constexpr size_t max_rx_memory = size_t{1} << 20;

/// Ancillary data per datagram: the SO_RXQ_OVFL drop count (uint32_t).
constexpr size_t rx_control_size = CMSG_SPACE(sizeof(uint32_t));

/// Errors a UDP socket reports for something a peer or the path did (ICMP
/// unreachable, a signal); the socket itself is fine.
bool is_transient(int err) {
  switch (err) {
    case EINTR:
    case EAGAIN:
#if EAGAIN != EWOULDBLOCK
    case EWOULDBLOCK:
#endif
    case ECONNREFUSED:
    case EHOSTUNREACH:
    case ENETUNREACH:
    case EHOSTDOWN:
      return true;
    default:
      return false;
  }
}

struct udp_settings {
  std::string device;
  link_profile profile;
  link_addr bind_addr = 0;
  std::vector<link_addr> peers;
  std::optional<link_addr> broadcast;
};

class udp_driver final : public link_driver {
public:
  /// Takes ownership of `fd` (bound, non-blocking socket).
  udp_driver(udp_settings cfg, int fd, link_addr local)
    : cfg_(std::move(cfg)), local_(local), fd_(fd) {
  }

  /// Must not run inside a handler call of this driver (i.e. the handler
  /// must not drop the last reference to its driver).
  ~udp_driver() override {
    stop();
  }

  /// Watches the socket on `loop`; see the file comment for the contract.
  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop& loop) override {
    return watch_.start(
      loop, fd_, handler != nullptr, "socket",
      [this](ec code, const std::string& what) { return fail(code, what); },
      [this] {
        if (auto err = collect_own_ips())
          return err;
        allocate_buffers();
        return caf::error{};
      },
      [this](uint32_t events) { on_ready(events); },
      [&] { handler_ = std::move(handler); });
  }

  void stop() override {
    watch_.stop([this] {
      close_socket();
      handler_.reset();
    });
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (auto err = check_frame(dst, size))
      return err;
    std::shared_lock<std::shared_mutex> guard{fd_mtx_};
    if (fd_ < 0)
      return fail(ec::device_failed, "device is stopped");
    if (dst != broadcast_addr)
      return send_to(dst, data, size);
    return send_to_all(data, size);
  }

  /// Runs of unicast frames leave with one sendmmsg per max_send_batch
  /// frames; a broadcast frame costs one sendto per target, as in send().
  /// A short sendmmsg (the socket's queue filled up) is followed by another
  /// one from the first frame not sent, which then reports queue_full (or
  /// is sent, if the queue drained meanwhile).
  size_t send_batch(const tx_frame* frames, size_t n,
                    caf::error& err) override {
    err = caf::error{};
    std::shared_lock<std::shared_mutex> guard{fd_mtx_};
    size_t done = 0;
    while (done < n) {
      auto& first = frames[done];
      if (auto e = check_frame(first.dst, first.size)) {
        err = std::move(e);
        return done;
      }
      if (fd_ < 0) {
        err = fail(ec::device_failed, "device is stopped");
        return done;
      }
      if (first.dst == broadcast_addr) {
        if (auto e = send_to_all(first.data, first.size)) {
          err = std::move(e);
          return done;
        }
        ++done;
        continue;
      }
      // The run: valid unicast frames from `done` on, at most one chunk.
      std::array<mmsghdr, max_send_batch> msgs{};
      std::array<iovec, max_send_batch> iovs{};
      std::array<sockaddr_in, max_send_batch> names{};
      size_t run = 0;
      while (run < max_send_batch && done + run < n) {
        auto& f = frames[done + run];
        if (f.dst == broadcast_addr || check_frame(f.dst, f.size))
          break;
        names[run] = udp::to_sockaddr(f.dst);
        iovs[run].iov_base = const_cast<uint8_t*>(f.data);
        iovs[run].iov_len = f.size;
        auto& hdr = msgs[run].msg_hdr;
        hdr.msg_name = &names[run];
        hdr.msg_namelen = sizeof(sockaddr_in);
        hdr.msg_iov = &iovs[run];
        hdr.msg_iovlen = 1;
        ++run;
      }
      auto sent = ::sendmmsg(fd_, msgs.data(), static_cast<unsigned>(run),
                             MSG_DONTWAIT | MSG_NOSIGNAL);
      if (sent < 0) {
        err = send_error(errno, first.dst);
        return done;
      }
      done += static_cast<size_t>(sent);
    }
    return done;
  }

  const link_profile& profile() const override {
    return cfg_.profile;
  }

  link_addr local_addr() const override {
    return local_;
  }

  std::string format_addr(link_addr addr) const override {
    return udp::format_addr(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    if (auto addr = udp::parse_addr(str, false))
      return *addr;
    return fail(ec::invalid_address,
                "'" + str + "' is not an IPv4 address and port (A.B.C.D:PORT)");
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "local")
      return udp::format_addr(local_);
    if (key == "peers") {
      std::string result;
      for (auto peer : cfg_.peers)
        result += (result.empty() ? "" : ",") + udp::format_addr(peer);
      return result;
    }
    if (key == "broadcast")
      return cfg_.broadcast ? udp::format_addr(*cfg_.broadcast) : "";
    if (key == "rx_kernel_dropped")
      return std::to_string(kernel_dropped_.load());
    return link_driver::get_param(key);
  }

private:
  caf::error fail(ec code, const std::string& what) const {
    return make_error(code, "device '" + cfg_.device + "': " + what);
  }

  /// Closes the socket (stop). On the loop thread once started.
  void close_socket() {
    std::unique_lock<std::shared_mutex> fd_guard{fd_mtx_};
    ::close(fd_);
    fd_ = -1;
  }

  /// The receive batch: `batch_` buffers of one MTU each, with their
  /// headers, addresses and control space, allocated once.
  void allocate_buffers() {
    auto mtu = size_t{cfg_.profile.mtu};
    batch_ = std::clamp<size_t>(max_rx_memory / mtu, 1, max_batch);
    buffers_.assign(batch_ * mtu, 0);
    msgs_.assign(batch_, mmsghdr{});
    iovs_.assign(batch_, iovec{});
    names_.assign(batch_, sockaddr_in{});
    // uint64_t storage keeps every cmsghdr aligned.
    controls_.assign(batch_ * (rx_control_size / sizeof(uint64_t) + 1), 0);
    for (size_t i = 0; i < batch_; ++i) {
      iovs_[i].iov_base = buffers_.data() + i * mtu;
      iovs_[i].iov_len = mtu;
      msgs_[i].msg_hdr.msg_iov = &iovs_[i];
      msgs_[i].msg_hdr.msg_iovlen = 1;
      msgs_[i].msg_hdr.msg_name = &names_[i];
      msgs_[i].msg_hdr.msg_control
        = controls_.data() + i * (rx_control_size / sizeof(uint64_t) + 1);
    }
  }

  /// What send() refuses before touching the socket: oversized or empty
  /// frames, destinations outside the udp address space.
  caf::error check_frame(link_addr dst, size_t size) const {
    if (size > cfg_.profile.mtu)
      return fail(ec::packet_too_large,
                  "frame of " + std::to_string(size)
                    + " bytes exceeds the MTU of "
                    + std::to_string(cfg_.profile.mtu) + " bytes");
    if (size == 0)
      return fail(ec::invalid_parameter,
                  "refusing to send an empty frame (receivers drop it)");
    if (dst != broadcast_addr
        && (dst > udp::max_addr || udp::port_of(dst) == 0))
      return fail(ec::invalid_address,
                  "not a udp destination: " + udp::format_addr(dst));
    return caf::none;
  }

  /// The error for errno `err` of a send to `dst`.
  caf::error send_error(int err, link_addr dst) const {
    auto where = " to " + udp::format_addr(dst) + ": " + errno_text(err);
    switch (err) {
      case EAGAIN:
#if EAGAIN != EWOULDBLOCK
      case EWOULDBLOCK:
#endif
      case ENOBUFS:
        return fail(ec::queue_full, "send queue full" + where);
      case EMSGSIZE:
        return fail(ec::packet_too_large, "datagram too large" + where);
      default:
        return fail(ec::device_failed, "send failed" + where);
    }
  }

  // Called with fd_mtx_ held (shared).
  caf::error send_to(link_addr dst, const uint8_t* data, size_t size) {
    auto sa = udp::to_sockaddr(dst);
    auto res = ::sendto(fd_, data, size, MSG_DONTWAIT | MSG_NOSIGNAL,
                        reinterpret_cast<const sockaddr*>(&sa), sizeof(sa));
    if (res >= 0)
      return caf::none;
    return send_error(errno, dst);
  }

  /// The broadcast fan-out: every target gets its copy even when one
  /// fails; the first error wins. Called with fd_mtx_ held (shared).
  caf::error send_to_all(const uint8_t* data, size_t size) {
    caf::error first;
    if (cfg_.broadcast)
      first = send_to(*cfg_.broadcast, data, size);
    for (auto peer : cfg_.peers) {
      auto err = send_to(peer, data, size);
      if (err && !first)
        first = std::move(err);
    }
    return first;
  }

  /// Snapshots this host's (network namespace's) IPv4 addresses, so that our
  /// own broadcasts, which the kernel loops back, can be recognised.
  caf::error collect_own_ips() {
    own_ips_.clear();
    ifaddrs* list = nullptr;
    if (::getifaddrs(&list) != 0)
      return fail(ec::device_unavailable,
                  "getifaddrs failed: " + errno_text(errno));
    for (auto* i = list; i != nullptr; i = i->ifa_next)
      if (i->ifa_addr != nullptr && i->ifa_addr->sa_family == AF_INET) {
        auto* sa = reinterpret_cast<const sockaddr_in*>(i->ifa_addr);
        own_ips_.push_back(ntohl(sa->sin_addr.s_addr));
      }
    ::freeifaddrs(list);
    // Binding to e.g. 127.0.0.2 works without that address being listed.
    if (udp::ip_of(local_) != INADDR_ANY)
      own_ips_.push_back(udp::ip_of(local_));
    return caf::none;
  }

  bool is_own(const sockaddr_in& src) const {
    if (ntohs(src.sin_port) != udp::port_of(local_))
      return false;
    auto ip = ntohl(src.sin_addr.s_addr);
    return std::find(own_ips_.begin(), own_ips_.end(), ip) != own_ips_.end();
  }

  /// Reports the failure once and stops watching the socket (send() keeps
  /// working until stop). Loop thread.
  void report_failure(const std::string& what, int err) {
    watch_.unwatch();
    handler_->on_failure(
      fail(ec::device_failed, what + " on " + udp::format_addr(local_) + ": "
                                + errno_text(err)));
  }

  // -- the loop thread ---------------------------------------------------------

  /// The socket's readiness callback.
  void on_ready(uint32_t events) {
    // Keeps the handler alive should it stop the driver during a call.
    auto keep = handler_;
    if ((events & EPOLLERR) != 0) {
      // A pending socket error (reading SO_ERROR clears it).
      int err = 0;
      socklen_t len = sizeof(err);
      if (::getsockopt(fd_, SOL_SOCKET, SO_ERROR, &err, &len) != 0)
        err = errno;
      if (err != 0 && !is_transient(err))
        return report_failure("socket error", err);
    }
    if ((events & (EPOLLIN | EPOLLERR)) == 0 && (events & EPOLLHUP) != 0)
      return report_failure("socket hung up", EPIPE);
    if ((events & EPOLLIN) != 0)
      read_batch();
  }

  /// Reads one batch of datagrams and hands them to the handler; returns
  /// early when the handler stopped the driver.
  void read_batch() {
    auto mtu = cfg_.profile.mtu;
    for (int attempt = 0; attempt < max_transient_retries; ++attempt) {
      for (size_t i = 0; i < batch_; ++i) {
        msgs_[i].msg_hdr.msg_namelen = sizeof(sockaddr_in);
        msgs_[i].msg_hdr.msg_flags = 0;
        msgs_[i].msg_hdr.msg_controllen = rx_control_size;
        msgs_[i].msg_len = 0;
      }
      // MSG_TRUNC: msg_len is the datagram's real length even when larger
      // than the buffer, which is how oversized datagrams are recognised.
      auto n = ::recvmmsg(fd_, msgs_.data(), static_cast<unsigned>(batch_),
                          MSG_DONTWAIT | MSG_TRUNC, nullptr);
      if (n < 0) {
        auto err = errno;
        if (err == EAGAIN || err == EWOULDBLOCK)
          return;
        if (is_transient(err))
          continue;
        return report_failure("recvmmsg failed", err);
      }
      for (int i = 0; i < n; ++i) {
        auto& msg = msgs_[static_cast<size_t>(i)];
        auto& name = names_[static_cast<size_t>(i)];
        note_drops(msg.msg_hdr);
        if (watch_.stopping())
          return;
        if (is_own(name))
          continue;
        auto src = udp::from_sockaddr(name);
        if (msg.msg_len == 0)
          handler_->on_malformed(src, "empty");
        else if (msg.msg_len > mtu || (msg.msg_hdr.msg_flags & MSG_TRUNC) != 0)
          handler_->on_malformed(src, "oversized");
        else
          handler_->on_frame(src,
                             static_cast<const uint8_t*>(
                               msg.msg_hdr.msg_iov->iov_base),
                             msg.msg_len);
        if (watch_.stopping())
          return;
      }
      return;
    }
  }

  /// Reports what the kernel dropped since the last datagram that told us.
  /// SO_RXQ_OVFL attaches the socket's drop count (cumulative, modulo
  /// 2^32) to a datagram once drops have happened.
  void note_drops(const msghdr& hdr) {
    if (auto delta = rxq_.drops_since(hdr); delta > 0) {
      kernel_dropped_ += delta;
      handler_->on_kernel_drops(delta);
    }
  }

  // -- state -------------------------------------------------------------------

  const udp_settings cfg_;
  const link_addr local_;

  /// Guards closing fd_ against concurrent send() calls.
  mutable std::shared_mutex fd_mtx_;
  int fd_;

  /// The life cycle (start, stop) on the event loop.
  loop_watch watch_;
  std::shared_ptr<frame_handler> handler_;

  // The loop thread's once started.
  std::vector<uint32_t> own_ips_;
  size_t batch_ = 0;
  std::vector<uint8_t> buffers_;
  std::vector<mmsghdr> msgs_;
  std::vector<iovec> iovs_;
  std::vector<sockaddr_in> names_;
  std::vector<uint64_t> controls_;
  posix::rxq_overflow rxq_;
  std::atomic<uint64_t> kernel_dropped_{0};
};

// -- open ----------------------------------------------------------------------

caf::expected<std::vector<link_addr>> parse_peers(option_reader& opts) {
  std::vector<link_addr> result;
  auto text = opts.str("peers");
  if (text.empty())
    return result;
  size_t pos = 0;
  for (;;) {
    auto comma = text.find(',', pos);
    auto item = text.substr(pos, comma == std::string::npos ? std::string::npos
                                                           : comma - pos);
    auto first = item.find_first_not_of(" \t");
    auto last = item.find_last_not_of(" \t");
    item = first == std::string::npos ? "" : item.substr(first, last - first + 1);
    auto addr = udp::parse_addr(item, false);
    if (!addr)
      return opts.fail(ec::invalid_address,
                       "option 'peers': '" + item
                         + "' is not an IPv4 address and port (A.B.C.D:PORT) "
                           "in '"
                         + text + "'");
    if (std::find(result.begin(), result.end(), *addr) == result.end())
      result.push_back(*addr);
    if (comma == std::string::npos)
      return result;
    pos = comma + 1;
  }
}

/// What a udp device's interface and options say, read and checked without
/// touching a socket: the one parser of open_udp and the kind's check.
struct udp_options {
  udp_settings set;
  std::string bind_device;
  /// SO_RCVBUF, SO_SNDBUF when given.
  std::optional<uint64_t> bufs[2];
};

const char* const udp_buf_keys[2] = {"rcvbuf", "sndbuf"};

caf::expected<udp_options> read_udp_options(const device_config& cfg) {
  option_reader opts{cfg};
  auto fail = [&](ec code, const std::string& what) {
    return opts.fail(code, what);
  };
  udp_options result;
  auto& set = result.set;
  set.device = cfg.name;
  if (auto err = read_into(set.profile, opts.profile("ethernet")))
    return err;
  // Without an explicit mtu, a frame must fit one Ethernet frame's UDP
  // payload (a smaller profile MTU, e.g. can2.0 emulated over UDP, stays).
  if (!opts.has("mtu"))
    set.profile.mtu = std::min(set.profile.mtu, default_udp_mtu);
  auto bind_addr = udp::parse_addr(cfg.interface, true);
  if (!bind_addr)
    return fail(ec::invalid_address,
                "interface '" + cfg.interface
                  + "' is not an IPv4 address and port to bind "
                    "(e.g. 0.0.0.0:47000 or 127.0.0.1:0)");
  set.bind_addr = *bind_addr;
  if (auto err = read_into(set.peers, parse_peers(opts)))
    return err;
  if (opts.has("broadcast")) {
    auto text = opts.str("broadcast");
    auto addr = udp::parse_addr(text, false);
    if (!addr)
      return fail(ec::invalid_address,
                  "option 'broadcast': '" + text
                    + "' is not an IPv4 address and port "
                      "(e.g. 10.77.0.255:47000)");
    set.broadcast = *addr;
  }
  result.bind_device = opts.str("bind_device");
  if (opts.has("bind_device")
      && (result.bind_device.empty() || result.bind_device.size() >= IFNAMSIZ))
    return fail(ec::invalid_parameter,
                "option 'bind_device' expects an interface name of 1 to "
                  + std::to_string(IFNAMSIZ - 1) + " characters, got '"
                  + result.bind_device + "'");
  for (int i = 0; i < 2; ++i)
    if (opts.has(udp_buf_keys[i])) {
      if (auto err = read_into(result.bufs[i],
                               opts.u64(udp_buf_keys[i], 0, 1024, INT_MAX / 2)))
        return err;
    }
  if (auto err = opts.finish())
    return err;
  return result;
}

caf::error check_udp(const device_config& cfg) {
  auto x = read_udp_options(cfg);
  return x ? caf::error{} : std::move(x.error());
}

caf::expected<link_driver_ptr> open_udp(const device_config& cfg) {
  auto parsed = read_udp_options(cfg);
  if (!parsed)
    return std::move(parsed.error());
  option_reader opts{cfg};
  auto fail = [&](ec code, const std::string& what) {
    return opts.fail(code, what);
  };
  auto& set = parsed->set;
  auto& bind_device = parsed->bind_device;
  auto& bufs = parsed->bufs;
  auto& buf_keys = udp_buf_keys;
  // -- socket --
  unique_fd sock{::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC,
                          0)};
  if (sock.get() < 0)
    return fail(ec::device_unavailable,
                "cannot create a UDP socket: " + errno_text(errno));
  int one = 1;
  // Count what a full receive buffer drops (Linux 2.6.33 and later).
  if (::setsockopt(sock.get(), SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof(one))
      != 0)
    return fail(ec::device_unavailable,
                "cannot enable SO_RXQ_OVFL: " + errno_text(errno));
  if (set.broadcast
      && ::setsockopt(sock.get(), SOL_SOCKET, SO_BROADCAST, &one, sizeof(one))
           != 0)
    return fail(ec::device_unavailable,
                "cannot enable SO_BROADCAST: " + errno_text(errno));
  if (!bind_device.empty()
      && ::setsockopt(sock.get(), SOL_SOCKET, SO_BINDTODEVICE,
                      bind_device.c_str(),
                      static_cast<socklen_t>(bind_device.size()))
           != 0)
    return fail(ec::device_unavailable, "option 'bind_device': cannot bind "
                                          "to interface '"
                                          + bind_device
                                          + "': " + errno_text(errno));
  const int buf_opts[2] = {SO_RCVBUF, SO_SNDBUF};
  for (int i = 0; i < 2; ++i)
    if (bufs[i]) {
      auto val = static_cast<int>(*bufs[i]);
      if (::setsockopt(sock.get(), SOL_SOCKET, buf_opts[i], &val, sizeof(val))
          != 0)
        return fail(ec::device_unavailable, std::string{"cannot set "}
                                              + buf_keys[i] + ": "
                                              + errno_text(errno));
    }
  auto sa = udp::to_sockaddr(set.bind_addr);
  if (::bind(sock.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof(sa))
      != 0)
    return fail(ec::device_unavailable, "cannot bind "
                                          + udp::format_addr(set.bind_addr)
                                          + ": " + errno_text(errno));
  sockaddr_in bound{};
  socklen_t len = sizeof(bound);
  if (::getsockname(sock.get(), reinterpret_cast<sockaddr*>(&bound), &len)
      != 0)
    return fail(ec::device_unavailable, "getsockname failed: "
                                          + errno_text(errno));
  auto local = udp::from_sockaddr(bound);
  auto drv = std::make_shared<udp_driver>(std::move(set), sock.get(), local);
  sock.release();
  return link_driver_ptr{std::move(drv)};
}

} // namespace

const link_kind& udp_link_kind() {
  static const link_kind kind{"udp", "UDP/IPv4 (Ethernet)", open_udp,
                              check_udp};
  return kind;
}

} // namespace herm
