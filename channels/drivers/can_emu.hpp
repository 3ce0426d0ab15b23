#pragma once

// The emulated CAN bus, the second backend of link kind "can" (interface
// "emu:/path/to/bus-directory"); see channels/drivers/can_emu.cpp.

#include "channels/drivers/can_common.hpp"
#include "channels/link_driver.hpp"

namespace herm::can {

/// Joins the emulated bus in `cfg.interface` (a directory, created unless
/// cfg.create is false) as node cfg.node (it transmits on the event loop given to start()).
/// Errors: ec::device_unavailable (directory, bus file, bit rate of the
/// stations already on the bus, sockets, threads), ec::already_exists (the
/// node id is taken), naming the device and the paths.
caf::expected<link_driver_ptr> open_emulated_bus(can_config cfg);

} // namespace herm::can
