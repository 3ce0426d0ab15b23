#pragma once

// Shared by the fuzz targets of tests/fuzz: a check that makes libFuzzer
// report a failed property as a crash, and a reader that turns the fuzzer's
// bytes into a script (never reads past the end: missing bytes read as 0).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <vector>

/// Fails the run when `cond` is false: prints the property, then traps, so
/// that libFuzzer saves the input as a crash.
#define HERM_FUZZ_CHECK(cond)                                                  \
  do {                                                                         \
    if (!(cond)) {                                                             \
      std::fprintf(stderr, "%s:%d: property violated: %s\n", __FILE__,         \
                   __LINE__, #cond);                                           \
      __builtin_trap();                                                        \
    }                                                                          \
  } while (false)

namespace herm::fuzz {

/// Consumes the fuzzer's bytes front to back.
struct reader {
  const uint8_t* data;
  size_t size;

  bool empty() const {
    return size == 0;
  }

  uint8_t u8() {
    if (size == 0)
      return 0;
    --size;
    return *data++;
  }

  uint16_t u16() {
    auto lo = u8();
    return static_cast<uint16_t>(lo | u8() << 8);
  }

  uint64_t u64() {
    uint64_t x = 0;
    for (int i = 0; i < 8; ++i)
      x |= uint64_t{u8()} << (8 * i);
    return x;
  }

  /// Up to `n` bytes (fewer at the end); the returned pointer stays valid.
  const uint8_t* take(size_t& n) {
    if (n > size)
      n = size;
    auto* p = data;
    data += n;
    size -= n;
    return p;
  }
};

/// One edit of a packet, read from the fuzzer's bytes (position, kind,
/// value): flip bits, set a byte, cut the end short, or append bytes.
struct mutation {
  uint16_t pos = 0;
  uint8_t kind = 0;
  uint8_t value = 0;

  static mutation read(reader& in) {
    mutation m;
    m.pos = in.u16();
    m.kind = in.u8();
    m.value = in.u8();
    return m;
  }

  void apply(std::vector<uint8_t>& bytes) const {
    switch (kind % 4) {
      case 0: // flip bits
        if (!bytes.empty())
          bytes[pos % bytes.size()] ^= static_cast<uint8_t>(value | 1);
        break;
      case 1: // set a byte
        if (!bytes.empty())
          bytes[pos % bytes.size()] = value;
        break;
      case 2: // cut short
        bytes.resize(bytes.size() - std::min<size_t>(bytes.size(), value % 32 + 1));
        break;
      default: // append
        bytes.insert(bytes.end(), value % 32 + 1, value);
        break;
    }
  }
};

} // namespace herm::fuzz
