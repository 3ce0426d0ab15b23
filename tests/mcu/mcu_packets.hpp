// Packets a neighbour sends the C client, built with the client's own
// encoders (whose bytes net_test and asl_test pin to the protocol), for the
// module specifications (module_test, module_keyed_test).
#pragma once

#include <cstdint>
#include <string>

#include "apps/mcu/client/hermc_asl.h"
#include "apps/mcu/client/hermc_net.h"
#include "tests/mcu/mcu_bytes.hpp"

namespace mcu_test {

/// A data packet of protocol 1 from `src` to `dst` carrying `asl`
/// (flooded when `flood_id` is not 0).
inline bytes data(uint16_t src, uint16_t dst, const bytes& asl,
                  uint32_t flood_id = 0) {
  hermc_data_header h{src, dst, 32, 1, 2, 1, flood_id, 0};
  uint8_t hdr[12];
  auto n = hermc_data_header_encode(&h, hdr, sizeof hdr);
  bytes out(hdr, hdr + n);
  out.insert(out.end(), asl.begin(), asl.end());
  return out;
}

inline bytes hello(uint16_t sender, uint64_t instance, uint16_t interval) {
  hermc_hello h{sender, instance, 1, interval};
  uint8_t out[15];
  return take(out, hermc_hello_encode(&h, out, sizeof out));
}

inline bytes query(uint32_t qid, hermc_query_by by, const std::string& p) {
  uint8_t out[64];
  return take(out, hermc_asl_query_encode(qid, by, p.data(), p.size(), out,
                                          sizeof out));
}

/// A request for APO `apo` (one-way when `rid` is 0) with `payload`.
inline bytes request(uint64_t rid, uint32_t apo, const bytes& payload) {
  uint8_t out[64];
  auto n = hermc_asl_request_header(rid, apo, 0, rid == 0, out, sizeof out);
  bytes b = take(out, n);
  b.insert(b.end(), payload.begin(), payload.end());
  return b;
}

} // namespace mcu_test
