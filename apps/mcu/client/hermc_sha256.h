/* hermc_sha256.h: SHA-256 (FIPS 180-4) and HMAC-SHA256 (RFC 2104) for the
 * HERM C client's authentication trailer (hermc_auth.h; docs/protocol.md,
 * "Authentication").
 *
 * Small rather than fast: one 64-byte block buffer and the eight chaining
 * words per context, the message schedule computed in that block buffer (a
 * rolling window of 16 words, no 64-word array), and no table but the 64
 * round constants (in flash on AVR). Streaming: init, update any number of
 * times in any chunking, final. C99, no heap, no I/O, no recursion.
 *
 * Ownership: every context is the caller's (a struct it allocates); the
 * functions keep no pointer to their arguments after returning. A context
 * is used from one context of execution at a time.
 *
 * Bounds: one message is at most 2^32 - 1 bytes (the length is counted in
 * 32 bits: on an 8-bit core 64-bit arithmetic costs flash). Cost: one
 * compression per 64 bytes (plus one or two for the padding); stack per
 * call about 60 bytes besides the context.
 */
#ifndef HERMC_SHA256_H
#define HERMC_SHA256_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define HERMC_SHA256_SIZE 32u
#define HERMC_SHA256_BLOCK 64u

/** A running hash. Fields are private to hermc_sha256.c. */
struct hermc_sha256 {
  uint32_t h[8];
  /** Bytes hashed so far, modulo 2^32. */
  uint32_t len;
  /** The block under way; the message schedule while it is compressed. */
  union {
    uint8_t b[HERMC_SHA256_BLOCK];
    uint32_t w[HERMC_SHA256_BLOCK / 4u];
  } blk;
};

/** Starts a hash. */
void hermc_sha256_init(struct hermc_sha256 *c);

/** Hashes `data[0..n)` (NULL allowed when n is 0). */
void hermc_sha256_update(struct hermc_sha256 *c, const uint8_t *data,
                         size_t n);

/** Writes the 32-byte digest to `out`. The context is used up (init it
 *  again to hash another message); `out` may not overlap it. */
void hermc_sha256_final(struct hermc_sha256 *c,
                        uint8_t out[HERMC_SHA256_SIZE]);

/* -- HMAC-SHA256 ------------------------------------------------------------- */

/** A key made ready for HMAC: the chaining words after the inner and the
 *  outer padded key block. It holds no copy of the key but is worth as much
 *  as the key to an attacker: keep it where the key would be kept. 64
 *  bytes. Each HMAC then costs two compressions less than from the key. */
struct hermc_hmac_key {
  uint32_t inner[8];
  uint32_t outer[8];
};

/** Prepares `key[0..n)` (any length; longer than 64 bytes is hashed first,
 *  as RFC 2104 says). The padded key block on the stack is wiped before
 *  returning. */
void hermc_hmac_sha256_key(struct hermc_hmac_key *k, const uint8_t *key,
                           size_t n);

/** Starts an HMAC with key `k` in `c`; feed the message with
 *  hermc_sha256_update, then finish with hermc_hmac_sha256_end. */
void hermc_hmac_sha256_begin(struct hermc_sha256 *c,
                             const struct hermc_hmac_key *k);

/** Writes the 32-byte tag to `out` (the context is used up). */
void hermc_hmac_sha256_end(struct hermc_sha256 *c,
                           const struct hermc_hmac_key *k,
                           uint8_t out[HERMC_SHA256_SIZE]);

/** 1 when a[0..n) equals b[0..n), else 0, in time that depends on n only
 *  (for tags and nonces: the position of the first difference leaks
 *  nothing). */
int hermc_equal_ct(const uint8_t *a, const uint8_t *b, size_t n);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_SHA256_H */
