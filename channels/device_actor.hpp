#pragma once

// Typed interface of a device actor: one per physical interface, owning its
// driver and shared by every channel on it (the paper's flyweight).

#include <memory>

#include "caf/fwd.hpp"
#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "channels/atoms.hpp"
#include "channels/channel_actor.hpp"
#include "channels/messages.hpp"
#include "channels/packet_tap.hpp"

namespace herm {

class link_driver;

/// What a device says about itself.
struct device_info {
  device_config config;
  link_profile profile;
  std::string local;
  uint32_t channels = 0;
  /// Frames that arrived for no channel (no matching peer, no "*" channel).
  uint64_t unclaimed_frames = 0;
  /// Frames the driver refused before decoding (oversized, bad medium header).
  uint64_t malformed_frames = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, device_info& x) {
  return f(caf::meta::type_name("device_info"), x.config, x.profile, x.local,
           x.channels, x.unclaimed_frames, x.malformed_frames);
}

using device_actor = caf::typed_actor<
  /// Creates a channel on this device for `request.address` with the given
  /// channel id. Errors: ec::invalid_address, ec::already_exists.
  caf::replies_to<atom::open, channel_request, channel_id>::with<channel_actor,
                                                                 channel_info>,
  caf::replies_to<atom::get, atom::info>::with<device_info>,
  /// The driver failed: every channel ends with that reason, then the device.
  caf::reacts_to<device_failed>,
  caf::reacts_to<atom::close>>;

/// Opens `cfg` with its link kind and spawns the device actor owning the
/// driver. Errors: ec::unknown_link_kind, or the kind's own open error.
/// Its channels show their packets to `tap` first (channels/packet_tap.hpp).
caf::expected<device_actor> spawn_device(caf::actor_system& sys,
                                         const device_config& cfg,
                                         packet_tap_ptr tap = nullptr);

} // namespace herm
