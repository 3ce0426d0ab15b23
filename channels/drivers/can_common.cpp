#include "channels/drivers/can_common.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>

#include <net/if.h>
#include <sys/un.h>

#include <linux/can/error.h>

#include "channels/drivers/medium_dir.hpp"

namespace herm::can {

std::string hex(uint32_t x) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%X", x);
  return buf;
}

// -- configuration ---------------------------------------------------------------

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
    auto longest = c.interface.size() + 1 + medium_dir::station_file(254).size();
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
  // A missing node is reported after the unknown options: a misspelled
  // "nod" says so rather than that "node" is missing.
  bool node_given = r.has("node");
  if (auto err = read_into(c.node, r.u64("node", 0, 1, max_node)))
    return err;
  if (auto err = read_into(c.fd, r.flag("fd", false)))
    return err;
  if (c.fd && c.format == can::id_format::std11)
    return r.fail(ec::invalid_parameter,
                  "option 'fd' needs id_format=29bit (11-bit identifiers "
                  "have no room for CAN FD padding)");
  if (auto err
      = read_into(c.bitrate, r.u64("bitrate", 1'000'000, 1'000, 10'000'000)))
    return err;
  if (auto err = read_into(c.stuffing, r.flag("stuffing", false)))
    return err;
  if (auto err
      = read_into(c.delay_coef, r.real("delay_coef", 1.0, 0.001, 1000.0)))
    return err;
  if (c.kind == backend::socketcan) {
    if (auto err = read_into(c.filter, r.flag("filter", true)))
      return err;
  } else {
    if (auto err = read_into(c.queue, r.u64("queue", 64, 1, 65'536)))
      return err;
    if (auto err = read_into(c.loss, r.real("loss", 0, 0, 1)))
      return err;
    if (auto err = read_into(c.error_rate, r.real("error_rate", 0, 0, 0.9)))
      return err;
    if (auto err = read_into(c.seed, r.u64("seed", 0, 0, UINT64_MAX)))
      return err;
    if (auto err = read_into(c.create, r.flag("create", true)))
      return err;
  }
  if (auto err = r.finish())
    return err;
  if (!node_given)
    return r.fail(ec::invalid_parameter,
                  "option 'node' is required: this module's node id on the "
                  "bus, 1.."
                    + std::to_string(max_node));
  return c;
}

// -- the common part of both backends --------------------------------------------

can_driver::can_driver(can_config cfg)
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

uint8_t can_driver::lane(link_addr dst, uint8_t priority) const {
  can::frame_id id;
  id.priority = std::min(priority, can::max_priority);
  id.dst = dst == broadcast_addr ? can::broadcast_node(cfg_.format) : 1;
  return can::lane_of(cfg_.format, id);
}

caf::expected<link_addr>
can_driver::parse_addr(const std::string& str) const {
  auto max = can::max_node(cfg_.format);
  auto n = medium_dir::parse_number(str, 1, max);
  if (n == 0)
    return fail(ec::invalid_address, "'" + str + "' is not a CAN node id (1.."
                                       + std::to_string(max) + ")");
  return n;
}

caf::expected<std::string>
can_driver::get_param(const std::string& key) const {
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
  static constexpr counter_param<can_driver> counters[] = {
    {"tx_frames", &can_driver::tx_frames_},
    {"rx_frames", &can_driver::rx_frames_},
    {"rx_malformed", &can_driver::rx_malformed_},
    {"rx_filtered", &can_driver::rx_filtered_},
    {"error_frames", &can_driver::error_frames_},
  };
  if (auto value = read_counter(*this, counters, key))
    return *value;
  return link_driver::get_param(key);
}

caf::expected<size_t> can_driver::build(link_addr dst, const uint8_t* data,
                                        size_t size, uint8_t priority,
                                        canfd_frame& out) const {
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

void can_driver::dispatch(frame_handler& h, const canfd_frame& f,
                          size_t nbytes) {
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

void can_driver::malformed(frame_handler& h, link_addr src,
                           const std::string& why) {
  ++rx_malformed_;
  auto text = "can: " + why;
  h.on_malformed(src, text.c_str());
}

void can_driver::error_frame(frame_handler& h, const canfd_frame& f) {
  ++error_frames_;
  auto cls = f.can_id & CAN_ERR_MASK;
  bool reported = false;
  if ((cls & CAN_ERR_BUSOFF) != 0) {
    h.on_event(link_event_kind::bus_off, 0,
               "controller of " + cfg_.interface + " is bus-off");
    reported = true;
  }
  if ((cls & CAN_ERR_RESTARTED) != 0 && !delivery_ended()) {
    h.on_event(link_event_kind::bus_recovered, 0,
               "controller of " + cfg_.interface + " restarted");
    reported = true;
  }
  if ((cls & CAN_ERR_CRTL) != 0 && !delivery_ended()) {
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
  if ((rest != 0 || !reported) && !delivery_ended())
    h.on_event(link_event_kind::error_frame, 0,
               "error frame on " + cfg_.interface + " (class "
                 + hex(cls) + ")");
}

} // namespace herm::can
