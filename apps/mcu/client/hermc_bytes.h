/* hermc_bytes.h: little-endian integers and unsigned LEB128, byte by byte
 * with shifts (never memcpy of a struct), for the hermc codecs.
 *
 * Internal to hermc (the network, APO message and APO payload codecs); an
 * application has no need to include it. Header-only (static inline), C99,
 * no heap, no I/O. Every reader checks its bounds against `n` and reports a
 * short input instead of reading past it.
 */
#ifndef HERMC_BYTES_H
#define HERMC_BYTES_H

#include <stddef.h>
#include <stdint.h>

static inline void hermc_put_u16(uint8_t *p, uint16_t x) {
  p[0] = (uint8_t)(x & 0xFFu);
  p[1] = (uint8_t)(x >> 8);
}

static inline void hermc_put_u32(uint8_t *p, uint32_t x) {
  uint8_t i;
  for (i = 0; i < 4u; ++i)
    p[i] = (uint8_t)((x >> (8u * i)) & 0xFFu);
}

static inline void hermc_put_u64(uint8_t *p, uint64_t x) {
  uint8_t i;
  for (i = 0; i < 8u; ++i)
    p[i] = (uint8_t)((x >> (8u * i)) & 0xFFu);
}

static inline uint16_t hermc_get_u16(const uint8_t *p) {
  return (uint16_t)((uint16_t)p[0] | (uint16_t)((uint16_t)p[1] << 8));
}

static inline uint32_t hermc_get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16)
         | ((uint32_t)p[3] << 24);
}

static inline uint64_t hermc_get_u64(const uint8_t *p) {
  uint64_t x = 0;
  uint8_t i;
  for (i = 8; i > 0; --i)
    x = (x << 8) | p[i - 1u];
  return x;
}

/* Bytes the shortest LEB128 encoding of `x` takes (1..10). */
static inline size_t hermc_uleb_size(uint64_t x) {
  size_t n = 1;
  while (x >= 0x80u) {
    x >>= 7;
    ++n;
  }
  return n;
}

/* Writes the shortest LEB128 encoding of `x` at `p` (room for
 * hermc_uleb_size(x) bytes is the caller's); returns the bytes written. */
static inline size_t hermc_put_uleb(uint8_t *p, uint64_t x) {
  size_t n = 0;
  while (x >= 0x80u) {
    p[n++] = (uint8_t)((x & 0x7Fu) | 0x80u);
    x >>= 7;
  }
  p[n++] = (uint8_t)x;
  return n;
}

/* Reads a canonical (shortest) unsigned LEB128 of at most 10 bytes (64
 * bits) from p[0..n). Returns the bytes read, or 0 when it runs past `n`,
 * is longer than 10 bytes, overflows 64 bits or is not the shortest form
 * (a last byte 00 after the first): the APO payload rules
 * (docs/protocol.md, "LEB128"). */
static inline size_t hermc_get_uleb(const uint8_t *p, size_t n,
                                      uint64_t *x) {
  uint64_t v = 0;
  size_t i;
  for (i = 0; i < n && i < 10u; ++i) {
    uint8_t b = p[i];
    if (i == 9u && b > 1u)
      return 0;
    v |= (uint64_t)(b & 0x7Fu) << (7u * i);
    if ((b & 0x80u) == 0) {
      if (i > 0 && b == 0)
        return 0;
      *x = v;
      return i + 1u;
    }
  }
  return 0;
}

#endif /* HERMC_BYTES_H */
