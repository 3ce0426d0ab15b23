/* hermc_sha256.c: SHA-256 and HMAC-SHA256 (contracts in hermc_sha256.h). */
#include "hermc_sha256.h"

#include <string.h>

/* The round constants live in flash on AVR (const data is copied to RAM
 * there otherwise: 256 bytes of a 4 KB RAM); elsewhere const data already
 * is in flash. */
#if defined(__AVR__)
#include <avr/pgmspace.h>
#define SHA_ROM PROGMEM
#define SHA_ROM_U32(p) pgm_read_dword(p)
#else
#define SHA_ROM
#define SHA_ROM_U32(p) (*(p))
#endif

static const uint32_t round_k[64] SHA_ROM = {
  0x428a2f98ul, 0x71374491ul, 0xb5c0fbcful, 0xe9b5dba5ul, 0x3956c25bul,
  0x59f111f1ul, 0x923f82a4ul, 0xab1c5ed5ul, 0xd807aa98ul, 0x12835b01ul,
  0x243185beul, 0x550c7dc3ul, 0x72be5d74ul, 0x80deb1feul, 0x9bdc06a7ul,
  0xc19bf174ul, 0xe49b69c1ul, 0xefbe4786ul, 0x0fc19dc6ul, 0x240ca1ccul,
  0x2de92c6ful, 0x4a7484aaul, 0x5cb0a9dcul, 0x76f988daul, 0x983e5152ul,
  0xa831c66dul, 0xb00327c8ul, 0xbf597fc7ul, 0xc6e00bf3ul, 0xd5a79147ul,
  0x06ca6351ul, 0x14292967ul, 0x27b70a85ul, 0x2e1b2138ul, 0x4d2c6dfcul,
  0x53380d13ul, 0x650a7354ul, 0x766a0abbul, 0x81c2c92eul, 0x92722c85ul,
  0xa2bfe8a1ul, 0xa81a664bul, 0xc24b8b70ul, 0xc76c51a3ul, 0xd192e819ul,
  0xd6990624ul, 0xf40e3585ul, 0x106aa070ul, 0x19a4c116ul, 0x1e376c08ul,
  0x2748774cul, 0x34b0bcb5ul, 0x391c0cb3ul, 0x4ed8aa4aul, 0x5b9cca4ful,
  0x682e6ff3ul, 0x748f82eeul, 0x78a5636ful, 0x84c87814ul, 0x8cc70208ul,
  0x90befffaul, 0xa4506cebul, 0xbef9a3f7ul, 0xc67178f2ul,
};

static uint32_t ror(uint32_t x, unsigned n) {
  return (x >> n) | (x << (32u - n));
}

static uint32_t get_be32(const uint8_t *p) {
  return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8
         | (uint32_t)p[3];
}

static void put_be32(uint8_t *p, uint32_t x) {
  p[0] = (uint8_t)(x >> 24);
  p[1] = (uint8_t)(x >> 16);
  p[2] = (uint8_t)(x >> 8);
  p[3] = (uint8_t)x;
}

/* Compresses the full block in c->blk into c->h. The block's bytes become
 * the message schedule (16 words, rolling), so the block is used up. */
static void compress(struct hermc_sha256 *c) {
  uint32_t *w = c->blk.w;
  uint32_t s[8];
  uint8_t i, j;
  for (i = 0; i < 16u; ++i)
    w[i] = get_be32(&c->blk.b[4u * i]); /* in place: word i is bytes 4i.. */
  for (j = 0; j < 8u; ++j)
    s[j] = c->h[j];
  for (i = 0; i < 64u; ++i) {
    uint32_t t1, t2;
    if (i >= 16u) {
      uint32_t w15 = w[(i + 1u) & 15u], w2 = w[(i + 14u) & 15u];
      w[i & 15u] += (ror(w15, 7) ^ ror(w15, 18) ^ (w15 >> 3))
                    + w[(i + 9u) & 15u]
                    + (ror(w2, 17) ^ ror(w2, 19) ^ (w2 >> 10));
    }
    t1 = s[7] + (ror(s[4], 6) ^ ror(s[4], 11) ^ ror(s[4], 25))
         + ((s[4] & s[5]) ^ (~s[4] & s[6])) + SHA_ROM_U32(&round_k[i])
         + w[i & 15u];
    t2 = (ror(s[0], 2) ^ ror(s[0], 13) ^ ror(s[0], 22))
         + ((s[0] & s[1]) ^ (s[0] & s[2]) ^ (s[1] & s[2]));
    for (j = 7; j > 0; --j)
      s[j] = s[j - 1u];
    s[4] += t1;
    s[0] = t1 + t2;
  }
  for (j = 0; j < 8u; ++j)
    c->h[j] += s[j];
}

static void set_iv(uint32_t h[8]) {
  h[0] = 0x6a09e667ul;
  h[1] = 0xbb67ae85ul;
  h[2] = 0x3c6ef372ul;
  h[3] = 0xa54ff53aul;
  h[4] = 0x510e527ful;
  h[5] = 0x9b05688cul;
  h[6] = 0x1f83d9abul;
  h[7] = 0x5be0cd19ul;
}

void hermc_sha256_init(struct hermc_sha256 *c) {
  set_iv(c->h);
  c->len = 0;
}

void hermc_sha256_update(struct hermc_sha256 *c, const uint8_t *data,
                         size_t n) {
  size_t fill = c->len & 63u;
  c->len += (uint32_t)n;
  while (n > 0) {
    size_t take = HERMC_SHA256_BLOCK - fill;
    if (take > n)
      take = n;
    memcpy(&c->blk.b[fill], data, take);
    fill += take;
    data += take;
    n -= take;
    if (fill == HERMC_SHA256_BLOCK) {
      compress(c);
      fill = 0;
    }
  }
}

void hermc_sha256_final(struct hermc_sha256 *c,
                        uint8_t out[HERMC_SHA256_SIZE]) {
  uint8_t fill = (uint8_t)(c->len & 63u);
  uint8_t j;
  c->blk.b[fill++] = 0x80u;
  if (fill > 56u) {
    memset(&c->blk.b[fill], 0, HERMC_SHA256_BLOCK - fill);
    compress(c);
    fill = 0;
  }
  memset(&c->blk.b[fill], 0, 56u - fill);
  /* The length in bits, 64-bit big endian, from a 32-bit byte count. */
  put_be32(&c->blk.b[56], c->len >> 29);
  put_be32(&c->blk.b[60], c->len << 3);
  compress(c);
  for (j = 0; j < 8u; ++j)
    put_be32(&out[4u * j], c->h[j]);
}

/* -- HMAC-SHA256 ------------------------------------------------------------- */

/* memset that the compiler may not drop although the buffer dies. */
static void wipe(void *p, size_t n) {
  volatile uint8_t *v = (volatile uint8_t *)p;
  while (n-- > 0)
    *v++ = 0;
}

/* The chaining words after one block: the key block XOR `pad`. */
static void pad_state(struct hermc_sha256 *c, const uint8_t *key,
                      size_t n, uint8_t pad, uint32_t out[8]) {
  uint8_t i;
  set_iv(c->h);
  for (i = 0; i < HERMC_SHA256_BLOCK; ++i)
    c->blk.b[i] = (uint8_t)((i < n ? key[i] : 0u) ^ pad);
  compress(c);
  for (i = 0; i < 8u; ++i)
    out[i] = c->h[i];
}

void hermc_hmac_sha256_key(struct hermc_hmac_key *k, const uint8_t *key,
                           size_t n) {
  struct hermc_sha256 c;
  uint8_t hashed[HERMC_SHA256_SIZE];
  if (n > HERMC_SHA256_BLOCK) {
    hermc_sha256_init(&c);
    hermc_sha256_update(&c, key, n);
    hermc_sha256_final(&c, hashed);
    key = hashed;
    n = HERMC_SHA256_SIZE;
  }
  pad_state(&c, key, n, 0x36u, k->inner);
  pad_state(&c, key, n, 0x5cu, k->outer);
  wipe(&c, sizeof c);
  wipe(hashed, sizeof hashed);
}

void hermc_hmac_sha256_begin(struct hermc_sha256 *c,
                             const struct hermc_hmac_key *k) {
  uint8_t i;
  for (i = 0; i < 8u; ++i)
    c->h[i] = k->inner[i];
  c->len = HERMC_SHA256_BLOCK;
}

void hermc_hmac_sha256_end(struct hermc_sha256 *c,
                           const struct hermc_hmac_key *k,
                           uint8_t out[HERMC_SHA256_SIZE]) {
  uint8_t i;
  hermc_sha256_final(c, out);
  for (i = 0; i < 8u; ++i)
    c->h[i] = k->outer[i];
  c->len = HERMC_SHA256_BLOCK;
  hermc_sha256_update(c, out, HERMC_SHA256_SIZE);
  hermc_sha256_final(c, out);
}

int hermc_equal_ct(const uint8_t *a, const uint8_t *b, size_t n) {
  uint8_t d = 0;
  while (n-- > 0)
    d = (uint8_t)(d | (*a++ ^ *b++));
  return d == 0;
}
