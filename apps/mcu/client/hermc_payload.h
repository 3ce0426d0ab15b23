/* hermc_payload.h: APO payloads (docs/protocol.md, "APO payloads"), the
 * standard encoding of the values APOs exchange: version 1, a LEB128
 * element count, then per element a LEB128-prefixed type name and the
 * fields in `inspect` order, integers little endian, strings and byte
 * sequences with a LEB128 length. The C++ peer is actors/marshal.hpp; the
 * golden string of tests/actors/marshal_test.cpp pins both.
 *
 * Writer: the caller owns the buffer; every write checks the room left and
 * a write that does not fit sets `overflow` (sticky) and writes nothing
 * more, so a sequence of writes needs one check at the end
 * (hermc_pw_finish). The writer only produces canonical encodings (shortest
 * LEB128, bools 00/01), which a strict HERM receiver requires.
 *
 * Reader: bounded by the payload's size; every read checks the bytes left
 * first, and the first failure sets `error` (sticky; later reads return 0
 * and read nothing). Strict like the C++ decoder where it matters for a
 * leaf: version 1, shortest LEB128, bools 00/01, a count and lengths not
 * above the bytes left, no trailing bytes (hermc_pr_finish). Strings and
 * byte sequences are returned as pointers into the payload (no copy).
 * No heap, no recursion, O(bytes) per call.
 */
#ifndef HERMC_PAYLOAD_H
#define HERMC_PAYLOAD_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define HERMC_PAYLOAD_VERSION 1u
/* Longest type name (docs/protocol.md, "Payload layout"). */
#define HERMC_PAYLOAD_MAX_NAME 255u

struct hermc_pw {
  uint8_t *buf;
  size_t cap;
  size_t len;
  uint8_t overflow;
};

/* Starts a payload of `count` elements in buf[0..cap). */
void hermc_pw_begin(struct hermc_pw *w, uint8_t *buf, size_t cap,
                    uint32_t count);
/* Starts an element of type `name` (1..255 bytes; else overflow is set). */
void hermc_pw_element(struct hermc_pw *w, const char *name);
void hermc_pw_u8(struct hermc_pw *w, uint8_t x);
void hermc_pw_u16(struct hermc_pw *w, uint16_t x);
void hermc_pw_u32(struct hermc_pw *w, uint32_t x);
void hermc_pw_u64(struct hermc_pw *w, uint64_t x);
void hermc_pw_bool(struct hermc_pw *w, int x);
/* A string (std::string) or byte sequence (std::vector<uint8_t>): LEB128
 * length, then the bytes. */
void hermc_pw_bytes(struct hermc_pw *w, const uint8_t *p, size_t n);
void hermc_pw_str(struct hermc_pw *w, const char *s);
/* The payload's length, or 0 if anything overflowed. */
size_t hermc_pw_finish(const struct hermc_pw *w);

enum hermc_payload_error {
  HERMC_PR_OK = 0,
  HERMC_PR_BAD_VERSION,
  HERMC_PR_TRUNCATED,     /* a value needs more bytes than are left */
  HERMC_PR_BAD_LEB128,    /* not the shortest form, or above 64 bits */
  HERMC_PR_OVER_BOUND,    /* a count or length above the bytes left */
  HERMC_PR_BAD_BOOL,
  HERMC_PR_WRONG_TYPE,    /* an element of another type than expected */
  HERMC_PR_TRAILING       /* bytes after the last element */
};

struct hermc_pr {
  const uint8_t *p;
  size_t n;
  size_t at;
  enum hermc_payload_error error;
};

/* Starts reading payload p[0..n); returns its element count (0 on error). */
uint32_t hermc_pr_begin(struct hermc_pr *r, const uint8_t *p, size_t n);
/* Reads the next element's type name and checks it equals `name` (else
 * HERMC_PR_WRONG_TYPE). Returns 1 when it does. */
int hermc_pr_element(struct hermc_pr *r, const char *name);
uint8_t hermc_pr_u8(struct hermc_pr *r);
uint16_t hermc_pr_u16(struct hermc_pr *r);
uint32_t hermc_pr_u32(struct hermc_pr *r);
uint64_t hermc_pr_u64(struct hermc_pr *r);
int hermc_pr_bool(struct hermc_pr *r);
/* A string or byte sequence: `*n` bytes at `*p` inside the payload. */
void hermc_pr_bytes(struct hermc_pr *r, const uint8_t **p, size_t *n);
/* HERMC_PR_OK when every read succeeded and no byte is left. */
enum hermc_payload_error hermc_pr_finish(struct hermc_pr *r);

/* -- the SRF04 board's reading ------------------------------------------- */

/* Type name the C++ side registers for the reading. */
#define HERMC_SRF04_TYPE "herm::hermd::srf04_reading"

struct hermc_srf04_reading {
  uint16_t seq;
  uint16_t distance_mm;
  uint32_t echo_us;
};

/* The encoded reading's size, bytes: version, count, the type name with its
 * length, 8 bytes of fields. */
#define HERMC_SRF04_SIZE 37u

/* One element `herm::hermd::srf04_reading` (hermd registers the type,
 * apps/hermd/testbed_types.hpp) {seq: u16, distance_mm: u16, echo_us:
 * u32}: HERMC_SRF04_SIZE bytes. Returns the length, or 0 when cap is too
 * small. */
size_t hermc_srf04_encode(const struct hermc_srf04_reading *x, uint8_t *out,
                          size_t cap);
/* Reads exactly that payload back; HERMC_PR_OK or what was wrong. */
enum hermc_payload_error hermc_srf04_decode(const uint8_t *p, size_t n,
                                            struct hermc_srf04_reading *x);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_PAYLOAD_H */
