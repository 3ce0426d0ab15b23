// Fuzz target: the CAN identifier layout (channels/drivers/can_id.hpp,
// docs/protocol.md "CAN identifier layout"): decode_id and decode_frame on
// any identifier, data length and frame type, as the driver calls them for
// every frame read from SocketCAN or the emulated bus.
//
// Input: flags (bit 0: 11-bit format, bit 1: CAN FD), can_id (4 bytes, flags
// included), len, a second can_id, and the fields of a frame to encode
// (priority, dst, src, payload size).
//
// Properties:
// - decode_frame agrees with decode_id; an accepted frame has fields in
//   range (valid()), payload + padding == len, a payload that fits the
//   frame type, padding only in CAN FD frames and exactly what rounding up
//   gives; its identifier re-encodes to the received one (29-bit: every bit;
//   11-bit: the 11 identifier bits) and passes its destination's filter;
// - encode then decode gives the fields back, for every valid frame_id and
//   every payload size the driver can send;
// - arbitration_key orders identifiers as bitwise arbitration does.

#include <cstddef>
#include <cstdint>

#include "channels/drivers/can_id.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;
using namespace herm::can;

namespace {

void check_received(id_format f, canid_t can_id, size_t len, bool fd) {
  frame_id id;
  frame_id from_id;
  size_t payload = 0;
  auto st = decode_frame(f, can_id, len, fd, id, payload);
  auto st_id = decode_id(f, can_id, from_id);
  if (st_id != id_status::ok) {
    HERM_FUZZ_CHECK(st == st_id);
    return;
  }
  if (st != id_status::ok) {
    HERM_FUZZ_CHECK(st == id_status::bad_length
                    || st == id_status::bad_padding);
    return;
  }
  HERM_FUZZ_CHECK(id == from_id);
  HERM_FUZZ_CHECK(valid(f, id));
  HERM_FUZZ_CHECK(payload + id.pad == len);
  HERM_FUZZ_CHECK(payload <= (fd ? fd_max_len : classic_max_len));
  if (!fd)
    HERM_FUZZ_CHECK(id.pad == 0);
  if (id.pad != 0)
    HERM_FUZZ_CHECK(fd_round_up(payload) == len);
  if (fd)
    HERM_FUZZ_CHECK(is_fd_len(len));
  if (f == id_format::ext29)
    HERM_FUZZ_CHECK(to_can_id(f, id) == can_id);
  else
    HERM_FUZZ_CHECK(to_can_id(f, id) == (can_id & CAN_SFF_MASK));
  auto filter = destination_filter(f, id.dst);
  HERM_FUZZ_CHECK((can_id & filter.mask) == filter.id);
  HERM_FUZZ_CHECK(accepts(f, id.dst, id.dst));
}

void check_sent(id_format f, bool fd, frame_id x, size_t size) {
  if (f == id_format::std11)
    fd = false; // CAN FD needs 29-bit identifiers
  x.priority = static_cast<uint8_t>(x.priority & 0x07);
  size = size % ((fd ? fd_max_len : classic_max_len) + 1);
  // As the driver builds a frame (can.cpp): pad up to a CAN FD length.
  size_t len = fd ? fd_round_up(size) : size;
  x.pad = static_cast<uint8_t>(len - size);
  if (!valid(f, x))
    return;
  auto can_id = to_can_id(f, x);
  frame_id y;
  size_t payload = 0;
  HERM_FUZZ_CHECK(decode_frame(f, can_id, len, fd, y, payload)
                  == id_status::ok);
  HERM_FUZZ_CHECK(y == x);
  HERM_FUZZ_CHECK(payload == size);
  // A CAN FD station also takes classic frames: the same frame sent classic.
  if (!fd && f == id_format::ext29) {
    HERM_FUZZ_CHECK(decode_frame(f, can_id, len, true, y, payload)
                    == id_status::ok);
    HERM_FUZZ_CHECK(y == x && payload == size);
  }
}

void check_arbitration(canid_t a, canid_t b) {
  auto eff_a = (a & CAN_EFF_FLAG) != 0;
  auto eff_b = (b & CAN_EFF_FLAG) != 0;
  auto id_a = a & (eff_a ? CAN_EFF_MASK : CAN_SFF_MASK);
  auto id_b = b & (eff_b ? CAN_EFF_MASK : CAN_SFF_MASK);
  auto ka = arbitration_key(a);
  auto kb = arbitration_key(b);
  if (eff_a == eff_b) {
    HERM_FUZZ_CHECK((id_a < id_b) == (ka < kb));
    HERM_FUZZ_CHECK((id_a == id_b) == (ka == kb));
  } else if (!eff_a) {
    // A standard frame wins against an extended one with the same or a
    // higher base identifier (dominant RTR/IDE after the 11 base bits).
    HERM_FUZZ_CHECK((ka < kb) == (id_a <= (id_b >> 18)));
  }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::reader in{data, size};
  auto flags = in.u8();
  auto f = (flags & 1) != 0 ? id_format::std11 : id_format::ext29;
  bool fd = (flags & 2) != 0;
  auto lo = in.u16();
  auto can_id = static_cast<canid_t>(lo | uint32_t{in.u16()} << 16);
  size_t len = in.u8();
  lo = in.u16();
  auto other = static_cast<canid_t>(lo | uint32_t{in.u16()} << 16);
  frame_id x;
  x.priority = in.u8();
  x.dst = in.u8();
  x.src = in.u8();
  size_t payload = in.u8();
  check_received(f, can_id, len, fd);
  check_sent(f, fd, x, payload);
  check_arbitration(can_id, other);
  check_arbitration(other, can_id);
  HERM_FUZZ_CHECK(frame_bits(f, len, true) >= frame_bits(f, len, false));
  return 0;
}
