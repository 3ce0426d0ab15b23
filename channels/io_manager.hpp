#pragma once

// Typed interface of the IO manager: keeps the devices and the Channel Table,
// creates channels on request (the paper's Fig. 4), supervises them and
// re-creates persistent ones with backoff when their device returns.

#include <vector>

#include "caf/fwd.hpp"
#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "channels/atoms.hpp"
#include "channels/channel_actor.hpp"
#include "channels/device_actor.hpp"
#include "channels/messages.hpp"
#include "channels/packet_tap.hpp"

namespace herm {

/// A channel came up (also after being re-created).
struct channel_up {
  channel_info info;
  channel_actor handle;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, channel_up& x) {
  return f(caf::meta::type_name("channel_up"), x.info, x.handle);
}

/// A channel ended. `will_retry` tells whether the IO manager re-creates it.
struct channel_down {
  channel_id id = 0;
  caf::error reason;
  bool will_retry = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, channel_down& x) {
  return f(caf::meta::type_name("channel_down"), x.id, x.reason, x.will_retry);
}

/// One row of the Channel Table.
struct channel_entry {
  channel_id id = 0;
  channel_request request;
  /// "up", "retrying" or "closed".
  std::string state;
  /// Last failure, rendered; empty while up.
  std::string last_error;
  uint32_t restarts = 0;
  channel_info info;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, channel_entry& x) {
  return f(caf::meta::type_name("channel_entry"), x.id, x.request, x.state,
           x.last_error, x.restarts, x.info);
}

/// Learns about channels coming and going (the routing agent).
using io_listener_actor
  = caf::typed_actor<caf::reacts_to<channel_up>, caf::reacts_to<channel_down>>;

/// Backoff for re-creating persistent channels: first, doubled up to max.
struct backoff_policy {
  caf::timespan first = std::chrono::milliseconds(100);
  caf::timespan max = std::chrono::seconds(5);
};

using io_manager_actor = caf::typed_actor<
  /// Registers a device (opens its driver now). Errors name the device.
  caf::replies_to<atom::add, device_config>::with<device_info>,
  /// Creates a channel (the paper's open). For a persistent request whose
  /// device cannot be opened now, the error is returned and the IO manager
  /// keeps retrying in the background.
  caf::replies_to<atom::open, channel_request>::with<channel_actor,
                                                     channel_info>,
  caf::replies_to<atom::close, channel_id>::with<void>,
  /// Removes a device: closes its channels (not re-created) and its driver,
  /// and forgets its configuration, so that a device of that name can be
  /// added anew (hermd's reload). Errors: ec::unknown_device.
  caf::replies_to<atom::close, std::string>::with<void>,
  caf::replies_to<atom::get, atom::channels>::with<std::vector<channel_entry>>,
  caf::replies_to<atom::get, atom::devices>::with<std::vector<device_info>>,
  caf::replies_to<atom::get, channel_id>::with<channel_actor>,
  /// Tells `listener` about every channel up now and every change after.
  caf::reacts_to<atom::subscribe, io_listener_actor>,
  /// Timer: try to re-create channel `id`.
  caf::reacts_to<atom::retry, channel_id>>;

/// Spawns the IO manager. Device configs in `devices` are registered at
/// start; ones that fail to open are retried with backoff. Every channel
/// it opens shows its packets to `tap` first (channels/packet_tap.hpp).
io_manager_actor spawn_io_manager(caf::actor_system& sys,
                                  backoff_policy backoff = {},
                                  packet_tap_ptr tap = nullptr);

} // namespace herm
