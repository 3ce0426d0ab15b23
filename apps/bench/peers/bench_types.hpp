#pragma once

// The benchmark's own type-ID block, after HERM's: the byte-vector payload
// of herm and caf requests. Both ends register it, so the type's name
// ("std::vector<uint8_t>") identifies it on the wire.

#include <cstdint>
#include <vector>

#include "caf/type_id.hpp"

#include "actors/runtime/type_ids.hpp"

CAF_BEGIN_TYPE_ID_BLOCK(herm_bench, caf::id_block::herm::end)
  CAF_ADD_TYPE_ID(herm_bench, (std::vector<uint8_t>))
CAF_END_TYPE_ID_BLOCK(herm_bench)
