/* hermc_bytes.c: little-endian integers byte by byte (see hermc_bytes.h).
 * Constant shifts only, and 64-bit values as two 32-bit halves, which an
 * 8-bit core does in byte moves. */
#include "hermc_bytes.h"

void hermc_put_u16(uint8_t *p, uint16_t x) {
  p[0] = (uint8_t)x;
  p[1] = (uint8_t)(x >> 8);
}

void hermc_put_u32(uint8_t *p, uint32_t x) {
  p[0] = (uint8_t)x;
  p[1] = (uint8_t)(x >> 8);
  p[2] = (uint8_t)(x >> 16);
  p[3] = (uint8_t)(x >> 24);
}

void hermc_put_u64(uint8_t *p, uint64_t x) {
  hermc_put_u32(p, (uint32_t)x);
  hermc_put_u32(p + 4, (uint32_t)(x >> 32));
}

uint16_t hermc_get_u16(const uint8_t *p) {
  return (uint16_t)((uint16_t)p[0] | (uint16_t)((uint16_t)p[1] << 8));
}

uint32_t hermc_get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16)
         | ((uint32_t)p[3] << 24);
}

uint64_t hermc_get_u64(const uint8_t *p) {
  return (uint64_t)hermc_get_u32(p) | ((uint64_t)hermc_get_u32(p + 4) << 32);
}
