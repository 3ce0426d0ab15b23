// Link kind "can": HERM frames as CAN 2.0B (or CAN FD) data frames, the
// identifier carrying priority, destination and source node
// (channels/drivers/can_id.hpp, docs/protocol.md). Two backends share the
// frame format, option set and receive path (channels/drivers/can_common.hpp):
//
//  * SocketCAN (interface "can0", "vcan0", ...), in this file: a
//    PF_CAN/SOCK_RAW/CAN_RAW socket bound to the interface, following
//    can-utils' cansend/candump: if_nametoindex, SIOCGIFMTU before enabling
//    CAN FD, reads accepted only when exactly CAN_MTU or CANFD_MTU bytes
//    long, an error-frame mask for bus-off, controller problems and
//    restarts, a kernel receive filter on the destination field, own
//    messages not received.
//
//  * The emulated bus (interface "emu:/path/to/bus-directory"), for hosts
//    without CAN: channels/drivers/can_emu.cpp.
//
// Threading of SocketCAN (the event-loop contract, channels/event_loop.hpp):
// the driver owns no thread. start() registers the socket with the module's
// event loop (through run_sync, so any thread may call it); the readiness
// callback reads at most max_reads_per_turn frames and returns to the loop
// (level-triggered: called again next turn while frames wait), so a busy
// bus cannot starve other links. The frame_handler is called on the loop
// thread only, and on_failure at most once, after which the socket is no
// longer watched. A send() that finds the interface gone posts the failure
// report to the loop (a task that checks a shared alive flag first, so it
// does nothing once the driver stopped or died). send() may be called from
// any thread and never blocks beyond one non-blocking system call. stop() is
// idempotent and may be called from any thread: on the loop thread
// (run_sync) it unwatches and closes the socket and drops the handler; no
// handler call follows its return. Called from a handler it ends delivery
// at once: the callback sees watch_.stopping() and touches the socket no more.

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <shared_mutex>
#include <memory>
#include <string>

#include <net/if.h>
#include <net/if_arp.h>
#include <sys/epoll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>

#include "channels/error.hpp"
#include "channels/drivers/can_common.hpp"
#include "channels/drivers/can_emu.hpp"
#include "channels/drivers/can_id.hpp"
#include "channels/drivers/loop_watch.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"

namespace herm {

namespace {

using can::can_config;
using can::can_driver;
using posix::errno_text;
using posix::unique_fd;

/// Frames read per readiness callback at most.
constexpr int max_reads_per_turn = 64;

/// Errors with which a CAN socket says its interface is gone or down.
bool is_down_error(int err) {
  return err == ENETDOWN || err == ENODEV || err == ENXIO;
}

// -- SocketCAN -------------------------------------------------------------------

class socketcan_driver final : public can_driver {
public:
  explicit socketcan_driver(can_config cfg) : can_driver(std::move(cfg)) {
  }

  /// Must not run inside a handler call of this driver (i.e. the handler
  /// must not drop the last reference to its driver).
  ~socketcan_driver() override {
    stop();
  }

  /// Opens and binds the socket. Errors: ec::device_unavailable naming the
  /// interface and what is wrong with it.
  caf::error open() {
    auto& ifname = cfg_.interface;
    ifindex_ = ::if_nametoindex(ifname.c_str());
    if (ifindex_ == 0)
      return fail(ec::device_unavailable,
                  "no network interface '" + ifname + "' ("
                    + errno_text(errno) + ")");
    // Interface type, state and MTU, asked through a plain socket so that
    // a kernel without CAN still says what is wrong with the interface.
    unique_fd probe{::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0)};
    if (!probe)
      probe.reset(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
    ifreq ifr{};
    std::memcpy(ifr.ifr_name, ifname.c_str(), ifname.size());
    if (::ioctl(probe.get(), SIOCGIFHWADDR, &ifr) != 0)
      return fail(ec::device_unavailable, "cannot query interface '" + ifname
                                            + "': " + errno_text(errno));
    if (ifr.ifr_hwaddr.sa_family != ARPHRD_CAN)
      return fail(ec::device_unavailable,
                  "interface '" + ifname + "' is not a CAN interface (link type "
                    + std::to_string(ifr.ifr_hwaddr.sa_family) + ", CAN is "
                    + std::to_string(ARPHRD_CAN) + ")");
    if (::ioctl(probe.get(), SIOCGIFFLAGS, &ifr) != 0)
      return fail(ec::device_unavailable, "cannot query interface '" + ifname
                                            + "': " + errno_text(errno));
    if ((ifr.ifr_flags & IFF_UP) == 0)
      return fail(ec::device_unavailable,
                  "interface '" + ifname + "' is down (ip link set " + ifname
                    + " up)");
    if (::ioctl(probe.get(), SIOCGIFMTU, &ifr) != 0)
      return fail(ec::device_unavailable, "cannot read the MTU of '" + ifname
                                            + "': " + errno_text(errno));
    if_mtu_ = ifr.ifr_mtu;
    if (cfg_.fd && if_mtu_ < static_cast<int>(CANFD_MTU))
      return fail(ec::device_unavailable,
                  "interface '" + ifname + "' is not CAN FD capable (MTU "
                    + std::to_string(if_mtu_) + ", CAN FD needs "
                    + std::to_string(CANFD_MTU)
                    + "); use fd=false or a CAN FD interface");
    fd_.reset(
      ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW));
    if (!fd_)
      return fail(ec::device_unavailable,
                  "cannot open a CAN_RAW socket for '" + ifname + "': "
                    + errno_text(errno)
                    + " (does the kernel have SocketCAN, module can-raw?)");
    auto set = [&](int opt, const void* val, socklen_t len,
                   const char* what) -> caf::error {
      if (::setsockopt(fd_.get(), SOL_CAN_RAW, opt, val, len) == 0)
        return caf::none;
      return fail(ec::device_unavailable,
                  std::string{"cannot set "} + what + " on '" + ifname
                    + "': " + errno_text(errno));
    };
    // Count what a full receive buffer drops, as candump does.
    int one = 1;
    if (::setsockopt(fd_.get(), SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof(one))
        != 0)
      return fail(ec::device_unavailable,
                  "cannot enable SO_RXQ_OVFL on '" + ifname
                    + "': " + errno_text(errno));
    int off = 0;
    if (auto err = set(CAN_RAW_RECV_OWN_MSGS, &off, sizeof(off),
                       "CAN_RAW_RECV_OWN_MSGS"))
      return err;
    if (cfg_.fd) {
      int on = 1;
      if (auto err = set(CAN_RAW_FD_FRAMES, &on, sizeof(on),
                         "CAN_RAW_FD_FRAMES"))
        return err;
    }
    can_err_mask_t err_mask = CAN_ERR_BUSOFF | CAN_ERR_CRTL
                              | CAN_ERR_RESTARTED;
    if (auto err = set(CAN_RAW_ERR_FILTER, &err_mask, sizeof(err_mask),
                       "CAN_RAW_ERR_FILTER"))
      return err;
    if (cfg_.filter) {
      auto own = can::destination_filter(cfg_.format, cfg_.node);
      auto all = can::destination_filter(cfg_.format,
                                         can::broadcast_node(cfg_.format));
      can_filter filters[2] = {{own.id, own.mask}, {all.id, all.mask}};
      if (auto err = set(CAN_RAW_FILTER, filters, sizeof(filters),
                         "CAN_RAW_FILTER"))
        return err;
    }
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = static_cast<int>(ifindex_);
    if (::bind(fd_.get(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr))
        != 0)
      return fail(ec::device_unavailable, "cannot bind to '" + ifname
                                            + "': " + errno_text(errno));
    return caf::none;
  }

  /// Watches the socket on `loop`; see the file comment for the contract.
  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop& loop) override {
    return watch_.start(
      loop, fd_.get(), handler != nullptr, "socket",
      [this](ec code, const std::string& what) { return fail(code, what); },
      nullptr, [this](uint32_t events) { on_ready(events); },
      [&] {
        handler_ = std::move(handler);
        // A send() before start may have found the interface gone.
        if (tx_down_errno_.load() != 0)
          post_tx_failure();
      });
  }

  void stop() override {
    watch_.stop([this] {
      close_socket();
      handler_.reset();
    });
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t priority) override {
    canfd_frame frame;
    auto n = build(dst, data, size, priority, frame);
    if (!n)
      return n.error();
    std::shared_lock<std::shared_mutex> guard{fd_mtx_};
    if (!fd_)
      return fail(ec::device_failed, "the device is stopped");
    for (;;) {
      auto res = ::send(fd_.get(), &frame, *n, MSG_DONTWAIT | MSG_NOSIGNAL);
      if (res == static_cast<ssize_t>(*n)) {
        ++tx_frames_;
        return caf::none;
      }
      auto err = res < 0 ? errno : EMSGSIZE;
      switch (err) {
        case EINTR:
          continue;
        case EAGAIN:
#if EAGAIN != EWOULDBLOCK
        case EWOULDBLOCK:
#endif
        case ENOBUFS:
          return fail(ec::queue_full, "transmit queue of '" + cfg_.interface
                                        + "' is full: " + errno_text(err));
        default:
          if (is_down_error(err)) {
            // Reported on the loop thread (once).
            int expected = 0;
            if (tx_down_errno_.compare_exchange_strong(expected, err))
              post_tx_failure();
          }
          return fail(ec::device_failed, "cannot send on '" + cfg_.interface
                                           + "': " + errno_text(err));
      }
    }
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "ifindex")
      return std::to_string(ifindex_);
    if (key == "if_mtu")
      return std::to_string(if_mtu_);
    if (key == "backend")
      return std::string{"socketcan"};
    if (key == "rx_kernel_dropped")
      return std::to_string(kernel_dropped_.load());
    return can_driver::get_param(key);
  }

private:
  bool delivery_ended() const override {
    return watch_.stopping();
  }

  /// Closes the socket (stop). On the loop thread once started.
  void close_socket() {
    *alive_ = false;
    std::unique_lock<std::shared_mutex> fd_guard{fd_mtx_};
    fd_.reset();
  }

  /// Has the loop thread report tx_down_errno_. Requires fd_mtx_ (shared)
  /// or the life-cycle lock; does nothing before start (start posts it
  /// then).
  void post_tx_failure() {
    auto* loop = watch_.loop();
    if (loop == nullptr)
      return;
    loop->post([this, alive = alive_] {
      if (*alive)
        report_failure(tx_down_errno_.load());
    });
  }

  /// Reports the failure once and stops watching the socket. Loop thread.
  void report_failure(int err) {
    if (watch_.stopping() || failed_)
      return;
    failed_ = true;
    watch_.unwatch();
    std::string what = err == ENETDOWN
                         ? "interface '" + cfg_.interface + "' went down"
                       : err == ENODEV || err == ENXIO
                         ? "interface '" + cfg_.interface + "' disappeared"
                         : "CAN socket on '" + cfg_.interface + "' failed";
    handler_->on_failure(
      fail(ec::device_failed, what + " (" + errno_text(err) + ")"));
  }

  // -- the loop thread -----------------------------------------------------------

  /// The socket's readiness callback.
  void on_ready(uint32_t events) {
    // Keeps the handler alive should it stop the driver during a call.
    auto keep = handler_;
    if ((events & EPOLLERR) != 0) {
      // raw_notify() sets ENETDOWN when the interface goes down and ENODEV
      // when it is unregistered. Reading SO_ERROR clears it.
      int err = 0;
      socklen_t len = sizeof(err);
      if (::getsockopt(fd_.get(), SOL_SOCKET, SO_ERROR, &err, &len) != 0)
        err = errno;
      if (err != 0)
        return report_failure(err);
    }
    if ((events & EPOLLIN) == 0)
      return;
    canfd_frame frame;
    for (int i = 0; i < max_reads_per_turn; ++i) {
      // SO_RXQ_OVFL: the socket's drop count (cumulative, modulo 2^32)
      // rides on frames received after drops happened.
      alignas(cmsghdr) char control[CMSG_SPACE(sizeof(uint32_t))];
      iovec iov{&frame, sizeof(frame)};
      msghdr msg{};
      msg.msg_iov = &iov;
      msg.msg_iovlen = 1;
      msg.msg_control = control;
      msg.msg_controllen = sizeof(control);
      auto n = ::recvmsg(fd_.get(), &msg, MSG_DONTWAIT);
      if (n < 0) {
        auto err = errno;
        if (err == EINTR)
          continue;
        if (err == EAGAIN || err == EWOULDBLOCK)
          return;
        return report_failure(err);
      }
      note_drops(msg);
      if (watch_.stopping())
        return;
      dispatch(*handler_, frame, static_cast<size_t>(n));
      if (watch_.stopping())
        return;
    }
  }

  /// Reports what the kernel dropped since the last frame that told us.
  void note_drops(const msghdr& msg) {
    if (auto delta = rxq_.drops_since(msg); delta > 0) {
      kernel_dropped_ += delta;
      handler_->on_kernel_drops(delta);
    }
  }

  unsigned ifindex_ = 0;
  int if_mtu_ = 0;
  posix::rxq_overflow rxq_;
  std::atomic<uint64_t> kernel_dropped_{0};

  /// Guards closing fd_ against concurrent send() calls.
  mutable std::shared_mutex fd_mtx_;
  unique_fd fd_;

  /// The life cycle (start, stop) on the event loop; its loop() is read by
  /// send() (post_tx_failure) on any thread.
  loop_watch watch_;
  /// on_failure was called (loop thread).
  bool failed_ = false;
  std::atomic<int> tx_down_errno_{0};
  /// Cleared by stop; tasks posted to the loop check it first.
  std::shared_ptr<std::atomic<bool>> alive_
    = std::make_shared<std::atomic<bool>>(true);
  std::shared_ptr<frame_handler> handler_;
};

// -- the link kind ---------------------------------------------------------------

caf::expected<link_driver_ptr> open_can(const device_config& cfg) {
  auto conf = can::read_config(cfg);
  if (!conf)
    return conf.error();
  if (conf->kind == can::backend::emu)
    return can::open_emulated_bus(std::move(*conf));
  auto driver = std::make_shared<socketcan_driver>(std::move(*conf));
  if (auto err = driver->open())
    return err;
  return link_driver_ptr{std::move(driver)};
}

caf::error check_can(const device_config& cfg) {
  auto x = can::read_config(cfg);
  return x ? caf::error{} : std::move(x.error());
}

} // namespace

const link_kind& can_link_kind() {
  static const link_kind kind{
    "can",
    "CAN 2.0B / CAN FD bus: SocketCAN interface (can0, vcan0) or an emulated "
    "bus between processes (emu:/path) with arbitration and bit-rate pacing",
    open_can, check_can};
  return kind;
}

} // namespace herm
