#pragma once

// HERM's one project-wide type-ID block. Every type that travels in a
// message between actors has an entry here; the build defines
// CAF_ENABLE_TYPE_ID_CHECKS, so a missing entry is a compile error.
// Append new entries at the end of their layer's section only: IDs are
// assigned in order.

#include <string>
#include <vector>

#include "caf/type_id.hpp"

#include "actors/app_support.hpp"
#include "channels/channel_actor.hpp"
#include "channels/device_actor.hpp"
#include "channels/io_manager.hpp"
#include "channels/messages.hpp"
#include "routing/routing_agent.hpp"

CAF_BEGIN_TYPE_ID_BLOCK(herm, caf::first_custom_type_id)

  // -- Network Interface Layer ---------------------------------------------------
  CAF_ADD_TYPE_ID(herm, (herm::write_packet))
  CAF_ADD_TYPE_ID(herm, (herm::packet_received))
  CAF_ADD_TYPE_ID(herm, (herm::link_event))
  CAF_ADD_TYPE_ID(herm, (herm::frame_received))
  CAF_ADD_TYPE_ID(herm, (herm::device_failed))
  CAF_ADD_TYPE_ID(herm, (herm::device_config))
  CAF_ADD_TYPE_ID(herm, (herm::device_info))
  CAF_ADD_TYPE_ID(herm, (std::vector<herm::device_info>))
  CAF_ADD_TYPE_ID(herm, (herm::channel_request))
  CAF_ADD_TYPE_ID(herm, (herm::channel_info))
  CAF_ADD_TYPE_ID(herm, (herm::channel_stats))
  CAF_ADD_TYPE_ID(herm, (herm::channel_entry))
  CAF_ADD_TYPE_ID(herm, (std::vector<herm::channel_entry>))
  CAF_ADD_TYPE_ID(herm, (herm::channel_up))
  CAF_ADD_TYPE_ID(herm, (herm::channel_down))
  CAF_ADD_TYPE_ID(herm, (herm::link_profile))
  CAF_ADD_TYPE_ID(herm, (herm::channel_reader_actor))
  CAF_ADD_TYPE_ID(herm, (herm::channel_actor))
  CAF_ADD_TYPE_ID(herm, (herm::device_actor))
  CAF_ADD_TYPE_ID(herm, (herm::io_listener_actor))
  CAF_ADD_TYPE_ID(herm, (herm::io_manager_actor))

  // -- Network Adaptation Layer ----------------------------------------------------
  CAF_ADD_TYPE_ID(herm, (herm::send_packet))
  CAF_ADD_TYPE_ID(herm, (herm::packet_delivered))
  CAF_ADD_TYPE_ID(herm, (herm::neighbour_info))
  CAF_ADD_TYPE_ID(herm, (std::vector<herm::neighbour_info>))
  CAF_ADD_TYPE_ID(herm, (herm::route_info))
  CAF_ADD_TYPE_ID(herm, (std::vector<herm::route_info>))
  CAF_ADD_TYPE_ID(herm, (herm::routing_stats))
  CAF_ADD_TYPE_ID(herm, (herm::network_receiver_actor))
  CAF_ADD_TYPE_ID(herm, (herm::routing_agent_actor))
  CAF_ADD_TYPE_ID(herm, (herm::reachability))
  CAF_ADD_TYPE_ID(herm, (herm::route_listener_actor))

  // -- Application Support Layer ---------------------------------------------------
  CAF_ADD_TYPE_ID(herm, (herm::apo_ref))
  CAF_ADD_TYPE_ID(herm, (std::vector<herm::apo_ref>))
  CAF_ADD_TYPE_ID(herm, (herm::apo_query))
  CAF_ADD_TYPE_ID(herm, (herm::bind_request))
  CAF_ADD_TYPE_ID(herm, (herm::apo_info))
  CAF_ADD_TYPE_ID(herm, (std::vector<herm::apo_info>))
  CAF_ADD_TYPE_ID(herm, (herm::app_support_stats))
  CAF_ADD_TYPE_ID(herm, (herm::app_support_actor))
  CAF_ADD_TYPE_ID(herm, (herm::apo_access))

CAF_END_TYPE_ID_BLOCK(herm)
