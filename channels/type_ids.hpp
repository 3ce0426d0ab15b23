#pragma once

// The Network Interface Layer's type-ID block, the first of HERM's three
// (docs/architecture.md, "Type IDs and errors"): every type its actors
// exchange. It starts at CAF's first custom ID.
// CAF_ENABLE_TYPE_ID_CHECKS is on, so a missing entry is a compile error.
// Append new entries at the end only: IDs are assigned in order, and the
// next layer's block starts where this one ends.

#include <vector>

#include "caf/type_id.hpp"

#include "channels/channel_actor.hpp"
#include "channels/device_actor.hpp"
#include "channels/io_manager.hpp"
#include "channels/messages.hpp"

CAF_BEGIN_TYPE_ID_BLOCK(herm_channels, caf::first_custom_type_id)

  CAF_ADD_TYPE_ID(herm_channels, (herm::write_packet))
  CAF_ADD_TYPE_ID(herm_channels, (herm::packet_received))
  CAF_ADD_TYPE_ID(herm_channels, (herm::link_event))
  CAF_ADD_TYPE_ID(herm_channels, (herm::frame_received))
  CAF_ADD_TYPE_ID(herm_channels, (herm::device_failed))
  CAF_ADD_TYPE_ID(herm_channels, (herm::device_config))
  CAF_ADD_TYPE_ID(herm_channels, (herm::device_info))
  CAF_ADD_TYPE_ID(herm_channels, (std::vector<herm::device_info>))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_request))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_info))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_stats))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_entry))
  CAF_ADD_TYPE_ID(herm_channels, (std::vector<herm::channel_entry>))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_up))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_down))
  CAF_ADD_TYPE_ID(herm_channels, (herm::link_profile))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_reader_actor))
  CAF_ADD_TYPE_ID(herm_channels, (herm::channel_actor))
  CAF_ADD_TYPE_ID(herm_channels, (herm::device_actor))
  CAF_ADD_TYPE_ID(herm_channels, (herm::io_listener_actor))
  CAF_ADD_TYPE_ID(herm_channels, (herm::io_manager_actor))

CAF_END_TYPE_ID_BLOCK(herm_channels)
