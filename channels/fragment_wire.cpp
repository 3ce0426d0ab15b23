#include "channels/fragment_wire.hpp"

#include <zlib.h>

#include "channels/le_codec.hpp"

namespace herm::fragment_wire {

size_t encode_consecutive(uint8_t tag, bool wide, uint32_t seq,
                          uint8_t* out) noexcept {
  if (wide) {
    out[0] = static_cast<uint8_t>(header(type_wide, tag) | (seq >> 8 & 0x0f));
    out[1] = static_cast<uint8_t>(seq & 0xff);
    return 2;
  }
  out[0] = static_cast<uint8_t>(header(type_narrow, tag) | (seq & 0x0f));
  return 1;
}

std::optional<consecutive_header> decode_consecutive(const uint8_t* data,
                                                     size_t size) noexcept {
  bool wide = type_of(data[0]) == type_wide;
  auto hdr = consecutive_header_size(wide);
  if (size <= hdr)
    return std::nullopt;
  auto seq = static_cast<uint16_t>(wide ? (data[0] & 0x0f) << 8 | data[1]
                                        : data[0] & 0x0f);
  return consecutive_header{tag_of(data[0]), wide, seq, hdr};
}

size_t length_field_size(size_t length) noexcept {
  return leb128_size(length);
}

std::optional<length_field> decode_length(const uint8_t* data, size_t size,
                                          bool minimal) noexcept {
  le_reader in{data, size};
  uint64_t value = 0;
  if (in.leb128(value, max_length_field, minimal) != leb128_status::ok)
    return std::nullopt;
  return length_field{static_cast<size_t>(value), in.pos()};
}

uint32_t crc_of(const uint8_t* data, size_t size) noexcept {
  // size <= max_announced_length, so the narrowing to uInt is exact.
  return static_cast<uint32_t>(
    crc32(0L, size == 0 ? Z_NULL : data, static_cast<uInt>(size)));
}

cut cut_for(uint32_t mtu, size_t size) noexcept {
  bool wide = mtu >= wide_fragment_mtu;
  return {mtu - 1 - length_field_size(size),
          mtu - consecutive_header_size(wide), wide};
}

} // namespace herm::fragment_wire
