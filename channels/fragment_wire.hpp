#pragma once

// The fragment header codec: what the fragmenter writes and the reassembler
// and the bundle codec read (docs/protocol.md, "Fragment header"). Pure
// code, no state, no allocation.
//
// Frame layout (first byte = header type in bits 7..6, tag in bits 5..4):
//   single       00 TT 0000  | payload                      (packet fits one frame)
//   first        01 TT W000  | LEB128 length | stream bytes (W: wide sequence)
//   consecutive  10 TT SSSS  | stream bytes                 (narrow: seq mod 16)
//   consecutive  11 TT SSSS SSSSSSSS | stream bytes         (wide: seq mod 4096)
// where the fragmented stream is payload || CRC-32(payload), little endian,
// the first frame has index 0 and consecutive frames 1, 2, ... The sender
// uses wide sequence numbers when the MTU is at least 64 bytes.
//
// Contract of every function here: O(1) time except crc_of (O(size)); no
// allocation; reads and writes stay within the sizes given (writers within
// the sizes stated per function).

#include <cstddef>
#include <cstdint>
#include <optional>

namespace herm {

/// Smallest MTU fragmentation supports (a CAN 2.0 frame).
constexpr uint32_t min_fragment_mtu = 8;

/// MTU from which the sender uses 12-bit (wide) sequence numbers.
constexpr uint32_t wide_fragment_mtu = 64;

namespace fragment_wire {

constexpr uint8_t type_single = 0;
constexpr uint8_t type_first = 1;
constexpr uint8_t type_narrow = 2;
constexpr uint8_t type_wide = 3;

/// Bit 3 of a first fragment's header: the packet uses wide sequence numbers.
constexpr uint8_t first_wide_flag = 0x08;

/// Bytes of the CRC-32 that ends a fragmented stream.
constexpr uint32_t crc_size = 4;

/// A length field longer than this is malformed, which caps what can be
/// fragmented at 2^21 - 1 bytes.
constexpr size_t max_length_field = 3;
constexpr size_t max_announced_length = (size_t{1} << (7 * max_length_field)) - 1;

constexpr uint32_t narrow_modulus = 16;
constexpr uint32_t wide_modulus = 4096;

/// The header byte of type `type` with packet tag `tag` (its low 2 bits),
/// low nibble 0.
constexpr uint8_t header(uint8_t type, uint8_t tag) {
  return static_cast<uint8_t>(type << 6 | (tag & 0x03) << 4);
}

constexpr uint8_t type_of(uint8_t header_byte) {
  return static_cast<uint8_t>(header_byte >> 6);
}

constexpr uint8_t tag_of(uint8_t header_byte) {
  return static_cast<uint8_t>(header_byte >> 4 & 0x03);
}

/// Bytes a consecutive fragment's header takes: 2 wide, 1 narrow.
constexpr size_t consecutive_header_size(bool wide) {
  return wide ? 2 : 1;
}

/// Writes a consecutive fragment's header for sequence number `seq`
/// (already reduced: below wide_modulus, or narrow_modulus when narrow)
/// into `out`, which holds consecutive_header_size(wide) bytes. Returns the
/// bytes written.
size_t encode_consecutive(uint8_t tag, bool wide, uint32_t seq,
                          uint8_t* out) noexcept;

/// A consecutive fragment's header as read from a frame.
struct consecutive_header {
  uint8_t tag;
  bool wide;
  uint16_t seq;
  /// Bytes of header before the stream bytes.
  size_t size;
};

/// Reads the header of a consecutive fragment (type narrow or wide).
/// @pre size >= 1 and type_of(data[0]) is type_narrow or type_wide
/// Returns nullopt when the frame holds no stream bytes after it.
std::optional<consecutive_header> decode_consecutive(const uint8_t* data,
                                                     size_t size) noexcept;

/// Bytes the minimal LEB128 form of a packet length takes (1 to 3).
/// @pre length <= max_announced_length
size_t length_field_size(size_t length) noexcept;

struct length_field {
  size_t value;
  size_t size;
};

/// Reads an LEB128 length of at most three bytes from `[data, data + size)`.
/// With `minimal` false, non-minimal encodings (0x81 0x00 for 1) are
/// accepted: the value is still unambiguous (a first fragment's length).
/// With `minimal`, they are refused (a bundle entry's length). Fails when
/// the field runs past the frame or past three bytes.
std::optional<length_field> decode_length(const uint8_t* data, size_t size,
                                          bool minimal = false) noexcept;

/// CRC-32 (IEEE, zlib's crc32) of `size` bytes.
/// @pre size <= max_announced_length
uint32_t crc_of(const uint8_t* data, size_t size) noexcept;

/// How a fragmented packet is cut: the first frame carries `first_data`
/// stream bytes after its header and length field, every other frame
/// `chunk` bytes after its sequence header, the last one what remains.
struct cut {
  size_t first_data;
  size_t chunk;
  bool wide;
};

/// The cut of a packet of `size` bytes at `mtu`.
/// @pre mtu >= min_fragment_mtu, size <= max_announced_length
cut cut_for(uint32_t mtu, size_t size) noexcept;

} // namespace fragment_wire

} // namespace herm
