// Fuzz target: bundle_decode and bundle_append (channels/fragmentation.hpp,
// docs/protocol.md "Bundles"): several small packets in one frame.
//
// Properties: a bundle that decodes re-encodes to exactly its bytes
// (bundle_append produces the only valid encoding), every packet is within
// 1..max_packet and there are at least two; a refused bundle emits nothing.
// The first input byte picks max_packet, the rest is the frame.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "channels/bundle_codec.hpp"
#include "tests/fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1)
    return 0;
  size_t max_packet = size_t{data[0]} * 8 + 1;
  ++data;
  --size;
  std::vector<herm::byte_buffer> packets;
  auto ok = herm::bundle_decode(data, size, max_packet,
                                [&](const uint8_t* p, size_t n) {
                                  packets.emplace_back(p, p + n);
                                });
  if (!ok) {
    HERM_FUZZ_CHECK(packets.empty());
    return 0;
  }
  HERM_FUZZ_CHECK(packets.size() >= 2);
  herm::byte_buffer again;
  for (auto& p : packets) {
    HERM_FUZZ_CHECK(!p.empty() && p.size() <= max_packet);
    HERM_FUZZ_CHECK(herm::bundle_append(again, static_cast<uint32_t>(size),
                                        p.data(), p.size()));
  }
  HERM_FUZZ_CHECK(again.size() == size);
  HERM_FUZZ_CHECK(std::equal(again.begin(), again.end(), data));
  return 0;
}
