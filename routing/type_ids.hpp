#pragma once

// The Network Adaptation Layer's type-ID block, the second of HERM's three
// (docs/architecture.md, "Type IDs and errors"). It starts where the
// Network Interface Layer's block ends.
// CAF_ENABLE_TYPE_ID_CHECKS is on, so a missing entry is a compile error.
// Append new entries at the end only: IDs are assigned in order, and the
// next layer's block starts where this one ends.

#include <vector>

#include "channels/type_ids.hpp"
#include "routing/routing_agent.hpp"

CAF_BEGIN_TYPE_ID_BLOCK(herm_routing, caf::id_block::herm_channels::end)

  CAF_ADD_TYPE_ID(herm_routing, (herm::send_packet))
  CAF_ADD_TYPE_ID(herm_routing, (herm::packet_delivered))
  CAF_ADD_TYPE_ID(herm_routing, (herm::neighbour_info))
  CAF_ADD_TYPE_ID(herm_routing, (std::vector<herm::neighbour_info>))
  CAF_ADD_TYPE_ID(herm_routing, (herm::route_info))
  CAF_ADD_TYPE_ID(herm_routing, (std::vector<herm::route_info>))
  CAF_ADD_TYPE_ID(herm_routing, (herm::routing_stats))
  CAF_ADD_TYPE_ID(herm_routing, (herm::network_receiver_actor))
  CAF_ADD_TYPE_ID(herm_routing, (herm::routing_agent_actor))
  CAF_ADD_TYPE_ID(herm_routing, (herm::reachability))
  CAF_ADD_TYPE_ID(herm_routing, (herm::route_listener_actor))

CAF_END_TYPE_ID_BLOCK(herm_routing)
