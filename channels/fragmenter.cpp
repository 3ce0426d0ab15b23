#include "channels/fragmenter.hpp"

#include <algorithm>
#include <cassert>
#include <cstring>

#include "channels/le_codec.hpp"

namespace herm {

using namespace fragment_wire;

fragmenter::fragmenter(uint32_t mtu) : mtu_(std::max(mtu, min_fragment_mtu)) {
  // Below the minimum the first frame could not carry its header, length
  // and a byte of data; release builds clamp instead of misbehaving.
  assert(mtu >= min_fragment_mtu);
}

size_t fragmenter::frames_for(size_t size) const noexcept {
  if (size < mtu_)
    return 1;
  if (size > max_announced_length)
    return 0; // the length field cannot announce it: split emits nothing
  auto c = cut_for(mtu_, size);
  auto rest = size + crc_size - c.first_data;
  return 1 + (rest + c.chunk - 1) / c.chunk;
}

void fragmenter::split(link_addr dst, uint8_t lane, const uint8_t* data,
                       size_t size, frame_sink emit) {
  auto key = std::pair{dst, lane};
  if (tags_.size() >= max_sequences && tags_.count(key) == 0)
    tags_.clear();
  auto& tag = tags_[key];
  next_tag_ = tag;
  split(data, size, emit);
  tag = next_tag_;
}

void fragmenter::split(link_addr dst, const uint8_t* data, size_t size, frame_sink emit) {
  split(dst, 0, data, size, emit);
}

void fragmenter::split(const uint8_t* data, size_t size, frame_sink emit) {
  auto tag = next_tag_;
  if (size < mtu_) {
    if (scratch_.size() < size + 1)
      scratch_.resize(size + 1);
    next_tag_ = (next_tag_ + 1) & 0x03;
    scratch_[0] = header(type_single, tag);
    if (size > 0)
      std::memcpy(scratch_.data() + 1, data, size);
    emit(scratch_.data(), size + 1);
    return;
  }
  if (size > max_announced_length)
    return;
  next_tag_ = (next_tag_ + 1) & 0x03;
  uint8_t crc[crc_size];
  store_le(crc_of(data, size), crc);
  // Copies stream bytes [offset, offset + n) of payload || crc to `out`.
  auto copy_stream = [&](size_t offset, size_t n, uint8_t* out) {
    if (offset < size) {
      auto from_payload = std::min(n, size - offset);
      std::memcpy(out, data + offset, from_payload);
      out += from_payload;
      n -= from_payload;
      offset += from_payload;
    }
    // Only when CRC bytes are due: with n == 0 the offset may still lie in
    // the payload, and crc + (offset - size) would point far outside.
    if (n > 0)
      std::memcpy(out, crc + (offset - size), n);
  };
  auto c = cut_for(mtu_, size);
  auto stream = size + crc_size;
  // First frame: header, length field, then stream bytes up to the MTU.
  // The scratch buffer keeps its capacity: no allocation once warmed up.
  scratch_.clear();
  le_writer{scratch_}
    .u8(static_cast<uint8_t>(header(type_first, tag)
                             | (c.wide ? first_wide_flag : 0)))
    .leb128(size);
  auto prefix = scratch_.size();
  scratch_.resize(mtu_);
  auto* frame = scratch_.data();
  copy_stream(0, c.first_data, frame + prefix);
  emit(frame, mtu_);
  size_t index = 1;
  auto modulus = c.wide ? wide_modulus : narrow_modulus;
  for (size_t offset = c.first_data; offset < stream; offset += c.chunk) {
    auto n = std::min(c.chunk, stream - offset);
    auto hdr = encode_consecutive(tag, c.wide,
                                  static_cast<uint32_t>(index % modulus), frame);
    copy_stream(offset, n, frame + hdr);
    emit(frame, hdr + n);
    ++index;
  }
}

} // namespace herm
