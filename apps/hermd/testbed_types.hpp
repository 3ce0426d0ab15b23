#pragma once

// Message types of the APOs hermd ships (apps/hermd/apo_kinds.cpp): the
// paper's testbed scenario. Their type-ID block follows HERM's; every
// module that talks to these APOs registers it (herm::hermd::add_apo_types).

#include <cstdint>
#include <string>
#include <vector>

#include "caf/type_id.hpp"

#include "actors/runtime/type_ids.hpp"
#include "apps/hermd/srf04.hpp"

namespace herm::hermd {

/// Ten (or `batch`) SRF04 readings collected by a sensor module.
struct sonar_batch {
  std::string source;
  uint32_t batch = 0;
  /// Sequence number (from the AVR board) of the first reading.
  uint32_t first_seq = 0;
  std::vector<uint16_t> distances_mm;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, sonar_batch& x) {
  return f(caf::meta::type_name("herm.sonar_batch"), x.source, x.batch,
           x.first_seq, x.distances_mm);
}

/// A vision module's periodic data (the paper assumes 100 bytes).
struct vision_frame {
  std::string source;
  uint32_t seq = 0;
  std::vector<uint8_t> data;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, vision_frame& x) {
  return f(caf::meta::type_name("herm.vision_frame"), x.source, x.seq, x.data);
}

} // namespace herm::hermd

CAF_BEGIN_TYPE_ID_BLOCK(herm_apos, caf::id_block::herm::end)
  CAF_ADD_TYPE_ID(herm_apos, (herm::hermd::sonar_batch))
  CAF_ADD_TYPE_ID(herm_apos, (herm::hermd::vision_frame))
  CAF_ADD_TYPE_ID(herm_apos, (herm::hermd::srf04_reading))
CAF_END_TYPE_ID_BLOCK(herm_apos)
