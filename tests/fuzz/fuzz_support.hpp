#pragma once

// Shared by the fuzz targets of tests/fuzz: a check that makes libFuzzer
// report a failed property as a crash, and a reader that turns the fuzzer's
// bytes into a script (never reads past the end: missing bytes read as 0).

#include <cstddef>
#include <cstdint>
#include <cstdio>

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

} // namespace herm::fuzz
