#pragma once

#include <atomic>
#include <memory>

#include "caf/fwd.hpp"

#include "channels/channel_actor.hpp"
#include "channels/device_actor.hpp"
#include "channels/fragmentation.hpp"
#include "channels/link_driver.hpp"

namespace herm {

/// Counters a device shares with its channels (updated from driver threads).
struct device_counters {
  std::atomic<uint64_t> unclaimed{0};
  std::atomic<uint64_t> malformed{0};
};

/// Everything a device hands a new channel.
struct channel_setup {
  channel_info info;
  link_driver_ptr driver;
  std::shared_ptr<device_counters> counters;
  /// The peer of a point-to-point channel; broadcast_addr for "*".
  link_addr peer = broadcast_addr;
  reassembly_limits limits;
  /// The device, monitored: the channel ends with it.
  device_actor device;
};

/// Spawns a channel actor. Used by device actors only; clients open channels
/// through the IO manager.
channel_actor spawn_channel(caf::actor_system& sys, channel_setup setup);

} // namespace herm
