// Fuzz target: decode_srf04 (apps/hermd/srf04.hpp, docs/protocol.md "SRF04
// reading"), the 8-byte record the testbed's AVR board sends.
//
// Properties: exactly the 8-byte inputs decode, anything else is
// ec::invalid_parameter; a reading re-encodes to exactly its 8 bytes.

#include <cstddef>
#include <cstdint>

#include "actors/runtime/error.hpp"
#include "apps/hermd/srf04.hpp"
#include "tests/fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto r = herm::hermd::decode_srf04(data, size);
  if (size != 8) {
    HERM_FUZZ_CHECK(!r);
    HERM_FUZZ_CHECK(herm::is(r.error(), herm::ec::invalid_parameter));
    return 0;
  }
  HERM_FUZZ_CHECK(r);
  auto bytes = herm::hermd::encode(*r);
  HERM_FUZZ_CHECK(bytes.size() == 8);
  HERM_FUZZ_CHECK(std::equal(bytes.begin(), bytes.end(), data));
  return 0;
}
