#include "channels/bundle_codec.hpp"

#include "channels/fragment_wire.hpp"
#include "channels/le_codec.hpp"

namespace herm {

using namespace fragment_wire;

size_t bundle_cost(size_t size) noexcept {
  return leb128_size(size) + size;
}

bool bundle_append(byte_buffer& frame, uint32_t mtu, const uint8_t* data,
                   size_t size) {
  if (size == 0 || size > max_announced_length)
    return false;
  auto need = bundle_cost(size) + (frame.empty() ? 1 : 0);
  if (frame.size() + need > mtu)
    return false;
  le_writer out{frame};
  if (frame.empty())
    out.u8(bundle_header);
  out.leb128(size).bytes(data, size);
  return true;
}

bool bundle_decode(const uint8_t* data, size_t size, size_t max_packet,
                   const std::function<void(const uint8_t*, size_t)>& emit) {
  if (size == 0 || data[0] != bundle_header)
    return false;
  // First pass: check everything, so that a bad bundle delivers nothing.
  size_t count = 0;
  for (size_t pos = 1; pos < size;) {
    auto len = decode_length(data + pos, size - pos, true);
    if (!len || len->value == 0 || len->value > max_packet
        || len->value > size - pos - len->size)
      return false;
    pos += len->size + len->value;
    ++count;
  }
  if (count < 2)
    return false;
  for (size_t pos = 1; pos < size;) {
    auto len = decode_length(data + pos, size - pos, true);
    emit(data + pos + len->size, len->value);
    pos += len->size + len->value;
  }
  return true;
}

} // namespace herm
