#pragma once

// The one little-endian reader and writer behind every hand-written codec in
// HERM (routing packets, ASL messages, the authentication trailer, APO
// payloads, link framings). It sits in the lowest layer so that every layer's
// codecs can use it; it includes nothing of HERM.
//
// Contract, for every function below:
// - Time: O(1) per integer, O(n) per run of n bytes; nothing else.
// - Memory: the writer only appends to the caller's buffer (amortised
//   growth of that vector, nothing else); the reader never allocates except
//   for `str`, which assigns exactly n bytes to the caller's string.
// - Bad input: the reader never reads past `size`. A read that does not fit
//   reads nothing, consumes nothing, yields 0 (or nullptr, or leaves the
//   output untouched) and sets a sticky failure flag: every later read fails
//   too, so a decoder may read a whole fixed layout and test `ok()` once.
//   Decoders that report which field was short test `left()` first instead.
// - Threading: none; a reader or writer is used by one thread at a time.
// - Ownership: the reader borrows `data` (must outlive it); the writer
//   borrows the output buffer.

#include <algorithm>
#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

namespace herm {

// -- fixed-position access --------------------------------------------------------

/// Stores `x` little-endian into `out[0, sizeof(T))`. `out` must hold that
/// many bytes.
template <class T>
void store_le(T x, uint8_t* out) noexcept {
  static_assert(std::is_unsigned_v<T>, "store_le needs an unsigned type");
  for (size_t i = 0; i < sizeof(T); ++i)
    out[i] = static_cast<uint8_t>(x >> (8 * i));
}

/// Loads a little-endian `T` from `in[0, sizeof(T))`. `in` must hold that
/// many bytes.
template <class T>
T load_le(const uint8_t* in) noexcept {
  static_assert(std::is_unsigned_v<T>, "load_le needs an unsigned type");
  T x = 0;
  for (size_t i = 0; i < sizeof(T); ++i)
    x = static_cast<T>(x | static_cast<T>(in[i]) << (8 * i));
  return x;
}

/// Most bytes an unsigned LEB128 of 64 bits takes.
constexpr size_t max_leb128_size = 10;

/// Bytes the unsigned LEB128 form of `x` takes (1 to 10).
constexpr size_t leb128_size(uint64_t x) noexcept {
  size_t n = 1;
  for (; x >= 0x80; x >>= 7)
    ++n;
  return n;
}

// -- writer -----------------------------------------------------------------------

/// Appends little-endian fields to a byte buffer. Never fails; every call
/// appends exactly the bytes its name says.
class le_writer {
public:
  explicit le_writer(std::vector<uint8_t>& out) noexcept : out_(out) {
    // nop
  }

  le_writer& u8(uint8_t x) {
    out_.push_back(x);
    return *this;
  }

  le_writer& u16(uint16_t x) {
    return le(x);
  }

  le_writer& u32(uint32_t x) {
    return le(x);
  }

  le_writer& u64(uint64_t x) {
    return le(x);
  }

  /// Any unsigned integer, sizeof(T) bytes.
  template <class T>
  le_writer& le(T x) {
    static_assert(std::is_unsigned_v<T>, "le_writer::le needs an unsigned type");
    for (size_t i = 0; i < sizeof(T); ++i)
      out_.push_back(static_cast<uint8_t>(x >> (8 * i)));
    return *this;
  }

  /// `n` bytes as they are; `data` may be null when `n` is 0.
  le_writer& bytes(const void* data, size_t n) {
    auto* p = static_cast<const uint8_t*>(data);
    if (n > 0)
      out_.insert(out_.end(), p, p + n);
    return *this;
  }

  template <size_t N>
  le_writer& bytes(const std::array<uint8_t, N>& x) {
    return bytes(x.data(), N);
  }

  /// Unsigned LEB128, minimal form: leb128_size(x) bytes.
  le_writer& leb128(uint64_t x) {
    for (; x >= 0x80; x >>= 7)
      out_.push_back(static_cast<uint8_t>((x & 0x7f) | 0x80));
    out_.push_back(static_cast<uint8_t>(x));
    return *this;
  }

  /// A list of at most `max` (at most 255) elements: their count in one
  /// byte, then `put(element)` for each, in order. A longer list is the
  /// caller's bug: asserted, and cut to its first `max` elements when
  /// assertions are off. O(elements written) plus what `put` costs.
  template <class Seq, class Put>
  le_writer& u8_counted(const Seq& xs, size_t max, Put put) {
    assert(max <= 255 && xs.size() <= max);
    auto count = std::min<size_t>({xs.size(), max, 255});
    u8(static_cast<uint8_t>(count));
    for (size_t i = 0; i < count; ++i)
      put(xs[i]);
    return *this;
  }

  std::vector<uint8_t>& buffer() noexcept {
    return out_;
  }

private:
  std::vector<uint8_t>& out_;
};

// -- reader -----------------------------------------------------------------------

/// Why an LEB128 read failed.
enum class leb128_status : uint8_t {
  ok,
  /// The input ended before the last byte of the number.
  truncated,
  /// No last byte within the allowed bytes, or more than 64 bits.
  too_long,
  /// A trailing 0x00 byte (only when minimal form is required).
  not_minimal,
};

/// Reads little-endian fields from `data[0, size)`, starting at `pos`.
/// Bounds-checked: see the contract at the top of this file.
class le_reader {
public:
  le_reader(const uint8_t* data, size_t size, size_t pos = 0) noexcept
    : data_(data), size_(data == nullptr ? 0 : size),
      pos_(pos <= size_ ? pos : size_), ok_(pos <= size_) {
    // nop
  }

  /// False once any read did not fit.
  bool ok() const noexcept {
    return ok_;
  }

  /// Bytes not yet read.
  size_t left() const noexcept {
    return size_ - pos_;
  }

  /// Offset of the next byte to read.
  size_t pos() const noexcept {
    return pos_;
  }

  size_t size() const noexcept {
    return size_;
  }

  /// Whether `n` more bytes can be read.
  bool has(size_t n) const noexcept {
    return ok_ && left() >= n;
  }

  uint8_t u8() noexcept {
    return le<uint8_t>();
  }

  uint16_t u16() noexcept {
    return le<uint16_t>();
  }

  uint32_t u32() noexcept {
    return le<uint32_t>();
  }

  uint64_t u64() noexcept {
    return le<uint64_t>();
  }

  /// Any unsigned integer of sizeof(T) bytes; 0 when it does not fit.
  template <class T>
  T le() noexcept {
    if (!take(sizeof(T)))
      return 0;
    return load_le<T>(data_ + pos_ - sizeof(T));
  }

  /// The next `n` bytes, or nullptr when they do not fit. The pointer is
  /// into the reader's input.
  const uint8_t* bytes(size_t n) noexcept {
    if (!take(n))
      return nullptr;
    return data_ + pos_ - n;
  }

  /// Fills `x`; leaves it untouched when N bytes do not fit.
  template <size_t N>
  bool bytes(std::array<uint8_t, N>& x) noexcept {
    auto* p = bytes(N);
    if (p == nullptr)
      return false;
    std::memcpy(x.data(), p, N);
    return true;
  }

  /// Assigns the next `n` bytes to `x`; leaves it untouched when they do
  /// not fit (so a hostile length allocates nothing).
  bool str(size_t n, std::string& x) {
    auto* p = bytes(n);
    if (p == nullptr)
      return false;
    x.assign(reinterpret_cast<const char*>(p), n);
    return true;
  }

  /// Everything left (nothing once the reader has failed); the reader is
  /// then at the end.
  void rest(std::vector<uint8_t>& x) {
    if (!ok_) {
      x.clear();
      return;
    }
    x.assign(data_ + pos_, data_ + size_);
    pos_ = size_;
  }

  /// Unsigned LEB128 of at most `max_bytes` bytes (at most 10) and at most
  /// 64 bits. With `minimal`, a number ending in a 0x00 byte (other than
  /// the number 0 itself) is refused. On anything but `ok`, `x` is
  /// untouched, nothing is consumed and the reader has failed.
  leb128_status leb128(uint64_t& x, size_t max_bytes = max_leb128_size,
                       bool minimal = true) noexcept {
    if (!ok_)
      return leb128_status::truncated;
    if (max_bytes > max_leb128_size)
      max_bytes = max_leb128_size;
    uint64_t result = 0;
    for (size_t i = 0; i < max_bytes; ++i) {
      if (i == left()) {
        ok_ = false;
        return leb128_status::truncated;
      }
      auto b = data_[pos_ + i];
      if (i == max_leb128_size - 1 && b > 1)
        break; // bits above 64
      result |= static_cast<uint64_t>(b & 0x7f) << (7 * i);
      if ((b & 0x80) == 0) {
        if (minimal && b == 0 && i > 0) {
          ok_ = false;
          return leb128_status::not_minimal;
        }
        pos_ += i + 1;
        x = result;
        return leb128_status::ok;
      }
    }
    ok_ = false;
    return leb128_status::too_long;
  }

private:
  /// Consumes `n` bytes if they fit, else fails.
  bool take(size_t n) noexcept {
    if (!ok_ || left() < n) {
      ok_ = false;
      return false;
    }
    pos_ += n;
    return true;
  }

  const uint8_t* data_;
  size_t size_;
  size_t pos_;
  bool ok_;
};

/// The reading side of le_writer::u8_counted: why a list of `count`
/// entries of at least `min_entry` (> 0) bytes each cannot follow when
/// `left` bytes are left and at most `max` entries are allowed ("N entries,
/// at most M", or "N entries need at least B bytes, L left"), or empty when
/// it can. A decoder checks this before it allocates for the entries. O(1).
inline std::string counted_list_problem(size_t count, size_t max,
                                        size_t min_entry, size_t left) {
  if (count > max)
    return std::to_string(count) + " entries, at most " + std::to_string(max);
  if (left / min_entry < count) // count * min_entry > left, without overflow
    return std::to_string(count) + " entries need at least "
           + std::to_string(count * min_entry) + " bytes, "
           + std::to_string(left) + " left";
  return {};
}

} // namespace herm
