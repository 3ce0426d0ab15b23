/* hermc_bytes.h: little-endian integers and unsigned LEB128, byte by byte
 * with shifts (never memcpy of a struct), for the hermc codecs.
 *
 * Internal to hermc (the network, APO message and APO payload codecs); an
 * application has no need to include it. C99, no heap, no I/O. Every reader checks its bounds against `n` and reports a
 * short input instead of reading past it.
 */
#ifndef HERMC_BYTES_H
#define HERMC_BYTES_H

#include <stddef.h>
#include <stdint.h>

/* Little-endian integers at p (room is the caller's). Out of line, in
 * hermc_bytes.c: on an 8-bit core every inlined 64-bit shift costs flash. */
void hermc_put_u16(uint8_t *p, uint16_t x);
void hermc_put_u32(uint8_t *p, uint32_t x);
void hermc_put_u64(uint8_t *p, uint64_t x);
uint16_t hermc_get_u16(const uint8_t *p);
uint32_t hermc_get_u32(const uint8_t *p);
uint64_t hermc_get_u64(const uint8_t *p);

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
