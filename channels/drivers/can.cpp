// Link kind "can": HERM frames as CAN 2.0B (or CAN FD) data frames, the
// identifier carrying priority, destination and source node
// (channels/drivers/can_id.hpp, docs/protocol.md). Two backends share
// the frame format, option set and receive path:
//
//  * SocketCAN (interface "can0", "vcan0", ...): a PF_CAN/SOCK_RAW/CAN_RAW
//    socket bound to the interface, following can-utils' cansend/candump:
//    if_nametoindex, SIOCGIFMTU before enabling CAN FD, reads accepted only
//    when exactly CAN_MTU or CANFD_MTU bytes long, an error-frame mask for
//    bus-off, controller problems and restarts, a kernel receive filter on
//    the destination field, own messages not received.
//
//  * The emulated bus (interface "emu:/path/to/bus-directory"), for hosts
//    without CAN: stations in any number of processes, each with a unix
//    datagram socket <dir>/<node>.sock, and a shared mmapped file <dir>/bus
//    holding the bus state: "busy until" (CLOCK_MONOTONIC ns) and one slot
//    per node in which a station publishes the arbitration key and ready
//    time of the frame it wants to send next. Arbitration: when the bus is
//    idle, the frames that were ready at the first moment the bus was idle
//    with something to send compete, and only the station with the lowest
//    identifier among them may take the bus, by compare-and-swap of "busy
//    until" (so exactly one station wins an idle period, and bus time is
//    never handed out twice). The winner sends the frame (struct can_frame /
//    canfd_frame bytes behind a small header, can_emu_wire.hpp) to every
//    other station with the time its transmission ends; receivers hold
//    frames until then, so all hear the bus in one order, and filter by
//    destination like a controller. Frame times are real CAN frame lengths
//    at the configured bit rate (can::frame_bits). See transmit_loop and
//    docs/protocol.md.
//
// Threads: SocketCAN has one receive thread (poll on the socket and an
// eventfd). The emulated bus adds a transmit thread (arbitration, pacing,
// fan-out). send() never blocks beyond one non-blocking system call (or a
// mutex for the emulated queue); the frame_handler is called from the
// receive thread only, and on_failure at most once.

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <random>
#include <shared_mutex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>

#include "channels/error.hpp"
#include "channels/drivers/can_emu_wire.hpp"
#include "channels/drivers/can_id.hpp"
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
  return list_stations(dir, 1, 254);
}


// -- constants -------------------------------------------------------------------

constexpr const char* emu_scheme = "emu:";

/// Slots of the bus file, indexed by node id.
constexpr size_t bus_slots = 256;
constexpr uint32_t bus_magic = 0x4E414348; // "HCAN"
constexpr uint32_t bus_version = 1;

/// How often the receive thread checks that its files still exist.
constexpr int64_t liveness_period_ns = 100'000'000;
/// Broadcast destinations are rescanned at least this often.
constexpr int64_t rescan_period_ns = 100'000'000;
/// A station waiting for the bus refreshes its heartbeat at least this often.
constexpr int64_t heartbeat_period_ns = 100'000'000;
/// A published frame whose station has not shown a heartbeat for this long
/// belongs to a dead or stopped process: arbitration ignores it.
constexpr int64_t stale_ns = 1'000'000'000;
/// How long a station that lost arbitration naps before looking again (the
/// winner takes the bus within microseconds).
constexpr int64_t backoff_ns = 20'000;
/// Bound of the back-to-back credit: a transmission starts no earlier than
/// this before now, however late the transmitter woke (see transmit_loop).
constexpr int64_t max_credit_ns = 50'000'000;
/// Grace period of a receiver whose socket queue is full.
constexpr int64_t overrun_wait_ns = 25'000'000;
/// Frames held by a receiver for delivery at the end of their transmission.
constexpr size_t max_held_frames = 4096;
/// Reads per wake-up of a receive thread.
constexpr int max_reads_per_wakeup = 64;
/// Bits an error frame adds after a destroyed frame: error flag (6) plus
/// superposition (6), delimiter (8), intermission (3).
constexpr uint32_t error_frame_bits = 23;

// -- small helpers ---------------------------------------------------------------

std::chrono::steady_clock::time_point to_time_point(int64_t ns) {
  // libstdc++'s steady_clock is CLOCK_MONOTONIC.
  return std::chrono::steady_clock::time_point{std::chrono::nanoseconds{ns}};
}

std::string hex(uint32_t x) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%X", x);
  return buf;
}

/// Errors with which a CAN socket says its interface is gone or down.
bool is_down_error(int err) {
  return err == ENETDOWN || err == ENODEV || err == ENXIO;
}

// -- configuration ---------------------------------------------------------------

enum class backend { socketcan, emu };

struct can_config {
  std::string name;
  /// The network interface (SocketCAN) or the bus directory (emulated).
  std::string interface;
  backend kind = backend::socketcan;
  can::id_format format = can::id_format::ext29;
  uint8_t node = 0;
  bool fd = false;
  uint64_t bitrate = 1'000'000;
  bool stuffing = false;
  double delay_coef = 1.0;
  // SocketCAN only.
  bool filter = true;
  // Emulated bus only.
  uint64_t queue = 64;
  double loss = 0;
  double error_rate = 0;
  uint64_t seed = 0;
  bool create = true;
};

caf::expected<can_config> read_config(const device_config& cfg) {
  option_reader r{cfg};
  can_config c;
  c.name = cfg.name;
  if (cfg.interface.rfind(emu_scheme, 0) == 0) {
    c.kind = backend::emu;
    c.interface = cfg.interface.substr(std::strlen(emu_scheme));
    while (c.interface.size() > 1 && c.interface.back() == '/')
      c.interface.pop_back();
    if (c.interface.empty())
      return r.fail(ec::invalid_address,
                    "interface '" + cfg.interface
                      + "' names no bus directory (expected "
                        "emu:/path/to/bus-directory)");
    // Longest socket path: <dir>/254.sock.
    auto longest = c.interface.size() + 1 + station_file(254).size();
    if (longest >= sizeof(sockaddr_un::sun_path))
      return r.fail(ec::invalid_address,
                    "bus directory '" + c.interface
                      + "' is too long for unix socket paths in it ("
                      + std::to_string(longest) + " bytes, at most "
                      + std::to_string(sizeof(sockaddr_un::sun_path) - 1)
                      + ")");
  } else {
    c.interface = cfg.interface;
    if (c.interface.empty() || c.interface.size() >= IFNAMSIZ
        || c.interface.find_first_of("/ \t:") != std::string::npos)
      return r.fail(ec::invalid_address,
                    "interface '" + cfg.interface
                      + "' is neither a network interface name (can0, "
                        "vcan0) nor emu:/path/to/bus-directory");
  }
  auto format = r.str("id_format", "29bit");
  if (format == "29bit")
    c.format = can::id_format::ext29;
  else if (format == "11bit")
    c.format = can::id_format::std11;
  else
    return r.fail(ec::invalid_parameter,
                  "option 'id_format' expects 29bit or 11bit, got '" + format
                    + "'");
  auto max_node = can::max_node(c.format);
  if (!r.has("node"))
    return r.fail(ec::invalid_parameter,
                  "option 'node' is required: this module's node id on the "
                  "bus, 1.."
                    + std::to_string(max_node));
  auto node = r.u64("node", 0, 1, max_node);
  if (!node)
    return node.error();
  c.node = static_cast<uint8_t>(*node);
  auto fd = r.flag("fd", false);
  if (!fd)
    return fd.error();
  c.fd = *fd;
  if (c.fd && c.format == can::id_format::std11)
    return r.fail(ec::invalid_parameter,
                  "option 'fd' needs id_format=29bit (11-bit identifiers "
                  "have no room for CAN FD padding)");
  auto bitrate = r.u64("bitrate", 1'000'000, 1'000, 10'000'000);
  if (!bitrate)
    return bitrate.error();
  c.bitrate = *bitrate;
  auto stuffing = r.flag("stuffing", false);
  if (!stuffing)
    return stuffing.error();
  c.stuffing = *stuffing;
  auto coef = r.real("delay_coef", 1.0, 0.001, 1000.0);
  if (!coef)
    return coef.error();
  c.delay_coef = *coef;
  if (c.kind == backend::socketcan) {
    auto filter = r.flag("filter", true);
    if (!filter)
      return filter.error();
    c.filter = *filter;
  } else {
    auto queue = r.u64("queue", 64, 1, 65'536);
    if (!queue)
      return queue.error();
    c.queue = *queue;
    auto loss = r.real("loss", 0, 0, 1);
    if (!loss)
      return loss.error();
    c.loss = *loss;
    auto error_rate = r.real("error_rate", 0, 0, 0.9);
    if (!error_rate)
      return error_rate.error();
    c.error_rate = *error_rate;
    auto seed = r.u64("seed", 0, 0, UINT64_MAX);
    if (!seed)
      return seed.error();
    c.seed = *seed;
    auto create = r.flag("create", true);
    if (!create)
      return create.error();
    c.create = *create;
  }
  if (auto err = r.finish())
    return err;
  return c;
}

// -- the common part of both backends --------------------------------------------

class can_driver : public link_driver {
public:
  explicit can_driver(can_config cfg)
    : cfg_(std::move(cfg)), prefix_("device '" + cfg_.name + "': ") {
    auto mtu = cfg_.fd ? can::fd_max_len : can::classic_max_len;
    profile_ = *find_profile("can2.0");
    if (cfg_.fd)
      profile_.name = "canfd";
    profile_.bandwidth_bps = cfg_.bitrate;
    profile_.mtu = static_cast<uint32_t>(mtu);
    profile_.delay_coef = cfg_.delay_coef;
    profile_.frame_overhead_bits
      = can::frame_bits(cfg_.format, mtu, cfg_.stuffing)
        - 8 * static_cast<uint32_t>(mtu);
  }

  const link_profile& profile() const override {
    return profile_;
  }

  link_addr local_addr() const override {
    return cfg_.node;
  }

  /// can::lane_of the identifier a frame to `dst` with `priority` gets.
  uint8_t lane(link_addr dst, uint8_t priority) const override {
    can::frame_id id;
    id.priority = std::min(priority, can::max_priority);
    id.dst = dst == broadcast_addr ? can::broadcast_node(cfg_.format) : 1;
    return can::lane_of(cfg_.format, id);
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
    auto max = can::max_node(cfg_.format);
    if (!ok || n < 1 || n > max)
      return fail(ec::invalid_address, "'" + str + "' is not a CAN node id (1.."
                                         + std::to_string(max) + ")");
    return n;
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "node")
      return std::to_string(cfg_.node);
    if (key == "bitrate")
      return std::to_string(cfg_.bitrate);
    if (key == "id_format")
      return std::string{can::to_string(cfg_.format)};
    if (key == "fd")
      return std::string{cfg_.fd ? "true" : "false"};
    if (key == "interface")
      return cfg_.interface;
    if (key == "tx_frames")
      return std::to_string(tx_frames_.load());
    if (key == "rx_frames")
      return std::to_string(rx_frames_.load());
    if (key == "rx_malformed")
      return std::to_string(rx_malformed_.load());
    if (key == "rx_filtered")
      return std::to_string(rx_filtered_.load());
    if (key == "error_frames")
      return std::to_string(error_frames_.load());
    return link_driver::get_param(key);
  }

protected:
  caf::error fail(ec code, const std::string& what) const {
    return make_error(code, prefix_ + what);
  }

  /// Checks a send() request and builds its frame in `out` (zeroed first).
  /// Returns the bytes to hand to the medium: CAN_MTU or CANFD_MTU.
  caf::expected<size_t> build(link_addr dst, const uint8_t* data, size_t size,
                              uint8_t priority, canfd_frame& out) const {
    if (size > profile_.mtu)
      return fail(ec::packet_too_large,
                  "frame of " + std::to_string(size)
                    + " bytes exceeds the MTU of "
                    + std::to_string(profile_.mtu) + " bytes");
    can::frame_id id;
    if (dst == broadcast_addr) {
      id.dst = can::broadcast_node(cfg_.format);
    } else if (dst >= 1 && dst <= can::max_node(cfg_.format)) {
      id.dst = static_cast<uint8_t>(dst);
    } else {
      return fail(ec::invalid_address,
                  std::to_string(dst) + " is not a CAN node id (1.."
                    + std::to_string(can::max_node(cfg_.format)) + ")");
    }
    id.src = cfg_.node;
    id.priority = std::min(priority, can::max_priority);
    std::memset(&out, 0, sizeof(out));
    size_t len = size;
    if (cfg_.fd) {
      len = can::fd_round_up(size);
      id.pad = static_cast<uint8_t>(len - size);
      out.flags = CANFD_FDF;
    }
    out.can_id = can::to_can_id(cfg_.format, id);
    out.len = static_cast<uint8_t>(len);
    if (size > 0)
      std::memcpy(out.data, data, size);
    return cfg_.fd ? size_t{CANFD_MTU} : size_t{CAN_MTU};
  }

  /// Hands one frame read from the medium, `nbytes` long as read, to `h`:
  /// error frames become events, HERM frames for this node on_frame, frames
  /// for other nodes are filtered out, everything else is malformed.
  void dispatch(frame_handler& h, const canfd_frame& f, size_t nbytes) {
    if (nbytes != CAN_MTU && nbytes != CANFD_MTU) {
      malformed(h, 0, "read of " + std::to_string(nbytes)
                        + " bytes is neither CAN_MTU nor CANFD_MTU");
      return;
    }
    bool fd = nbytes == CANFD_MTU;
    if ((f.can_id & CAN_ERR_FLAG) != 0) {
      error_frame(h, f);
      return;
    }
    can::frame_id id;
    size_t payload = 0;
    auto st = can::decode_frame(cfg_.format, f.can_id, f.len, fd, id, payload);
    if (st != can::id_status::ok) {
      // Name the sender when the identifier itself is fine.
      link_addr src = 0;
      can::frame_id tmp;
      if (can::decode_id(cfg_.format, f.can_id, tmp) == can::id_status::ok)
        src = tmp.src;
      malformed(h, src, std::string{can::to_string(st)} + " (id "
                          + hex(f.can_id) + ", len "
                          + std::to_string(f.len) + (fd ? ", CAN FD)" : ")"));
      return;
    }
    if (!can::accepts(cfg_.format, cfg_.node, id.dst)) {
      ++rx_filtered_;
      return;
    }
    // A CAN FD controller also takes classic frames; a classic one cannot
    // take CAN FD frames (on a real bus it would flag errors).
    if (fd && !cfg_.fd) {
      malformed(h, id.src, "CAN FD frame at a station with fd=false");
      return;
    }
    if (id.src == cfg_.node) {
      malformed(h, id.src,
                "frame from this node's own id " + std::to_string(cfg_.node)
                  + " (another station uses the same node id?)");
      return;
    }
    ++rx_frames_;
    h.on_frame_in_lane(id.src, can::lane_of(cfg_.format, id), f.data,
                       payload);
  }

  void malformed(frame_handler& h, link_addr src, const std::string& why) {
    ++rx_malformed_;
    auto text = "can: " + why;
    h.on_malformed(src, text.c_str());
  }

  /// Maps an error frame (CAN_ERR_FLAG, classes in linux/can/error.h) to
  /// link events.
  void error_frame(frame_handler& h, const canfd_frame& f) {
    ++error_frames_;
    auto cls = f.can_id & CAN_ERR_MASK;
    bool reported = false;
    if ((cls & CAN_ERR_BUSOFF) != 0) {
      h.on_event(link_event_kind::bus_off, 0,
                 "controller of " + cfg_.interface + " is bus-off");
      reported = true;
    }
    if ((cls & CAN_ERR_RESTARTED) != 0) {
      h.on_event(link_event_kind::bus_recovered, 0,
                 "controller of " + cfg_.interface + " restarted");
      reported = true;
    }
    if ((cls & CAN_ERR_CRTL) != 0) {
      auto state = f.data[1];
      if (state == CAN_ERR_CRTL_ACTIVE) {
        h.on_event(link_event_kind::bus_recovered, 0,
                   "controller of " + cfg_.interface
                     + " is error-active again");
      } else {
        std::string what;
        auto add = [&](uint8_t bit, const char* text) {
          if ((state & bit) != 0)
            what += (what.empty() ? "" : ", ") + std::string{text};
        };
        add(CAN_ERR_CRTL_RX_OVERFLOW, "rx overflow");
        add(CAN_ERR_CRTL_TX_OVERFLOW, "tx overflow");
        add(CAN_ERR_CRTL_RX_WARNING, "rx warning level");
        add(CAN_ERR_CRTL_TX_WARNING, "tx warning level");
        add(CAN_ERR_CRTL_RX_PASSIVE, "rx error-passive");
        add(CAN_ERR_CRTL_TX_PASSIVE, "tx error-passive");
        h.on_event(link_event_kind::error_frame, 0,
                   "controller problem on " + cfg_.interface + ": "
                     + (what.empty() ? "unspecified" : what));
      }
      reported = true;
    }
    auto rest = cls & ~(CAN_ERR_BUSOFF | CAN_ERR_RESTARTED | CAN_ERR_CRTL);
    if (rest != 0 || !reported)
      h.on_event(link_event_kind::error_frame, 0,
                 "error frame on " + cfg_.interface + " (class "
                   + hex(cls) + ")");
  }

  const can_config cfg_;
  const std::string prefix_;
  link_profile profile_;

  // Counters (get_param).
  std::atomic<uint64_t> tx_frames_{0};
  std::atomic<uint64_t> rx_frames_{0};
  std::atomic<uint64_t> rx_malformed_{0};
  std::atomic<uint64_t> rx_filtered_{0};
  std::atomic<uint64_t> error_frames_{0};
};

// -- SocketCAN -------------------------------------------------------------------

class socketcan_driver final : public can_driver {
public:
  explicit socketcan_driver(can_config cfg) : can_driver(std::move(cfg)) {
  }

  /// Must not run on the receive thread.
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
    wake_fd_.reset(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!wake_fd_)
      return fail(ec::device_unavailable,
                  "cannot create eventfd: " + errno_text(errno));
    return caf::none;
  }

  caf::error start(std::shared_ptr<frame_handler> handler) override {
    std::lock_guard<std::mutex> guard{life_mtx_};
    if (state_ != state::opened)
      return fail(ec::device_unavailable, state_ == state::running
                                            ? "already started"
                                            : "already stopped");
    if (!handler)
      return fail(ec::invalid_parameter, "start needs a frame handler");
    handler_ = std::move(handler);
    try {
      thread_ = std::thread{[this] { receive_loop(); }};
    } catch (const std::system_error& ex) {
      handler_.reset();
      return fail(ec::device_unavailable,
                  std::string{"cannot start the receive thread: "} + ex.what());
    }
    state_ = state::running;
    return caf::none;
  }

  void stop() override {
    std::lock_guard<std::mutex> guard{life_mtx_};
    if (state_ == state::stopped)
      return;
    state_ = state::stopped;
    stopping_.store(true);
    wake();
    if (thread_.joinable()) {
      if (thread_.get_id() == std::this_thread::get_id()) {
        // Called from a handler: the loop ends after this callback and
        // still uses the descriptors, so leave them open until destruction.
        thread_.detach();
        return;
      }
      thread_.join();
    }
    handler_.reset();
    std::unique_lock<std::shared_mutex> fd_guard{fd_mtx_};
    fd_.reset();
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
            // The receive thread reports the failure (once).
            int expected = 0;
            tx_down_errno_.compare_exchange_strong(expected, err);
            wake();
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
  enum class state { opened, running, stopped };

  void wake() {
    if (wake_fd_) {
      uint64_t one = 1;
      [[maybe_unused]] auto res = ::write(wake_fd_.get(), &one, sizeof(one));
    }
  }

  void report_failure(int err) {
    if (stopping_.load())
      return;
    std::string what = err == ENETDOWN
                         ? "interface '" + cfg_.interface + "' went down"
                       : err == ENODEV || err == ENXIO
                         ? "interface '" + cfg_.interface + "' disappeared"
                         : "CAN socket on '" + cfg_.interface + "' failed";
    handler_->on_failure(
      fail(ec::device_failed, what + " (" + errno_text(err) + ")"));
  }

  void receive_loop() {
    pthread_setname_np(pthread_self(), "herm-can");
    pollfd fds[2] = {{fd_.get(), POLLIN, 0}, {wake_fd_.get(), POLLIN, 0}};
    canfd_frame frame;
    while (!stopping_.load()) {
      if (auto err = tx_down_errno_.load()) {
        report_failure(err);
        return;
      }
      if (::poll(fds, 2, -1) < 0) {
        if (errno == EINTR)
          continue;
        report_failure(errno);
        return;
      }
      if (fds[1].revents != 0) {
        uint64_t count;
        [[maybe_unused]] auto res = ::read(wake_fd_.get(), &count,
                                           sizeof(count));
        continue; // re-check stopping_ and tx_down_errno_
      }
      auto ev = fds[0].revents;
      if ((ev & POLLNVAL) != 0) {
        report_failure(EBADF);
        return;
      }
      if ((ev & POLLERR) != 0) {
        // raw_notify() sets ENETDOWN when the interface goes down and ENODEV
        // when it is unregistered. Reading SO_ERROR clears it.
        int err = 0;
        socklen_t len = sizeof(err);
        if (::getsockopt(fd_.get(), SOL_SOCKET, SO_ERROR, &err, &len) != 0)
          err = errno;
        if (err != 0) {
          report_failure(err);
          return;
        }
      }
      if ((ev & POLLIN) == 0)
        continue;
      for (int i = 0; i < max_reads_per_wakeup && !stopping_.load(); ++i) {
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
        if (n >= 0)
          note_drops(msg);
        if (n < 0) {
          auto err = errno;
          if (err == EINTR)
            continue;
          if (err == EAGAIN || err == EWOULDBLOCK)
            break;
          report_failure(err);
          return;
        }
        dispatch(*handler_, frame, static_cast<size_t>(n));
      }
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
  unique_fd wake_fd_;

  std::mutex life_mtx_;
  state state_ = state::opened;
  std::atomic<bool> stopping_{false};
  std::atomic<int> tx_down_errno_{0};
  std::thread thread_;
  std::shared_ptr<frame_handler> handler_;
};

// -- emulated bus: shared state ----------------------------------------------------

/// What a station wants to send next. Written by its own transmit path only.
struct bus_slot {
  /// 0: nothing; else 1 << 32 | can::arbitration_key of the frame.
  std::atomic<uint64_t> pending;
  /// When that frame was handed to the driver, CLOCK_MONOTONIC ns.
  std::atomic<int64_t> ready_at;
  /// Last sign of life of the station's transmit path, CLOCK_MONOTONIC ns.
  std::atomic<int64_t> heartbeat;
  std::atomic<int64_t> reserved;
};

/// Layout of <dir>/bus. Lives in MAP_SHARED memory of several processes:
/// only lock-free atomics, no pointers.
struct bus_layout {
  uint32_t magic;
  uint32_t version;
  /// Bit rate of the stations on the bus, bit/s.
  std::atomic<uint64_t> bitrate;
  /// Bumped whenever a station binds or unbinds, so transmitters rescan.
  std::atomic<uint32_t> generation;
  uint32_t reserved0;
  uint8_t reserved[40];
  /// The bus is occupied until then, CLOCK_MONOTONIC ns. Only grows.
  std::atomic<int64_t> busy_until;
  uint8_t reserved1[56];
  bus_slot slots[bus_slots];
};

static_assert(std::atomic<int64_t>::is_always_lock_free,
              "the bus file needs address-free 64-bit atomics");
static_assert(std::atomic<uint64_t>::is_always_lock_free,
              "the bus file needs address-free 64-bit atomics");
static_assert(std::atomic<uint32_t>::is_always_lock_free,
              "the bus file needs address-free 32-bit atomics");
static_assert(sizeof(bus_slot) == 32, "the bus file layout is shared");
static_assert(sizeof(bus_layout) == 128 + 32 * bus_slots,
              "the bus file layout is shared");

/// Holds flock(LOCK_EX) on the bus file while a station joins.
struct bus_lock {
  unique_fd fd;
  bus_lock() = default;
  bus_lock(const bus_lock&) = delete;
  bus_lock& operator=(const bus_lock&) = delete;
  ~bus_lock() {
    if (fd)
      ::flock(fd.get(), LOCK_UN);
  }
};

// -- emulated bus: the driver ------------------------------------------------------

class emu_can_driver final : public can_driver {
public:
  explicit emu_can_driver(can_config cfg)
    : can_driver(std::move(cfg)),
      bus_path_(cfg_.interface + "/bus"),
      loss_(cfg_.loss),
      error_rate_(cfg_.error_rate),
      rng_(cfg_.seed) {
  }

  ~emu_can_driver() override {
    stop();
    if (bus_ != nullptr)
      ::munmap(bus_, sizeof(bus_layout));
  }

  /// Joins the bus: directory, bus file, station socket.
  caf::error open() {
    if (auto err = open_directory())
      return err;
    bus_lock lock;
    if (auto err = open_bus(lock))
      return err;
    if (auto err = claim_station())
      return err;
    bus_->generation.fetch_add(1);
    return caf::none;
  }

  caf::error start_transmitter() {
    try {
      tx_thread_ = std::thread{[this] { transmit_loop(); }};
    } catch (const std::system_error& ex) {
      return fail(ec::device_unavailable,
                  std::string{"cannot start the transmit thread: "}
                    + ex.what());
    }
    return caf::none;
  }

  // -- link_driver ---------------------------------------------------------------

  caf::error start(std::shared_ptr<frame_handler> handler) override {
    std::lock_guard<std::mutex> guard{life_mtx_};
    if (!handler)
      return fail(ec::invalid_parameter, "start needs a frame handler");
    if (stopped_)
      return fail(ec::device_unavailable, "already stopped");
    if (rx_thread_.joinable())
      return fail(ec::device_unavailable, "already started");
    handler_ = std::move(handler);
    try {
      rx_thread_ = std::thread{[this] { receive_loop(); }};
    } catch (const std::system_error& ex) {
      handler_.reset();
      return fail(ec::device_unavailable,
                  std::string{"cannot start the receive thread: "} + ex.what());
    }
    return caf::none;
  }

  void stop() override {
    std::lock_guard<std::mutex> guard{life_mtx_};
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
      if (rx_thread_.get_id() == std::this_thread::get_id()) {
        // Called from a handler: the loop ends after this callback; the
        // descriptors stay open until destruction.
        rx_thread_.detach();
        detached_ = true;
      } else {
        rx_thread_.join();
      }
    }
    if (bus_ != nullptr) {
      auto& me = bus_->slots[cfg_.node];
      me.pending.store(0);
      me.heartbeat.store(0);
    }
    // Remove our socket file, unless somebody else's replaced it.
    struct stat st;
    if (sock_ino_ != 0 && ::stat(sock_path_.c_str(), &st) == 0
        && st.st_ino == sock_ino_ && st.st_dev == sock_dev_)
      ::unlink(sock_path_.c_str());
    if (bus_ != nullptr)
      bus_->generation.fetch_add(1);
    if (!detached_) {
      handler_.reset();
      rx_fd_.reset();
    }
    tx_fd_.reset();
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t priority) override {
    tx_frame f;
    auto n = build(dst, data, size, priority, f.frame);
    if (!n)
      return n.error();
    if (failed_.load())
      return fail(ec::device_failed, "the bus has failed");
    f.wire_size = *n;
    f.key = can::arbitration_key(f.frame.can_id);
    f.order = std::min(priority, can::max_priority);
    f.bits = can::frame_bits(cfg_.format, f.frame.len, cfg_.stuffing);
    f.enqueued_at = now_ns();
    std::lock_guard<std::mutex> guard{mtx_};
    if (stopping_)
      return fail(ec::device_failed, "the device is stopped");
    if (queue_.size() >= cfg_.queue)
      return fail(ec::queue_full, "transmit queue full ("
                                    + std::to_string(cfg_.queue)
                                    + " frames)");
    f.seq = next_seq_++;
    queue_.push_back(f);
    std::push_heap(queue_.begin(), queue_.end(), later);
    // Published before send() returns: from now on, the frame takes part
    // in every arbitration on the bus.
    publish(queue_.front());
    if (tx_idle_)
      tx_cv_.notify_one();
    return caf::none;
  }

  caf::error set_param(const std::string& key,
                       const std::string& value) override {
    device_config tmp{cfg_.name, "can", emu_scheme + cfg_.interface,
                      {{key, value}}};
    option_reader r{tmp};
    if (key == "loss") {
      auto x = r.real(key, 0, 0, 1);
      if (!x)
        return x.error();
      loss_.store(*x);
      return caf::none;
    }
    if (key == "error_rate") {
      auto x = r.real(key, 0, 0, 0.9);
      if (!x)
        return x.error();
      error_rate_.store(*x);
      return caf::none;
    }
    return fail(ec::invalid_parameter,
                "parameter '" + key
                  + "' cannot be changed on an emulated CAN bus (changeable: "
                    "loss, error_rate)");
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "backend")
      return std::string{"emu"};
    if (key == "loss")
      return format_double(loss_.load());
    if (key == "error_rate")
      return format_double(error_rate_.load());
    if (key == "tx_lost")
      return std::to_string(tx_lost_.load());
    if (key == "tx_overruns")
      return std::to_string(tx_overruns_.load());
    if (key == "tx_errors")
      return std::to_string(tx_errors_.load());
    if (key == "arbitration_lost")
      return std::to_string(arbitration_lost_.load());
    return can_driver::get_param(key);
  }

private:
  struct tx_frame {
    /// Arbitration key on the bus (can::arbitration_key).
    uint32_t key = 0;
    /// Order in our own queue: the priority (0..7).
    uint8_t order = 0;
    uint64_t seq = 0;
    int64_t enqueued_at = 0;
    uint32_t bits = 0;
    size_t wire_size = 0;
    canfd_frame frame;
  };

  /// std::*_heap comparator of the transmit queue: most urgent priority
  /// first, FIFO within a priority, so a control frame overtakes bulk
  /// frames queued before it. Receivers reassemble per lane (priority and
  /// broadcast, can::lane_of), so that costs no packet. (A controller whose
  /// mailboxes arbitrate by full identifier also lets unicasts overtake a
  /// broadcast of the same priority: another lane, also harmless.)
  static bool later(const tx_frame& x, const tx_frame& y) {
    return x.order != y.order ? x.order > y.order : x.seq > y.seq;
  }

  struct held_frame {
    int64_t deliver_at = 0;
    uint64_t seq = 0;
    bool error = false;
    size_t size = 0;
    canfd_frame frame;
  };

  static bool held_later(const held_frame& x, const held_frame& y) {
    return x.deliver_at != y.deliver_at ? x.deliver_at > y.deliver_at
                                        : x.seq > y.seq;
  }

  // -- opening -------------------------------------------------------------------

  caf::error open_directory() {
    auto& dir = cfg_.interface;
    struct stat st;
    if (::stat(dir.c_str(), &st) == 0) {
      if (!S_ISDIR(st.st_mode))
        return fail(ec::device_unavailable,
                    "bus path '" + dir + "' is not a directory");
      return caf::none;
    }
    auto err = errno;
    if (err != ENOENT)
      return fail(ec::device_unavailable, "cannot use bus directory '" + dir
                                            + "': " + errno_text(err));
    if (!cfg_.create)
      return fail(ec::device_unavailable,
                  "bus directory '" + dir
                    + "' does not exist (and option create=false)");
    if (auto e = make_dirs(dir))
      return fail(ec::device_unavailable, "cannot create bus directory '"
                                            + dir + "': " + errno_text(e));
    return caf::none;
  }

  caf::error open_bus(bus_lock& lock) {
    lock.fd.reset(
      ::open(bus_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666));
    auto fd = lock.fd.get();
    if (fd < 0)
      return fail(ec::device_unavailable, "cannot open bus file '" + bus_path_
                                            + "': " + errno_text(errno));
    while (::flock(fd, LOCK_EX) != 0)
      if (errno != EINTR)
        return fail(ec::device_unavailable, "cannot lock bus file '"
                                              + bus_path_
                                              + "': " + errno_text(errno));
    struct stat st;
    if (::fstat(fd, &st) != 0)
      return fail(ec::device_unavailable, "cannot stat bus file '" + bus_path_
                                            + "': " + errno_text(errno));
    if (st.st_size == 0 && ::ftruncate(fd, sizeof(bus_layout)) != 0)
      return fail(ec::device_unavailable, "cannot size bus file '" + bus_path_
                                            + "': " + errno_text(errno));
    if (st.st_size != 0 && st.st_size != off_t{sizeof(bus_layout)})
      return fail(ec::device_unavailable,
                  "'" + bus_path_ + "' is not an emulated CAN bus file ("
                    + std::to_string(st.st_size) + " bytes, expected "
                    + std::to_string(sizeof(bus_layout)) + ")");
    bus_dev_ = st.st_dev;
    bus_ino_ = st.st_ino;
    auto* mem = ::mmap(nullptr, sizeof(bus_layout), PROT_READ | PROT_WRITE,
                       MAP_SHARED, fd, 0);
    if (mem == MAP_FAILED)
      return fail(ec::device_unavailable, "cannot map bus file '" + bus_path_
                                            + "': " + errno_text(errno));
    bus_ = static_cast<bus_layout*>(mem);
    if (bus_->magic == 0 && bus_->version == 0) {
      bus_->magic = bus_magic;
      bus_->version = bus_version;
    } else if (bus_->magic != bus_magic) {
      return fail(ec::device_unavailable,
                  "'" + bus_path_ + "' is not an emulated CAN bus file");
    } else if (bus_->version != bus_version) {
      return fail(ec::device_unavailable,
                  "bus file '" + bus_path_ + "' has version "
                    + std::to_string(bus_->version)
                    + ", this driver speaks version "
                    + std::to_string(bus_version));
    }
    return caf::none;
  }

  /// Checks the bus's bit rate, claims the node id and binds the socket.
  /// Runs under the bus lock.
  caf::error claim_station() {
    auto& dir = cfg_.interface;
    std::vector<uint64_t> live;
    std::vector<uint64_t> stale;
    for (auto n : list_stations_in(dir)) {
      switch (probe_socket(dir + "/" + station_file(n))) {
        case probe_result::live: live.push_back(n); break;
        case probe_result::stale: stale.push_back(n); break;
        case probe_result::absent: break;
      }
    }
    if (live.empty()) {
      // First station: it sets the bit rate; state of earlier users goes.
      bus_->bitrate.store(cfg_.bitrate);
      bus_->busy_until.store(0);
      for (auto& slot : bus_->slots) {
        slot.pending.store(0);
        slot.ready_at.store(0);
        slot.heartbeat.store(0);
      }
    } else if (bus_->bitrate.load() != cfg_.bitrate) {
      return fail(ec::device_unavailable,
                  "bus '" + dir + "' runs at "
                    + std::to_string(bus_->bitrate.load())
                    + " bit/s (nodes " + join_numbers(live)
                    + "), this device is configured for "
                    + std::to_string(cfg_.bitrate) + " bit/s");
    }
    if (std::find(live.begin(), live.end(), cfg_.node) != live.end())
      return fail(ec::already_exists,
                  "node " + std::to_string(cfg_.node)
                    + " is already on bus '" + dir + "'");
    sock_path_ = dir + "/" + station_file(cfg_.node);
    if (std::find(stale.begin(), stale.end(), cfg_.node) != stale.end())
      ::unlink(sock_path_.c_str()); // left behind by a dead process
    auto& me = bus_->slots[cfg_.node];
    me.pending.store(0);
    me.ready_at.store(0);
    me.heartbeat.store(now_ns());
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
                    "node " + std::to_string(cfg_.node)
                      + " is already on bus '" + dir + "' (" + sock_path_
                      + " exists)");
      return fail(ec::device_unavailable,
                  "cannot bind " + sock_path_ + ": " + errno_text(err));
    }
    struct stat st;
    if (::stat(sock_path_.c_str(), &st) != 0)
      return fail(ec::device_unavailable, "cannot stat " + sock_path_ + ": "
                                            + errno_text(errno));
    sock_dev_ = st.st_dev;
    sock_ino_ = st.st_ino;
    int rcvbuf = 1 << 20; // best effort; capped at net.core.rmem_max
    ::setsockopt(rx_fd_.get(), SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
    tx_fd_.reset(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
    if (!tx_fd_)
      return fail(ec::device_unavailable,
                  "cannot create socket: " + errno_text(errno));
    timeval tv{0, overrun_wait_ns / 1000};
    ::setsockopt(tx_fd_.get(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof(tv));
    wake_fd_.reset(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!wake_fd_)
      return fail(ec::device_unavailable,
                  "cannot create eventfd: " + errno_text(errno));
    for (uint64_t n = 1; n <= 254; ++n)
      peer_addrs_[n] = unix_addr(dir + "/" + station_file(n));
    return caf::none;
  }

  // -- arbitration and transmission ------------------------------------------------

  /// Makes `f` this station's published frame and shows a sign of life.
  /// Called with mtx_ held.
  void publish(const tx_frame& f) {
    auto& me = bus_->slots[cfg_.node];
    auto word = uint64_t{1} << 32 | f.key;
    me.heartbeat.store(now_ns());
    if (published_ != word || published_ready_ != f.enqueued_at) {
      me.ready_at.store(f.enqueued_at);
      me.pending.store(word);
      published_ = word;
      published_ready_ = f.enqueued_at;
    }
  }

  void unpublish() {
    bus_->slots[cfg_.node].pending.store(0);
    published_ = 0;
  }

  /// Decides the arbitration `mine` takes part in, with the bus idle since
  /// `busy` (<= now). The arbitration happens at `point`: the first moment
  /// at which the bus was idle and some frame was ready, i.e. max(busy,
  /// earliest ready time of all published frames). Every frame ready by then
  /// competes and the lowest key wins. True when that is `mine`; false when
  /// another live station wins (or `mine` was not ready yet at `point`): it
  /// is about to take the bus. Published frames of stations without a
  /// heartbeat for stale_ns (dead or stopped processes) do not count.
  bool wins_arbitration(const tx_frame& mine, int64_t busy, int64_t now,
                        int64_t& point) const {
    struct rival {
      uint32_t key;
      int64_t ready;
    };
    rival rivals[bus_slots];
    size_t count = 0;
    auto earliest = mine.enqueued_at;
    for (size_t n = 1; n < bus_slots - 1; ++n) {
      if (n == cfg_.node)
        continue;
      auto& slot = bus_->slots[n];
      auto word = slot.pending.load();
      if (word == 0)
        continue;
      auto ready = slot.ready_at.load();
      if (now - slot.heartbeat.load() > stale_ns)
        continue;
      rivals[count++] = {static_cast<uint32_t>(word), ready};
      earliest = std::min(earliest, ready);
    }
    point = std::max(busy, earliest);
    if (mine.enqueued_at > point)
      return false;
    for (size_t i = 0; i < count; ++i)
      if (rivals[i].ready <= point && rivals[i].key < mine.key)
        return false;
    return true;
  }

  // Arbitration, one frame at a time:
  //  1. The lowest queued frame is published in our slot with its ready
  //     time (send() does that before it returns).
  //  2. While the bus is busy, sleep until it is idle.
  //  3. Decide the arbitration (wins_arbitration): the frames ready when the
  //     bus first was idle with something to send compete; the lowest key
  //     wins. A loser naps briefly and goes to 2 (the winner will have taken
  //     the bus).
  //  4. The winner's transmission starts at that arbitration point, or at
  //     now - max_credit_ns if the thread woke later than that: frames
  //     queued back to back leave no gaps despite wake-up latency, and a
  //     stalled process cannot release an unbounded burst.
  //  5. Take the bus with compare_exchange(busy_until: idle -> start +
  //     frame time). Only one station succeeds per idle period, and busy
  //     periods never overlap, so the bus never carries more than its bit
  //     rate. A station that lost the exchange goes to 2.
  //  6. Send the frame to every other station, to be delivered when the
  //     transmission ends.
  void transmit_loop() {
    ::prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0); // precise wake-ups
    std::vector<uint8_t> buf(can::wire::header_size + CANFD_MTU);
    std::uniform_real_distribution<double> coin{0.0, 1.0};
    auto& busy_until = bus_->busy_until;
    std::unique_lock<std::mutex> lk{mtx_};
    for (;;) {
      tx_idle_ = true;
      tx_cv_.wait(lk, [this] { return stopping_ || !queue_.empty(); });
      tx_idle_ = false;
      if (stopping_)
        break;
      auto& head = queue_.front();
      publish(head);
      auto now = now_ns();
      auto busy = busy_until.load();
      if (busy > now) {
        tx_cv_.wait_until(lk, to_time_point(
                                std::min(busy, now + heartbeat_period_ns)));
        continue;
      }
      int64_t point = 0;
      if (!wins_arbitration(head, busy, now, point)) {
        ++arbitration_lost_;
        tx_cv_.wait_until(lk, to_time_point(now + backoff_ns));
        continue;
      }
      auto start = std::max(point, now - max_credit_ns);
      auto error_rate = error_rate_.load();
      bool destroyed = error_rate > 0 && coin(rng_) < error_rate;
      auto bits = head.bits + (destroyed ? error_frame_bits : 0);
      auto end = start + can::bits_time_ns(bits, cfg_.bitrate);
      if (!busy_until.compare_exchange_strong(busy, end))
        continue; // somebody else took the bus first
      tx_frame f = head;
      if (!destroyed) {
        std::pop_heap(queue_.begin(), queue_.end(), later);
        queue_.pop_back();
        if (queue_.empty())
          unpublish();
        else
          publish(queue_.front());
      }
      lk.unlock();
      if (destroyed)
        ++tx_errors_;
      else
        ++tx_frames_;
      if (!failed_.load() && !fan_out(f, end, destroyed, buf)) {
        lk.lock();
        break;
      }
      lk.lock();
    }
    unpublish();
  }

  /// Sends one frame (or, when `destroyed`, an error frame) to the stations
  /// on the bus. False after a fatal error.
  bool fan_out(const tx_frame& f, int64_t end, bool destroyed,
               std::vector<uint8_t>& buf) {
    can::wire::header hdr;
    hdr.flags = destroyed ? can::wire::flag_error : 0;
    hdr.deliver_at_ns = end;
    can::wire::encode(hdr, buf.data());
    std::memcpy(buf.data() + can::wire::header_size, &f.frame, f.wire_size);
    auto size = can::wire::header_size + f.wire_size;
    refresh_peers();
    std::uniform_real_distribution<double> coin{0.0, 1.0};
    auto loss = loss_.load();
    for (size_t i = 0; i < peers_.size();) {
      auto peer = peers_[i];
      // Every station hears an error frame, the sender included; a data
      // frame goes to every other station (as with CAN_RAW_RECV_OWN_MSGS
      // off). Loss drops a frame for one receiver (not what CAN does, but
      // what the upper layers must survive).
      if ((peer == cfg_.node && !destroyed)
          || (!destroyed && loss > 0 && coin(rng_) < loss)) {
        if (peer != cfg_.node)
          ++tx_lost_;
        ++i;
        continue;
      }
      switch (send_datagram(peer, buf.data(), size)) {
        case send_result::ok:
          ++i;
          break;
        case send_result::gone:
          peers_.erase(peers_.begin() + static_cast<ptrdiff_t>(i));
          break;
        case send_result::fatal:
          return false;
      }
    }
    return true;
  }

  enum class send_result { ok, gone, fatal };

  send_result send_datagram(uint64_t dst, const uint8_t* data, size_t size) {
    auto& addr = peer_addrs_[dst];
    // A receiver that overran once gets no grace period until it takes a
    // frame again: a stuck station must not stall the whole bus.
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
          ++tx_overruns_; // the receiver lost this frame
          congested_[dst] = true;
          return send_result::ok;
        case ENOENT:
        case ECONNREFUSED:
        case ENOTDIR:
          return send_result::gone;
        case EACCES:
        case EPERM:
          return send_result::ok; // somebody else's socket
        default:
          report_tx_failure(fail(ec::device_failed,
                                 "cannot send on emulated CAN bus "
                                   + cfg_.interface + ": " + errno_text(err)));
          return send_result::fatal;
      }
    }
  }

  /// Rescans the stations when one joined or left, or every
  /// rescan_period_ns (stations of crashed processes).
  void refresh_peers() {
    auto gen = bus_->generation.load();
    auto now = now_ns();
    if (peers_valid_ && gen == peers_generation_
        && now - peers_scanned_at_ < rescan_period_ns)
      return;
    peers_ = list_stations_in(cfg_.interface);
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
    pthread_setname_np(pthread_self(), "herm-can-emu");
    std::vector<uint8_t> buf(can::wire::header_size + CANFD_MTU);
    auto next_check = now_ns() + liveness_period_ns;
    for (;;) {
      if (stopped_rx_.load())
        return;
      auto now = now_ns();
      deliver_due(now);
      if (stopped_rx_.load())
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
                            "cannot poll emulated CAN socket " + sock_path_
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
                            "cannot receive on emulated CAN socket "
                              + sock_path_ + ": " + errno_text(err)));
        return false;
      }
      auto size = static_cast<size_t>(n); // the real size (MSG_TRUNC)
      auto now = now_ns();
      can::wire::header hdr;
      auto st = can::wire::check(buf.data(), size, now, hdr);
      if (st != can::wire::status::ok) {
        malformed(*handler_, 0,
                  std::string{"emulated bus: "} + can::wire::to_string(st)
                    + " (" + std::to_string(size) + "-byte datagram)");
        if (stopped_rx_.load())
          return true;
        continue;
      }
      held_frame h;
      h.size = size - can::wire::header_size;
      std::memset(&h.frame, 0, sizeof(h.frame));
      std::memcpy(&h.frame, buf.data() + can::wire::header_size, h.size);
      h.error = (hdr.flags & can::wire::flag_error) != 0;
      h.deliver_at = hdr.deliver_at_ns;
      h.seq = rx_seq_++;
      if (held_.empty() && h.deliver_at <= now) {
        deliver(h);
        if (stopped_rx_.load())
          return true;
        continue;
      }
      if (held_.size() >= max_held_frames) {
        deliver_front(); // overloaded: hand the earliest up early
        if (stopped_rx_.load())
          return true;
      }
      held_.push_back(h);
      std::push_heap(held_.begin(), held_.end(), held_later);
    }
    return true;
  }

  void deliver_due(int64_t now) {
    while (!held_.empty() && held_.front().deliver_at <= now
           && !stopped_rx_.load())
      deliver_front();
  }

  void deliver_front() {
    std::pop_heap(held_.begin(), held_.end(), held_later);
    auto h = held_.back();
    held_.pop_back();
    deliver(h);
  }

  void deliver(const held_frame& h) {
    if (h.error) {
      // The frame was destroyed on the bus: what arrives is the error.
      canfd_frame err{};
      err.can_id = CAN_ERR_FLAG | CAN_ERR_PROT;
      err.len = CAN_ERR_DLC;
      error_frame(*handler_, err);
      return;
    }
    dispatch(*handler_, h.frame, h.size);
  }

  /// Non-null when our socket file or the bus file is gone or replaced.
  caf::error check_files() const {
    struct stat st;
    auto check = [&](const std::string& path, dev_t dev,
                     ino_t ino) -> caf::error {
      if (::stat(path.c_str(), &st) == 0) {
        if (st.st_dev == dev && st.st_ino == ino)
          return caf::none;
        return fail(ec::device_failed,
                    "emulated CAN bus file " + path + " was replaced");
      }
      auto err = errno;
      if (err == ENOENT || err == ENOTDIR)
        return fail(ec::device_failed,
                    "emulated CAN bus file " + path + " was removed");
      return fail(ec::device_failed, "cannot check emulated CAN bus file "
                                        + path + ": " + errno_text(err));
    };
    if (auto err = check(sock_path_, sock_dev_, sock_ino_))
      return err;
    return check(bus_path_, bus_dev_, bus_ino_);
  }

  caf::error take_tx_failure() {
    std::lock_guard<std::mutex> guard{failure_mtx_};
    return std::exchange(tx_failure_, caf::error{});
  }

  /// Reports a fatal error once; the receive thread ends right after.
  void report_failure(caf::error err) {
    failed_.store(true);
    if (!stopped_rx_.load())
      handler_->on_failure(std::move(err));
  }

  // -- state ---------------------------------------------------------------------

  const std::string bus_path_;
  std::string sock_path_;
  bus_layout* bus_ = nullptr;
  dev_t bus_dev_ = 0;
  ino_t bus_ino_ = 0;
  dev_t sock_dev_ = 0;
  ino_t sock_ino_ = 0;
  unique_fd rx_fd_;
  unique_fd tx_fd_;
  unique_fd wake_fd_;

  std::atomic<double> loss_;
  std::atomic<double> error_rate_;

  // Lifecycle.
  std::mutex life_mtx_;
  bool stopped_ = false;
  bool detached_ = false;
  std::atomic<bool> failed_{false};
  std::atomic<bool> stopped_rx_{false};
  std::shared_ptr<frame_handler> handler_;
  std::thread tx_thread_;
  std::thread rx_thread_;

  // Transmit queue (a heap, see `later`) and our slot, guarded by mtx_.
  std::mutex mtx_;
  std::condition_variable tx_cv_;
  std::vector<tx_frame> queue_;
  uint64_t next_seq_ = 0;
  uint64_t published_ = 0;
  int64_t published_ready_ = 0;
  bool stopping_ = false;
  bool tx_idle_ = false;

  // Transmit thread only.
  std::mt19937_64 rng_;
  sockaddr_un peer_addrs_[255] = {};
  bool congested_[255] = {};
  std::vector<uint64_t> peers_;
  bool peers_valid_ = false;
  uint32_t peers_generation_ = 0;
  int64_t peers_scanned_at_ = 0;

  // Failure handed from the transmit thread to the receive thread.
  std::mutex failure_mtx_;
  caf::error tx_failure_;

  // Receive thread only.
  std::vector<held_frame> held_;
  uint64_t rx_seq_ = 0;

  // Counters (get_param).
  std::atomic<uint64_t> tx_lost_{0};
  std::atomic<uint64_t> tx_overruns_{0};
  std::atomic<uint64_t> tx_errors_{0};
  std::atomic<uint64_t> arbitration_lost_{0};
};

// -- the link kind ---------------------------------------------------------------

caf::expected<link_driver_ptr> open_can(const device_config& cfg) {
  auto conf = read_config(cfg);
  if (!conf)
    return conf.error();
  if (conf->kind == backend::socketcan) {
    auto driver = std::make_shared<socketcan_driver>(std::move(*conf));
    if (auto err = driver->open())
      return err;
    return link_driver_ptr{std::move(driver)};
  }
  auto driver = std::make_shared<emu_can_driver>(std::move(*conf));
  if (auto err = driver->open())
    return err;
  if (auto err = driver->start_transmitter())
    return err;
  return link_driver_ptr{std::move(driver)};
}

} // namespace

const link_kind& can_link_kind() {
  static const link_kind kind{
    "can",
    "CAN 2.0B / CAN FD bus: SocketCAN interface (can0, vcan0) or an emulated "
    "bus between processes (emu:/path) with arbitration and bit-rate pacing",
    open_can};
  return kind;
}

} // namespace herm
