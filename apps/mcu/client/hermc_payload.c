/* hermc_payload.c: APO payload writer and reader (see hermc_payload.h). */
#include "hermc_payload.h"

#include "hermc_bytes.h"

/* -- writer ---------------------------------------------------------------- */

static uint8_t *room(struct hermc_pw *w, size_t k) {
  uint8_t *at;
  if (w->overflow || w->cap - w->len < k) {
    w->overflow = 1;
    return NULL;
  }
  at = w->buf + w->len;
  w->len += k;
  return at;
}

/* Counts and lengths fit 32 bits: no 64-bit arithmetic on small cores. */
static void put_uleb(struct hermc_pw *w, uint32_t x) {
  size_t n = 1;
  uint32_t v = x;
  uint8_t *at;
  while (v >= 0x80u) {
    v >>= 7;
    ++n;
  }
  at = room(w, n);
  if (!at)
    return;
  while (x >= 0x80u) {
    *at++ = (uint8_t)((x & 0x7Fu) | 0x80u);
    x >>= 7;
  }
  *at = (uint8_t)x;
}

void hermc_pw_begin(struct hermc_pw *w, uint8_t *buf, size_t cap,
                    uint32_t count) {
  w->buf = buf;
  w->cap = buf ? cap : 0;
  w->len = 0;
  w->overflow = 0;
  hermc_pw_u8(w, HERMC_PAYLOAD_VERSION);
  put_uleb(w, count);
}

void hermc_pw_element(struct hermc_pw *w, const char *name) {
  size_t n = 0;
  while (name[n] != '\0' && n <= HERMC_PAYLOAD_MAX_NAME)
    ++n;
  if (n == 0 || n > HERMC_PAYLOAD_MAX_NAME) {
    w->overflow = 1;
    return;
  }
  hermc_pw_bytes(w, (const uint8_t *)name, n);
}

void hermc_pw_u8(struct hermc_pw *w, uint8_t x) {
  uint8_t *at = room(w, 1);
  if (at)
    at[0] = x;
}

void hermc_pw_u16(struct hermc_pw *w, uint16_t x) {
  uint8_t *at = room(w, 2);
  if (at)
    hermc_put_u16(at, x);
}

void hermc_pw_u32(struct hermc_pw *w, uint32_t x) {
  uint8_t *at = room(w, 4);
  if (at)
    hermc_put_u32(at, x);
}

void hermc_pw_u64(struct hermc_pw *w, uint64_t x) {
  uint8_t *at = room(w, 8);
  if (at)
    hermc_put_u64(at, x);
}

void hermc_pw_bool(struct hermc_pw *w, int x) {
  hermc_pw_u8(w, x ? 1u : 0u);
}

void hermc_pw_bytes(struct hermc_pw *w, const uint8_t *p, size_t n) {
  uint8_t *at;
  size_t i;
  put_uleb(w, (uint32_t)n); /* a longer n fails room() below */
  at = room(w, n);
  if (at)
    for (i = 0; i < n; ++i)
      at[i] = p[i];
}

void hermc_pw_str(struct hermc_pw *w, const char *s) {
  size_t n = 0;
  while (s[n] != '\0')
    ++n;
  hermc_pw_bytes(w, (const uint8_t *)s, n);
}

size_t hermc_pw_finish(const struct hermc_pw *w) {
  return w->overflow ? 0 : w->len;
}

/* -- reader ---------------------------------------------------------------- */

static const uint8_t *take(struct hermc_pr *r, size_t k) {
  const uint8_t *at;
  if (r->error != HERMC_PR_OK)
    return NULL;
  if (r->n - r->at < k) {
    r->error = HERMC_PR_TRUNCATED;
    return NULL;
  }
  at = r->p + r->at;
  r->at += k;
  return at;
}

/* A LEB128 count or length, refused above the bytes left. */
static size_t get_length(struct hermc_pr *r) {
  uint64_t x = 0;
  size_t k;
  if (r->error != HERMC_PR_OK)
    return 0;
  k = hermc_get_uleb(r->p + r->at, r->n - r->at, &x);
  if (k == 0) {
    /* Ran out of bytes (every byte left continues, fewer than 10), or a
     * bad form. */
    size_t i = r->at;
    while (i < r->n && i - r->at < 10u && (r->p[i] & 0x80u) != 0)
      ++i;
    r->error = i == r->n && i - r->at < 10u ? HERMC_PR_TRUNCATED
                                             : HERMC_PR_BAD_LEB128;
    return 0;
  }
  r->at += k;
  if (x > r->n - r->at) {
    r->error = HERMC_PR_OVER_BOUND;
    return 0;
  }
  return (size_t)x;
}

uint32_t hermc_pr_begin(struct hermc_pr *r, const uint8_t *p, size_t n) {
  const uint8_t *v;
  size_t count;
  r->p = p;
  r->n = p ? n : 0;
  r->at = 0;
  r->error = HERMC_PR_OK;
  v = take(r, 1);
  if (v && v[0] != HERMC_PAYLOAD_VERSION)
    r->error = HERMC_PR_BAD_VERSION;
  count = get_length(r);
  return r->error == HERMC_PR_OK ? (uint32_t)count : 0;
}

int hermc_pr_element(struct hermc_pr *r, const char *name) {
  const uint8_t *got;
  size_t n, i;
  hermc_pr_bytes(r, &got, &n);
  if (r->error != HERMC_PR_OK)
    return 0;
  for (i = 0; i < n; ++i)
    if (name[i] == '\0' || (uint8_t)name[i] != got[i])
      break;
  if (i != n || name[n] != '\0') {
    r->error = HERMC_PR_WRONG_TYPE;
    return 0;
  }
  return 1;
}

uint8_t hermc_pr_u8(struct hermc_pr *r) {
  const uint8_t *at = take(r, 1);
  return at ? at[0] : 0;
}

uint16_t hermc_pr_u16(struct hermc_pr *r) {
  const uint8_t *at = take(r, 2);
  return at ? hermc_get_u16(at) : 0;
}

uint32_t hermc_pr_u32(struct hermc_pr *r) {
  const uint8_t *at = take(r, 4);
  return at ? hermc_get_u32(at) : 0;
}

uint64_t hermc_pr_u64(struct hermc_pr *r) {
  const uint8_t *at = take(r, 8);
  return at ? hermc_get_u64(at) : 0;
}

int hermc_pr_bool(struct hermc_pr *r) {
  uint8_t b = hermc_pr_u8(r);
  if (r->error == HERMC_PR_OK && b > 1u) {
    r->error = HERMC_PR_BAD_BOOL;
    return 0;
  }
  return b;
}

void hermc_pr_bytes(struct hermc_pr *r, const uint8_t **p, size_t *n) {
  size_t len = get_length(r);
  const uint8_t *at = take(r, len);
  *p = at;
  *n = at ? len : 0;
}

enum hermc_payload_error hermc_pr_finish(struct hermc_pr *r) {
  if (r->error == HERMC_PR_OK && r->at != r->n)
    r->error = HERMC_PR_TRAILING;
  return r->error;
}

/* -- SRF04 reading --------------------------------------------------------- */

/* The reading's layout is fixed: version 1, one element, the type name,
 * then the fields; written directly, so that a board sending only readings
 * links no payload writer. The bytes are those of the hermc_pw_* calls
 * (payload_test checks both against the C++ encoder). */
size_t hermc_srf04_encode(const struct hermc_srf04_reading *x, uint8_t *out,
                          size_t cap) {
  static const char type[] = HERMC_SRF04_TYPE;
  size_t i;
  if (cap < HERMC_SRF04_SIZE)
    return 0;
  out[0] = HERMC_PAYLOAD_VERSION;
  out[1] = 1u;
  out[2] = (uint8_t)(sizeof type - 1u);
  for (i = 0; i < sizeof type - 1u; ++i)
    out[3u + i] = (uint8_t)type[i];
  hermc_put_u16(out + 2u + sizeof type, x->seq);
  hermc_put_u16(out + 4u + sizeof type, x->distance_mm);
  hermc_put_u32(out + 6u + sizeof type, x->echo_us);
  return HERMC_SRF04_SIZE;
}

enum hermc_payload_error hermc_srf04_decode(const uint8_t *p, size_t n,
                                            struct hermc_srf04_reading *x) {
  struct hermc_pr r;
  uint32_t count = hermc_pr_begin(&r, p, n);
  if (r.error == HERMC_PR_OK && count != 1u)
    r.error = HERMC_PR_WRONG_TYPE;
  hermc_pr_element(&r, HERMC_SRF04_TYPE);
  x->seq = hermc_pr_u16(&r);
  x->distance_mm = hermc_pr_u16(&r);
  x->echo_us = hermc_pr_u32(&r);
  return hermc_pr_finish(&r);
}
