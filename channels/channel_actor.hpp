#pragma once

// Typed interfaces of a channel and of its readers. No implementation here.

#include <string>

#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "channels/atoms.hpp"
#include "channels/messages.hpp"

namespace herm {

/// Whoever reads from a channel (the routing agent, a test, an APO) speaks
/// this interface. Readers monitor the channel to learn when it ends.
using channel_reader_actor
  = caf::typed_actor<caf::reacts_to<packet_received>, caf::reacts_to<link_event>>;

/// A logical channel on one link: the paper's open (via the IO manager),
/// control (get/set), read (subscribe), write and close.
///
/// A channel ends with a reason when its device fails; its readers and the IO
/// manager receive a down message.
using channel_actor = caf::typed_actor<
  // -- write: one packet, fragmented when above the MTU; failures counted ---
  caf::reacts_to<write_packet>,
  // -- read: received packets and link events go to every subscriber -------
  caf::replies_to<atom::subscribe, channel_reader_actor>::with<channel_info>,
  caf::reacts_to<atom::unsubscribe, channel_reader_actor>,
  // -- control ---------------------------------------------------------------
  caf::replies_to<atom::get, atom::info>::with<channel_info>,
  caf::replies_to<atom::get, atom::stats>::with<channel_stats>,
  caf::replies_to<atom::get, std::string>::with<std::string>,
  caf::replies_to<atom::set, std::string, std::string>::with<channel_info>,
  // -- close -----------------------------------------------------------------
  caf::reacts_to<atom::close>,
  // -- from the device's driver and the channel's own timer ------------------
  caf::reacts_to<frame_received>,
  caf::reacts_to<link_event>,
  caf::reacts_to<atom::tick>>;

} // namespace herm
