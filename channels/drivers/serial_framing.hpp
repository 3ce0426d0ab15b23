#pragma once

// Byte-stream framing of the "serial" link kind (channels/drivers/serial.cpp):
// how frames of at most MTU bytes travel over a line that carries bytes only
// (RS232C, USB CDC-ACM). Pure code without clock or I/O, so the driver, its
// tests and fuzzers share one definition. Specified for people (and
// microcontrollers) in docs/protocol.md (serial framing).
//
// On the wire, one frame of n bytes (1 <= n <= MTU <= 255) is
//
//   [0x00]  COBS(frame || CRC-16/CCITT-FALSE(frame), big endian)  0x00
//
// The leading 0x00 is sent only when the line was idle, so that a receiver
// that woke up in the middle of garbage resynchronises at once. COBS removes
// every 0x00 from the encoded bytes, so 0x00 is the one and only frame
// delimiter. With XON/XOFF flow control the tty itself consumes 0x11 and
// 0x13, so in that mode the encoded bytes 0x11, 0x13 and 0x7D additionally
// travel as 0x7D followed by the byte XOR 0x20 ("escaped" mode).
//
// Bounds per call: encode_frame and cobs_encode/cobs_decode are O(n) in the
// frame size and allocate nothing (encode_frame uses two stack buffers of
// under 600 bytes); append_frame grows the caller's buffer by at most
// max_wire_size(size, escaped) bytes. decoder::feed is O(size) plus O(MTU)
// per delimiter, allocates nothing (its two buffers of
// cobs_max_size(mtu + crc_size) bytes are made by the constructor) and
// never writes past them: a run longer than the largest valid frame is
// counted as oversized and skipped to the next delimiter. The only
// multi-byte integer is the CRC, big endian by the specification, so this
// framing needs nothing from channels/le_codec.hpp.

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace herm::serial {

// -- constants -------------------------------------------------------------------

/// The frame delimiter; never occurs inside an encoded frame.
constexpr uint8_t delimiter = 0x00;

/// Bytes of CRC appended to every frame before COBS encoding.
constexpr size_t crc_size = 2;

/// Largest MTU of the serial link kind, bytes of frame payload.
constexpr uint32_t max_mtu = 255;

/// Escaped mode (flow control XON/XOFF) only.
constexpr uint8_t xon = 0x11;
constexpr uint8_t xoff = 0x13;
constexpr uint8_t escape_byte = 0x7D;
constexpr uint8_t escape_xor = 0x20;

/// True for the encoded bytes that escaped mode sends as two bytes.
constexpr bool needs_escape(uint8_t x) {
  return x == xon || x == xoff || x == escape_byte;
}

// -- CRC-16/CCITT-FALSE ------------------------------------------------------------

namespace detail {

constexpr std::array<uint16_t, 256> make_crc16_table() {
  std::array<uint16_t, 256> table{};
  for (unsigned i = 0; i < 256; ++i) {
    auto crc = static_cast<uint16_t>(i << 8);
    for (int bit = 0; bit < 8; ++bit)
      crc = static_cast<uint16_t>((crc & 0x8000) != 0 ? (crc << 1) ^ 0x1021
                                                       : crc << 1);
    table[i] = crc;
  }
  return table;
}

inline constexpr std::array<uint16_t, 256> crc16_table = make_crc16_table();

} // namespace detail

/// Initial value of CRC-16/CCITT-FALSE.
constexpr uint16_t crc16_init = 0xFFFF;

/// CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF, not
/// reflected, no final XOR; check value 0x29B1 for "123456789"). Continue a
/// running CRC by passing the previous result as `crc`.
inline uint16_t crc16(const uint8_t* data, size_t size,
                      uint16_t crc = crc16_init) {
  for (size_t i = 0; i < size; ++i)
    crc = static_cast<uint16_t>((crc << 8)
                                ^ detail::crc16_table[((crc >> 8) ^ data[i])
                                                      & 0xFF]);
  return crc;
}

// -- COBS ----------------------------------------------------------------------

/// Upper bound of the COBS encoding of `n` bytes: one code byte per started
/// run of 254 bytes, at least one.
constexpr size_t cobs_max_size(size_t n) {
  return n + n / 254 + 1;
}

/// COBS-encodes `in[0..n)` into `out`, which must hold cobs_max_size(n)
/// bytes; returns the encoded size. The output contains no 0x00. Canonical
/// form (Cheshire and Baker): a run of 254 non-zero bytes that ends the
/// input is not followed by a 0x01 code byte. `in` and `out` must not
/// overlap.
inline size_t cobs_encode(const uint8_t* in, size_t n, uint8_t* out) {
  size_t code_pos = 0;
  size_t pos = 1;
  uint8_t code = 1;
  for (size_t i = 0; i < n; ++i) {
    if (in[i] != 0) {
      out[pos++] = in[i];
      ++code;
    }
    if (in[i] == 0 || code == 0xFF) {
      out[code_pos] = code;
      code = 1;
      code_pos = pos;
      // A full block at the very end needs no further (empty) block.
      if (in[i] == 0 || i + 1 < n)
        ++pos;
    }
  }
  // Final block, unless a full block just ended the input (then code_pos
  // == pos and nothing is written: pos was not advanced for it).
  if (code_pos < pos)
    out[code_pos] = code;
  return pos;
}

/// Decodes COBS bytes `in[0..n)` (without delimiter) into `out`, which must
/// hold `n` bytes; returns the decoded size, or SIZE_MAX when `in` is not
/// COBS: it contains 0x00, or a code byte points past the end. Accepts both
/// the canonical form and a redundant trailing 0x01 after a full block.
inline size_t cobs_decode(const uint8_t* in, size_t n, uint8_t* out) {
  size_t pos = 0;
  size_t len = 0;
  while (pos < n) {
    auto code = in[pos++];
    if (code == 0)
      return SIZE_MAX;
    size_t run = code - 1u;
    if (run > n - pos)
      return SIZE_MAX;
    for (size_t i = 0; i < run; ++i) {
      if (in[pos] == 0)
        return SIZE_MAX;
      out[len++] = in[pos++];
    }
    if (code != 0xFF && pos < n)
      out[len++] = 0;
  }
  return len;
}

// -- frames ----------------------------------------------------------------------

/// Upper bound of the bytes one frame of `size` bytes takes on the wire,
/// both delimiters included.
constexpr size_t max_wire_size(size_t size, bool escaped) {
  return (escaped ? 2 : 1) * cobs_max_size(size + crc_size) + 2;
}

/// Encodes one frame for the wire into `out`, which must hold
/// max_wire_size(size, escaped) bytes: an optional leading delimiter, the
/// COBS encoding of frame || CRC (big endian), escaped when `escaped`, and
/// the trailing delimiter. Returns the number of bytes written.
/// @pre 1 <= size <= max_mtu
inline size_t encode_frame(const uint8_t* frame, size_t size,
                           bool leading_delimiter, bool escaped,
                           uint8_t* out) {
  uint8_t raw[max_mtu + crc_size];
  std::memcpy(raw, frame, size);
  auto crc = crc16(frame, size);
  raw[size] = static_cast<uint8_t>(crc >> 8);
  raw[size + 1] = static_cast<uint8_t>(crc & 0xFF);
  size_t pos = 0;
  if (leading_delimiter)
    out[pos++] = delimiter;
  if (!escaped) {
    pos += cobs_encode(raw, size + crc_size, out + pos);
  } else {
    uint8_t cobs[cobs_max_size(max_mtu + crc_size)];
    auto n = cobs_encode(raw, size + crc_size, cobs);
    for (size_t i = 0; i < n; ++i) {
      if (needs_escape(cobs[i])) {
        out[pos++] = escape_byte;
        out[pos++] = static_cast<uint8_t>(cobs[i] ^ escape_xor);
      } else {
        out[pos++] = cobs[i];
      }
    }
  }
  out[pos++] = delimiter;
  return pos;
}

/// Appends the wire form of one frame to `buf` (see encode_frame).
inline size_t append_frame(std::vector<uint8_t>& buf, const uint8_t* frame,
                           size_t size, bool leading_delimiter, bool escaped) {
  auto old = buf.size();
  buf.resize(old + max_wire_size(size, escaped));
  auto n = encode_frame(frame, size, leading_delimiter, escaped,
                        buf.data() + old);
  buf.resize(old + n);
  return n;
}

// -- decoding --------------------------------------------------------------------

/// Why the decoder dropped the bytes between two delimiters.
enum class rx_error : uint8_t {
  /// Not valid COBS (a code byte points past the delimiter).
  bad_cobs,
  /// Decoded to fewer than 1 + crc_size bytes.
  too_short,
  /// Longer than the MTU allows; bytes were discarded up to the next
  /// delimiter (counted once per run of garbage).
  oversized,
  /// The CRC-16 does not match.
  bad_crc,
  /// Escaped mode: 0x7D not followed by 0x31, 0x33 or 0x5D.
  bad_escape,
};

constexpr size_t rx_error_count = 5;

/// Short reason for frame_handler::on_malformed. Static storage.
inline const char* to_string(rx_error x) {
  switch (x) {
    case rx_error::bad_cobs: return "serial: bad COBS encoding";
    case rx_error::too_short: return "serial: frame shorter than its CRC";
    case rx_error::oversized: return "serial: frame longer than the MTU";
    case rx_error::bad_crc: return "serial: CRC-16 mismatch";
    case rx_error::bad_escape: return "serial: bad escape sequence";
  }
  return "serial: malformed";
}

/// Counters of a decoder. Every run of bytes between two delimiters counts
/// exactly once: as a frame, as idle (empty) or under one error.
struct decoder_stats {
  uint64_t frames = 0;
  /// Empty runs: two delimiters back to back (idle line, resynchronisation).
  uint64_t idle = 0;
  std::array<uint64_t, rx_error_count> errors{};

  uint64_t malformed() const {
    uint64_t sum = 0;
    for (auto x : errors)
      sum += x;
    return sum;
  }

  uint64_t count(rx_error x) const {
    return errors[static_cast<size_t>(x)];
  }
};

/// Incremental decoder: feed it bytes as they come off the line, in chunks
/// of any size; it calls back once per frame or per malformed run. Memory is
/// bounded by the MTU (allocated once in the constructor). Not thread-safe.
class decoder {
public:
  /// @pre 1 <= mtu <= max_mtu
  explicit decoder(uint32_t mtu, bool escaped = false)
    : mtu_(mtu),
      escaped_(escaped),
      cap_(cobs_max_size(mtu + crc_size)),
      buf_(cap_),
      out_(cap_) {
  }

  /// Consumes `data[0..size)`. Calls `on_frame(const uint8_t* frame,
  /// size_t size)` for each good frame (the pointer is valid during the call
  /// only) and `on_malformed(rx_error)` for each bad one. A bad escape or an
  /// overflow is reported as soon as it is seen (the rest of the run up to
  /// the next delimiter is then skipped); COBS, length and CRC are checked
  /// at the delimiter.
  template <class OnFrame, class OnMalformed>
  void feed(const uint8_t* data, size_t size, OnFrame&& on_frame,
            OnMalformed&& on_malformed) {
    for (size_t i = 0; i < size; ++i) {
      auto x = data[i];
      if (x == delimiter) {
        end_of_run(on_frame, on_malformed);
        continue;
      }
      if (discarding_)
        continue;
      if (escaped_) {
        if (escape_pending_) {
          escape_pending_ = false;
          x = static_cast<uint8_t>(x ^ escape_xor);
          if (!needs_escape(x)) {
            fail(rx_error::bad_escape, on_malformed);
            continue;
          }
        } else if (x == escape_byte) {
          escape_pending_ = true;
          continue;
        }
      }
      if (len_ == cap_) {
        fail(rx_error::oversized, on_malformed);
        continue;
      }
      buf_[len_++] = x;
    }
  }

  /// Forgets a partly received frame (e.g. after the line speed changed).
  void reset() {
    len_ = 0;
    discarding_ = false;
    escape_pending_ = false;
  }

  const decoder_stats& stats() const {
    return stats_;
  }

  uint32_t mtu() const {
    return mtu_;
  }

private:
  template <class OnMalformed>
  void fail(rx_error why, OnMalformed& on_malformed) {
    ++stats_.errors[static_cast<size_t>(why)];
    len_ = 0;
    escape_pending_ = false;
    discarding_ = true;
    on_malformed(why);
  }

  template <class OnFrame, class OnMalformed>
  void end_of_run(OnFrame& on_frame, OnMalformed& on_malformed) {
    if (discarding_) {
      discarding_ = false;
      return;
    }
    if (escape_pending_) {
      fail(rx_error::bad_escape, on_malformed);
      discarding_ = false;
      return;
    }
    if (len_ == 0) {
      ++stats_.idle;
      return;
    }
    auto n = cobs_decode(buf_.data(), len_, out_.data());
    len_ = 0;
    rx_error why;
    if (n == SIZE_MAX)
      why = rx_error::bad_cobs;
    else if (n < 1 + crc_size)
      why = rx_error::too_short;
    else if (n > mtu_ + crc_size)
      why = rx_error::oversized;
    else if (crc16(out_.data(), n - crc_size)
             != ((uint16_t{out_[n - 2]} << 8) | out_[n - 1]))
      why = rx_error::bad_crc;
    else {
      ++stats_.frames;
      on_frame(static_cast<const uint8_t*>(out_.data()), n - crc_size);
      return;
    }
    fail(why, on_malformed);
    discarding_ = false;
  }

  uint32_t mtu_;
  bool escaped_;
  /// Capacity of buf_: the largest valid COBS run for the MTU.
  size_t cap_;
  /// COBS bytes of the current run (escapes removed).
  std::vector<uint8_t> buf_;
  size_t len_ = 0;
  /// Decoded frame || CRC.
  std::vector<uint8_t> out_;
  /// Skipping to the next delimiter after an error in this run.
  bool discarding_ = false;
  bool escape_pending_ = false;
  decoder_stats stats_;
};

} // namespace herm::serial
