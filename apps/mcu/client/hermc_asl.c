/* hermc_asl.c: APO message codec (see hermc_asl.h). */
#include "hermc_asl.h"

#include <string.h>

#include "hermc_bytes.h"

/* A bounded reader over the message; `bad` sticks at the first error. */
struct rd {
  const uint8_t *p;
  size_t n;
  size_t at;
  enum hermc_asl_error bad;
};

static int need(struct rd *r, size_t k) {
  if (r->bad != HERMC_ASL_OK)
    return 0;
  if (r->n - r->at < k) {
    r->bad = HERMC_ASL_TRUNCATED;
    return 0;
  }
  return 1;
}

static uint8_t rd_u8(struct rd *r) {
  return need(r, 1) ? r->p[r->at++] : 0;
}

static uint32_t rd_u32(struct rd *r) {
  uint32_t x = 0;
  if (need(r, 4)) {
    x = hermc_get_u32(r->p + r->at);
    r->at += 4;
  }
  return x;
}

static uint64_t rd_u64(struct rd *r) {
  uint64_t x = 0;
  if (need(r, 8)) {
    x = hermc_get_u64(r->p + r->at);
    r->at += 8;
  }
  return x;
}

static uint8_t rd_bool(struct rd *r) {
  uint8_t b = rd_u8(r);
  if (r->bad == HERMC_ASL_OK && b > 1u)
    r->bad = HERMC_ASL_BAD_BOOL;
  return b;
}

static struct hermc_bytes rd_string(struct rd *r) {
  struct hermc_bytes s = {NULL, 0};
  uint8_t len = rd_u8(r);
  if (need(r, len)) {
    s.data = r->p + r->at;
    s.size = len;
    r->at += len;
  }
  return s;
}

static struct hermc_bytes rd_rest(struct rd *r) {
  struct hermc_bytes s;
  s.data = r->p + r->at;
  s.size = r->n - r->at;
  r->at = r->n;
  return s;
}

static void rd_error(struct rd *r, struct hermc_asl_msg *m) {
  m->err_category = rd_u64(r);
  m->err_code = rd_u8(r);
  m->text = rd_string(r);
}

/* -- the decoder: one layout per kind ---------------------------------------
 *
 * Each kind's fields are a layout of up to four 4-bit field codes, read
 * from the low nibble up (0 ends it). One loop walks it: the fields, their
 * order and their checks are those of docs/protocol.md and
 * actors/asl_wire.cpp, and the first error found is the one returned. */
enum field {
  F_END = 0,
  F_ID32,    /* id32 = u32 */
  F_BY,      /* by = u8, at most HERMC_BY_ANY (else BAD_QUERY_BY) */
  F_TEXT,    /* text = string */
  F_NO_PAT,  /* by any takes no pattern (else PATTERN_ON_ANY) */
  F_ENTRIES, /* count = u8 (at most 64), then count answer entries */
  F_RID,     /* request_id = u64; 0 makes it one-way */
  F_RID_NZ,  /* request_id = u64, not 0 (else ZERO_REQUEST_ID) */
  F_ONEWAY,  /* oneway = bool */
  F_PAYLOAD, /* payload = the rest */
  F_RESULT,  /* ok = bool, then the payload (ok) or an error (not ok) */
  F_ERROR,   /* err_category = u64, err_code = u8, text = string */
  F_U32      /* u32 = u32 */
};

/* Unsigned operands: with a 16-bit int (AVR) `9 << 12` overflows int. */
#define LAYOUT(a, b, c, d)                                                \
  (uint16_t)((unsigned)(a) | (unsigned)(b) << 4 | (unsigned)(c) << 8    \
             | (unsigned)(d) << 12)

/* Indexed by kind - 1 (HERMC_ASL_QUERY .. HERMC_ASL_ACK). In flash on AVR,
 * where const data would otherwise be copied to RAM. */
#if defined(__AVR__)
#include <avr/pgmspace.h>
#define LAYOUTS_ROM PROGMEM
#define LAYOUT_OF(k) pgm_read_word(&layouts[(k) - 1u])
#else
#define LAYOUTS_ROM
#define LAYOUT_OF(k) (layouts[(k) - 1u])
#endif
static const uint16_t layouts[HERMC_ASL_ACK] LAYOUTS_ROM = {
  LAYOUT(F_ID32, F_BY, F_TEXT, F_NO_PAT),        /* query */
  LAYOUT(F_ID32, F_ENTRIES, 0, 0),               /* answer */
  LAYOUT(F_RID, F_ID32, F_PAYLOAD, 0),           /* request */
  LAYOUT(F_RID_NZ, F_RESULT, 0, 0),              /* response */
  LAYOUT(F_ID32, 0, 0, 0),                       /* watch */
  LAYOUT(F_ID32, 0, 0, 0),                       /* unwatch */
  LAYOUT(F_ID32, F_ERROR, 0, 0),                 /* down */
  LAYOUT(F_ID32, F_TEXT, 0, 0),                  /* withdraw */
  LAYOUT(F_TEXT, F_U32, 0, 0),                   /* subscribe */
  LAYOUT(F_TEXT, 0, 0, 0),                       /* unsubscribe */
  LAYOUT(F_TEXT, F_U32, F_PAYLOAD, 0),           /* publish */
  LAYOUT(F_TEXT, 0, 0, 0),                       /* advertise */
  LAYOUT(F_RID_NZ, F_ID32, F_ONEWAY, F_PAYLOAD), /* reliable request */
  LAYOUT(F_RID_NZ, 0, 0, 0),                     /* ack */
};

/* Reads the count and the entries of an answer (their bytes in entries). */
static enum hermc_asl_error rd_entries(struct rd *r, struct hermc_asl_msg *m) {
  size_t start;
  uint8_t i;
  m->count = rd_u8(r);
  if (r->bad != HERMC_ASL_OK)
    return r->bad;
  if (m->count > HERMC_ASL_MAX_ANSWER_ENTRIES)
    return HERMC_ASL_OVER_BOUND;
  if ((size_t)m->count * 6u > r->n - r->at)
    return HERMC_ASL_TRUNCATED;
  start = r->at;
  for (i = 0; i < m->count && r->bad == HERMC_ASL_OK; ++i) {
    (void)rd_u32(r);
    (void)rd_string(r);
    (void)rd_string(r);
  }
  m->entries.data = r->p + start;
  m->entries.size = r->at - start;
  return r->bad;
}

enum hermc_asl_error hermc_asl_decode(const uint8_t *p, size_t n,
                                      struct hermc_asl_msg *m) {
  struct rd r;
  uint16_t layout;
  r.p = p;
  r.n = n;
  r.at = 2;
  r.bad = HERMC_ASL_OK;
  /* Every field zero, every byte string {NULL, 0}. */
  memset(m, 0, sizeof *m);
  m->text.data = NULL;
  m->payload = m->text;
  m->entries = m->text;
  if (n == 0)
    return HERMC_ASL_EMPTY;
  if (p[0] != HERMC_ASL_VERSION)
    return HERMC_ASL_BAD_VERSION;
  if (n < 2)
    return HERMC_ASL_TRUNCATED;
  if (p[1] < HERMC_ASL_QUERY || p[1] > HERMC_ASL_ACK)
    return HERMC_ASL_BAD_KIND;
  m->kind = (enum hermc_asl_kind)p[1];
  for (layout = LAYOUT_OF(p[1]); layout != 0 && r.bad == HERMC_ASL_OK;
       layout = (uint16_t)(layout >> 4)) {
    switch (layout & 0x0Fu) {
      case F_ID32:
        m->id32 = rd_u32(&r);
        break;
      case F_BY:
        m->by = rd_u8(&r);
        if (r.bad == HERMC_ASL_OK && m->by > HERMC_BY_ANY)
          return HERMC_ASL_BAD_QUERY_BY;
        break;
      case F_TEXT:
        m->text = rd_string(&r);
        break;
      case F_NO_PAT:
        if (m->by == HERMC_BY_ANY && m->text.size > 0)
          return HERMC_ASL_PATTERN_ON_ANY;
        break;
      case F_ENTRIES: {
        enum hermc_asl_error e = rd_entries(&r, m);
        if (e != HERMC_ASL_OK)
          return e;
        break;
      }
      case F_RID:
      case F_RID_NZ:
        m->request_id = rd_u64(&r);
        m->oneway = (uint8_t)(m->request_id == 0);
        if (r.bad == HERMC_ASL_OK && m->oneway && (layout & 0x0Fu) == F_RID_NZ)
          return HERMC_ASL_ZERO_REQUEST_ID;
        break;
      case F_ONEWAY:
        m->oneway = rd_bool(&r);
        break;
      case F_RESULT:
        m->ok = rd_bool(&r);
        if (r.bad != HERMC_ASL_OK)
          break;
        if (m->ok)
          m->payload = rd_rest(&r);
        else
          rd_error(&r, m);
        break;
      case F_PAYLOAD:
        m->payload = rd_rest(&r);
        break;
      case F_ERROR:
        rd_error(&r, m);
        break;
      default: /* F_U32 */
        m->u32 = rd_u32(&r);
        break;
    }
  }
  if (r.bad != HERMC_ASL_OK)
    return r.bad;
  return r.at == n ? HERMC_ASL_OK : HERMC_ASL_TRAILING;
}

int hermc_asl_answer_entry(const struct hermc_asl_msg *m, size_t *at,
                           struct hermc_asl_entry *e) {
  struct rd r;
  if (m->kind != HERMC_ASL_ANSWER || *at >= m->entries.size)
    return 0;
  r.p = m->entries.data;
  r.n = m->entries.size;
  r.at = *at;
  r.bad = HERMC_ASL_OK;
  e->apo = rd_u32(&r);
  e->name = rd_string(&r);
  e->type = rd_string(&r);
  if (r.bad != HERMC_ASL_OK)
    return 0;
  *at = r.at;
  return 1;
}

/* -- encoders -------------------------------------------------------------- */

static size_t put_string(uint8_t *out, const char *s, size_t len) {
  size_t i;
  out[0] = (uint8_t)len;
  for (i = 0; i < len; ++i)
    out[1 + i] = (uint8_t)s[i];
  return 1 + len;
}

size_t hermc_asl_query_encode(uint32_t query_id, enum hermc_query_by by,
                              const char *pattern, size_t pattern_len,
                              uint8_t *out, size_t cap) {
  if (by == HERMC_BY_ANY)
    pattern_len = 0;
  if (pattern_len > HERMC_ASL_MAX_STRING || cap < 8u + pattern_len)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_QUERY;
  hermc_put_u32(out + 2, query_id);
  out[6] = (uint8_t)by;
  return 7u + put_string(out + 7, pattern, pattern_len);
}

size_t hermc_asl_answer_begin(uint32_t query_id, uint8_t count, uint8_t *out,
                              size_t cap) {
  if (count > HERMC_ASL_MAX_ANSWER_ENTRIES || cap < 7u)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_ANSWER;
  hermc_put_u32(out + 2, query_id);
  out[6] = count;
  return 7u;
}

size_t hermc_asl_answer_entry_encode(uint32_t apo, const char *name,
                                     size_t name_len, const char *type,
                                     size_t type_len, uint8_t *out,
                                     size_t cap) {
  size_t at = 4;
  if (name_len > HERMC_ASL_MAX_STRING || type_len > HERMC_ASL_MAX_STRING
      || cap < 6u + name_len + type_len)
    return 0;
  hermc_put_u32(out, apo);
  at += put_string(out + at, name, name_len);
  at += put_string(out + at, type, type_len);
  return at;
}

size_t hermc_asl_request_header(uint64_t request_id, uint32_t apo,
                                int reliable, int oneway, uint8_t *out,
                                size_t cap) {
  size_t size = reliable ? 15u : 14u;
  if (cap < size || (reliable && request_id == 0))
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = reliable ? HERMC_ASL_RELIABLE_REQUEST : HERMC_ASL_REQUEST;
  hermc_put_u64(out + 2, request_id);
  hermc_put_u32(out + 10, apo);
  if (reliable)
    out[14] = oneway ? 1u : 0u;
  return size;
}

size_t hermc_asl_response_ok_header(uint64_t request_id, uint8_t *out,
                                    size_t cap) {
  if (cap < 11u || request_id == 0)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_RESPONSE;
  hermc_put_u64(out + 2, request_id);
  out[10] = 1;
  return 11u;
}

size_t hermc_asl_response_error_encode(uint64_t request_id, uint64_t category,
                                       uint8_t code, const char *context,
                                       size_t context_len, uint8_t *out,
                                       size_t cap) {
  if (context_len > HERMC_ASL_MAX_STRING)
    context_len = HERMC_ASL_MAX_STRING;
  if (cap < 21u + context_len || request_id == 0)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_RESPONSE;
  hermc_put_u64(out + 2, request_id);
  out[10] = 0;
  hermc_put_u64(out + 11, category);
  out[19] = code;
  return 20u + put_string(out + 20, context, context_len);
}

size_t hermc_asl_subscribe_encode(const char *topic, size_t topic_len,
                                  uint32_t lease_ms, uint8_t *out,
                                  size_t cap) {
  size_t at;
  if (topic_len > HERMC_ASL_MAX_STRING || cap < 7u + topic_len)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_SUBSCRIBE;
  at = 2u + put_string(out + 2, topic, topic_len);
  hermc_put_u32(out + at, lease_ms);
  return at + 4u;
}

size_t hermc_asl_publish_header(const char *topic, size_t topic_len,
                                uint32_t seq, uint8_t *out, size_t cap) {
  size_t at;
  if (topic_len > HERMC_ASL_MAX_STRING || cap < 7u + topic_len)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_PUBLISH;
  at = 2u + put_string(out + 2, topic, topic_len);
  hermc_put_u32(out + at, seq);
  return at + 4u;
}

size_t hermc_asl_advertise_encode(const char *topic, size_t topic_len,
                                  uint8_t *out, size_t cap) {
  if (topic_len > HERMC_ASL_MAX_STRING || cap < 3u + topic_len)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_ADVERTISE;
  return 2u + put_string(out + 2, topic, topic_len);
}

size_t hermc_asl_ack_encode(uint64_t request_id, uint8_t *out, size_t cap) {
  if (cap < 10u || request_id == 0)
    return 0;
  out[0] = HERMC_ASL_VERSION;
  out[1] = HERMC_ASL_ACK;
  hermc_put_u64(out + 2, request_id);
  return 10u;
}
