#pragma once

// An SRF04 ultrasonic reading. A board that is a HERM module of its own
// (the C client, apps/mcu) sends it to the sensor module's srf04_batcher as
// an APO payload (registered in testbed_types.hpp as
// herm::hermd::srf04_reading); a board on a local line sends the 8-byte
// record of docs/protocol.md, "SRF04 reading" (encode, decode_srf04).

#include <cstdint>
#include <string>
#include <vector>

#include "caf/expected.hpp"
#include "caf/meta/type_name.hpp"

#include "actors/runtime/error.hpp"

namespace herm::hermd {

struct srf04_reading {
  /// Counts readings, wrapping at 2^16.
  uint16_t seq = 0;
  /// Distance to the obstacle, mm.
  uint16_t distance_mm = 0;
  /// Echo pulse width, us (distance_mm * 2000 / 343).
  uint32_t echo_us = 0;
};

/// No echo within the sensor's range (an echo of 30 ms or more).
constexpr uint16_t srf04_out_of_range = 0xFFFF;

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, srf04_reading& x) {
  return f(caf::meta::type_name("herm.srf04_reading"), x.seq, x.distance_mm,
           x.echo_us);
}

inline std::vector<uint8_t> encode(const srf04_reading& x) {
  return {static_cast<uint8_t>(x.seq), static_cast<uint8_t>(x.seq >> 8),
          static_cast<uint8_t>(x.distance_mm),
          static_cast<uint8_t>(x.distance_mm >> 8),
          static_cast<uint8_t>(x.echo_us), static_cast<uint8_t>(x.echo_us >> 8),
          static_cast<uint8_t>(x.echo_us >> 16),
          static_cast<uint8_t>(x.echo_us >> 24)};
}

/// Exactly 8 bytes; anything else is ec::invalid_parameter.
inline caf::expected<srf04_reading> decode_srf04(const uint8_t* data,
                                                 size_t size) {
  if (size != 8)
    return make_error(ec::invalid_parameter,
                      "an SRF04 reading is 8 bytes, got " + std::to_string(size));
  srf04_reading r;
  r.seq = static_cast<uint16_t>(data[0] | data[1] << 8);
  r.distance_mm = static_cast<uint16_t>(data[2] | data[3] << 8);
  r.echo_us = uint32_t{data[4]} | uint32_t{data[5]} << 8
              | uint32_t{data[6]} << 16 | uint32_t{data[7]} << 24;
  return r;
}

} // namespace herm::hermd
