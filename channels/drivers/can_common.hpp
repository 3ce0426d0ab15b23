#pragma once

// What the two backends of link kind "can" share (channels/drivers/can.cpp,
// SocketCAN; channels/drivers/can_emu.cpp, the emulated bus): the options,
// the link profile, how a send() request becomes a CAN frame and how a frame
// read from the medium reaches the frame_handler. The frame format is in
// channels/drivers/can_id.hpp and docs/protocol.md.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>

#include <linux/can.h>

#include "channels/drivers/can_id.hpp"
#include "channels/drivers/params.hpp"
#include "channels/error.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"

namespace herm::can {

/// Interface prefix of the emulated bus: "emu:/path/to/bus-directory".
constexpr const char* emu_scheme = "emu:";

enum class backend { socketcan, emu };

/// The options of a can device (docs/user-guide.md).
struct can_config {
  std::string name;
  /// The network interface (SocketCAN) or the bus directory (emulated,
  /// without the scheme and trailing '/').
  std::string interface;
  backend kind = backend::socketcan;
  id_format format = id_format::ext29;
  uint8_t node = 0;
  bool fd = false;
  /// bit/s.
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

/// Reads and checks a can device's options; the backend follows from the
/// interface. Errors: ec::invalid_address (interface), ec::invalid_parameter
/// (options), naming the device.
caf::expected<can_config> read_config(const device_config& cfg);

/// "0x1F".
std::string hex(uint32_t x);

/// The part of a can driver both backends share: profile, addressing,
/// frame building and dispatch, common counters. Counters are atomics;
/// dispatch and the handler calls run where the backend receives (the
/// event loop's thread).
class can_driver : public link_driver {
public:
  explicit can_driver(can_config cfg);

  const link_profile& profile() const override {
    return profile_;
  }

  link_addr local_addr() const override {
    return cfg_.node;
  }

  /// can::lane_of the identifier a frame to `dst` with `priority` gets.
  uint8_t lane(link_addr dst, uint8_t priority) const override;

  std::string format_addr(link_addr addr) const override {
    if (addr == broadcast_addr)
      return "*";
    return std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override;

  caf::expected<std::string> get_param(const std::string& key) const override;

protected:
  caf::error fail(ec code, const std::string& what) const {
    return make_error(code, prefix_ + what);
  }

  /// Checks a send() request and builds its frame in `out` (zeroed first).
  /// Returns the bytes to hand to the medium: CAN_MTU or CANFD_MTU.
  caf::expected<size_t> build(link_addr dst, const uint8_t* data, size_t size,
                              uint8_t priority, canfd_frame& out) const;

  /// Hands one frame read from the medium, `nbytes` long as read, to `h`:
  /// error frames become events, HERM frames for this node on_frame, frames
  /// for other nodes are filtered out, everything else is malformed.
  void dispatch(frame_handler& h, const canfd_frame& f, size_t nbytes);

  /// Counts and reports a malformed frame ("can: " + why).
  void malformed(frame_handler& h, link_addr src, const std::string& why);

  /// Maps an error frame (CAN_ERR_FLAG, classes in linux/can/error.h) to
  /// link events; stops between events once delivery_ended().
  void error_frame(frame_handler& h, const canfd_frame& f);

  /// Whether the driver was stopped (from a handler call, say), so that
  /// dispatch makes no further handler call. Default: never.
  virtual bool delivery_ended() const {
    return false;
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

} // namespace herm::can
