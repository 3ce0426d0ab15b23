#pragma once

// The Application Support Layer's type-ID block, the last of HERM's three
// (docs/architecture.md, "Type IDs and errors"). It starts where the
// Network Adaptation Layer's block ends; including this header gives all
// three. An application's own block starts at `caf::id_block::herm::end`,
// the end of HERM's IDs.
// CAF_ENABLE_TYPE_ID_CHECKS is on, so a missing entry is a compile error.
// Append new entries at the end only: IDs are assigned in order, and the
// next layer's block starts where this one ends.

#include <vector>

#include "actors/app_support.hpp"
#include "routing/type_ids.hpp"

CAF_BEGIN_TYPE_ID_BLOCK(herm_asl, caf::id_block::herm_routing::end)

  CAF_ADD_TYPE_ID(herm_asl, (herm::apo_ref))
  CAF_ADD_TYPE_ID(herm_asl, (std::vector<herm::apo_ref>))
  CAF_ADD_TYPE_ID(herm_asl, (herm::apo_query))
  CAF_ADD_TYPE_ID(herm_asl, (herm::bind_request))
  CAF_ADD_TYPE_ID(herm_asl, (herm::apo_info))
  CAF_ADD_TYPE_ID(herm_asl, (std::vector<herm::apo_info>))
  CAF_ADD_TYPE_ID(herm_asl, (herm::app_support_stats))
  CAF_ADD_TYPE_ID(herm_asl, (herm::app_support_actor))
  CAF_ADD_TYPE_ID(herm_asl, (herm::apo_access))
  CAF_ADD_TYPE_ID(herm_asl, (herm::raw_payload))
  CAF_ADD_TYPE_ID(herm_asl, (herm::topic_sample))
  CAF_ADD_TYPE_ID(herm_asl, (herm::topic_info))
  CAF_ADD_TYPE_ID(herm_asl, (std::vector<herm::topic_info>))

CAF_END_TYPE_ID_BLOCK(herm_asl)

namespace caf::id_block {

/// All of HERM's type IDs end where the last block ends: applications chain
/// their own blocks from `caf::id_block::herm::end`. herm::configure
/// registers the three blocks; do not pass this alias to add_message_types.
using herm = herm_asl;

} // namespace caf::id_block
