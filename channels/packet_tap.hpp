#pragma once

// A shorter way in for received packets (docs/architecture.md, "Threads"):
// a channel shows each packet it reassembled to the tap of its IO manager
// before it sends it to its reader, and the tap may deliver it itself. The
// routing agent's fast path (routing/fast_routes.hpp, fast_receiver) is one:
// a data packet for one of its module's own receivers goes from the channel
// straight to that receiver's mailbox, and one for another module straight
// to the channel of its next hop, without a turn through the agent.

#include <memory>

#include "channels/messages.hpp"

namespace herm {

class packet_tap {
public:
  virtual ~packet_tap();

  /// Called on the channel's thread for each packet it received, while the
  /// channel has exactly one reader (so no other reader misses what the
  /// tap takes). Returns true when it delivered `packet` (then it may have
  /// moved from it), false to leave it to the reader. Thread-safe: every
  /// channel of the IO manager calls it. Must not block.
  virtual bool take(channel_id ch, link_addr src, byte_buffer& packet) = 0;
};

using packet_tap_ptr = std::shared_ptr<packet_tap>;

} // namespace herm
