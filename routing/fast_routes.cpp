#include "routing/fast_routes.hpp"

#include "channels/thread_cache.hpp"
#include "routing/type_ids.hpp"
#include "routing/wire.hpp"

namespace herm {

namespace {

/// Puts the data packet `packet` (header `h`) for another module on the
/// next hop `snap` publishes for it, as the agent's forward does; false
/// when the agent must (no hop published, or its hop limit ends here:
/// the agent counts the drop).
bool forward(route_cell& cell, const route_snapshot& snap,
             const data_header& h, byte_buffer& packet) {
  if (h.hop_limit <= 1)
    return false;
  auto* hop = snap.lookup(h.dst, h.size_class);
  if (hop == nullptr || !hop->channel)
    return false;
  set_hop_limit(packet.data(), static_cast<uint8_t>(h.hop_limit - 1));
  pooled_anon_send(hop->channel,
                   write_packet{hop->neighbour, h.priority, std::move(packet)});
  cell.count_forwarded();
  return true;
}

} // namespace

bool fast_receiver::take(channel_id, link_addr, byte_buffer& packet) {
  auto snap = cell_->get();
  if (snap == nullptr)
    return false;
  auto type = peek_type(packet.data(), packet.size());
  if (!type || *type != packet_type::data)
    return false;
  auto h = decode_data_header(packet.data(), packet.size());
  // Broadcasts (duplicate suppression, relaying) and signed packets (which
  // a keyless module refuses) are the agent's; so is a header that does
  // not decode (counted there).
  if (!h || h->dst == broadcast_module || h->authenticated)
    return false;
  if (h->dst != snap->self)
    return forward(*cell_, *snap, *h, packet);
  auto i = snap->receivers.find(h->protocol);
  if (i == snap->receivers.end())
    return false;
  // As the agent counts them (routing_agent.cpp, deliver).
  uint8_t hops = h->src == snap->self
                   ? 0
                   : static_cast<uint8_t>(default_hop_limit - h->hop_limit + 1);
  packet_delivered msg{h->src, h->protocol, h->priority, hops, {}, false};
  packet.erase(packet.begin(),
               packet.begin() + static_cast<ptrdiff_t>(header_size(*h)));
  msg.payload = std::move(packet);
  pooled_anon_send(i->second, std::move(msg));
  cell_->count_delivered();
  return true;
}

} // namespace herm
