// Fuzz target: the datagram headers of the emulated media, as a receiving
// station checks every datagram on its socket:
// - emu::check (channels/drivers/emu_wire.hpp), the "emu" link kind;
// - can::wire::check (channels/drivers/can_emu_wire.hpp), the emulated CAN
//   bus, followed by what the CAN driver does with an accepted datagram:
//   copy the frame into a zeroed struct canfd_frame and decode_frame it.
//
// Input: MTU (2 bytes), the receiver's CLOCK_MONOTONIC time (8 bytes, kept
// non-negative like the real clock), CAN options (1 byte: 11-bit format,
// node id), then the datagram.
//
// Properties: check is total; an accepted header has every field in range,
// re-encodes to exactly the datagram's first 16 bytes and does not lie
// more than max_hold_ns ahead; an emu payload fits the MTU; an accepted CAN
// datagram holds exactly a can_frame or canfd_frame, and a frame that
// decodes hands up no more bytes than its data field holds.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "channels/drivers/can_emu_wire.hpp"
#include "channels/drivers/can_id.hpp"
#include "channels/drivers/emu_wire.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

void check_emu(const uint8_t* data, size_t size, uint32_t mtu,
               int64_t now) {
  emu::wire_header hdr;
  auto st = emu::check(data, size, mtu, now, hdr);
  if (st == emu::wire_status::too_short) {
    HERM_FUZZ_CHECK(size < emu::wire_header_size);
    return;
  }
  uint8_t again[emu::wire_header_size];
  emu::encode(hdr, again);
  HERM_FUZZ_CHECK(std::memcmp(again, data, sizeof(again)) == 0);
  if (st != emu::wire_status::ok)
    return;
  HERM_FUZZ_CHECK(hdr.magic == emu::wire_magic);
  HERM_FUZZ_CHECK(hdr.version == emu::wire_version);
  HERM_FUZZ_CHECK((hdr.flags & ~emu::flag_mask) == 0 && hdr.reserved == 0);
  HERM_FUZZ_CHECK(hdr.src >= emu::min_station && hdr.src <= emu::max_station);
  HERM_FUZZ_CHECK(size - emu::wire_header_size <= mtu);
  HERM_FUZZ_CHECK(hdr.deliver_at_ns <= now
                  || hdr.deliver_at_ns - now <= emu::max_hold_ns);
}

void check_can(const uint8_t* data, size_t size, int64_t now, uint8_t opts) {
  can::wire::header hdr;
  auto st = can::wire::check(data, size, now, hdr);
  if (st == can::wire::status::too_short) {
    HERM_FUZZ_CHECK(size < can::wire::header_size);
    return;
  }
  uint8_t again[can::wire::header_size];
  can::wire::encode(hdr, again);
  HERM_FUZZ_CHECK(std::memcmp(again, data, sizeof(again)) == 0);
  if (st != can::wire::status::ok)
    return;
  HERM_FUZZ_CHECK(hdr.magic == can::wire::magic);
  HERM_FUZZ_CHECK(hdr.version == can::wire::version);
  HERM_FUZZ_CHECK((hdr.flags & ~can::wire::flag_mask) == 0
                  && hdr.reserved == 0);
  HERM_FUZZ_CHECK(hdr.deliver_at_ns <= now
                  || hdr.deliver_at_ns - now <= can::wire::max_hold_ns);
  auto n = size - can::wire::header_size;
  HERM_FUZZ_CHECK(n == CAN_MTU || n == CANFD_MTU);
  // What the driver does next (can.cpp: receive, then dispatch).
  canfd_frame frame;
  std::memset(&frame, 0, sizeof(frame));
  std::memcpy(&frame, data + can::wire::header_size, n);
  auto f = (opts & 1) != 0 ? can::id_format::std11 : can::id_format::ext29;
  can::frame_id id;
  size_t payload = 0;
  if (can::decode_frame(f, frame.can_id, frame.len, n == CANFD_MTU, id,
                        payload)
      != can::id_status::ok)
    return;
  HERM_FUZZ_CHECK(payload <= (n == CANFD_MTU ? sizeof(frame.data)
                                             : size_t{CAN_MAX_DLEN}));
  HERM_FUZZ_CHECK(can::valid(f, id));
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::reader in{data, size};
  uint32_t mtu = in.u16();
  auto now = static_cast<int64_t>(in.u64() >> 1);
  auto opts = in.u8();
  // The datagram as received: its own heap block, so that ASan sees any
  // read past its end.
  std::vector<uint8_t> dgram(in.data, in.data + in.size);
  check_emu(dgram.data(), dgram.size(), mtu, now);
  check_can(dgram.data(), dgram.size(), now, opts);
  return 0;
}
