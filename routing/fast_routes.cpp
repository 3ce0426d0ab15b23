#include "routing/fast_routes.hpp"

#include "channels/thread_cache.hpp"
#include "routing/type_ids.hpp"
#include "routing/wire.hpp"

namespace herm {

bool fast_receiver::take(channel_id, link_addr, byte_buffer& packet) {
  auto snap = cell_->get();
  if (snap == nullptr || snap->receivers.empty())
    return false;
  auto type = peek_type(packet.data(), packet.size());
  if (!type || *type != packet_type::data)
    return false;
  auto h = decode_data_header(packet.data(), packet.size());
  // Broadcasts (duplicate suppression, relaying), packets for others
  // (forwarding) and signed ones (which a keyless module refuses) are the
  // agent's; so is a header that does not decode (counted there).
  if (!h || h->dst != snap->self || h->authenticated)
    return false;
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
