/* hermc_net.c: network packet codecs (see hermc_net.h). */
#include "hermc_net.h"

#include "hermc_bytes.h"

#define HERMC_NET_VERSION 0x10u

static const uint32_t class_bytes[HERMC_SIZE_CLASSES] = {8u, 64u, 1024u,
                                                         65536u};

enum hermc_net_error hermc_peek_type(const uint8_t *p, size_t n,
                                     enum hermc_packet_type *type) {
  if (n == 0)
    return HERMC_NET_EMPTY;
  if ((p[0] & 0xF0u) != HERMC_NET_VERSION)
    return HERMC_NET_BAD_VERSION;
  if ((p[0] & 0x0Fu) > 7u)
    return HERMC_NET_BAD_TYPE;
  *type = (enum hermc_packet_type)(p[0] & 0x0Fu);
  return HERMC_NET_OK;
}

/* The first byte is type `t` and the packet exactly `size` bytes long. */
static enum hermc_net_error check_control(const uint8_t *p, size_t n,
                                          enum hermc_packet_type t,
                                          size_t size) {
  enum hermc_packet_type got;
  enum hermc_net_error e = hermc_peek_type(p, n, &got);
  if (e != HERMC_NET_OK)
    return e;
  if (got != t)
    return HERMC_NET_BAD_TYPE;
  if (n < size)
    return HERMC_NET_TRUNCATED;
  if (n > size)
    return HERMC_NET_TRAILING;
  return HERMC_NET_OK;
}

/* -- data ---------------------------------------------------------------- */

uint8_t hermc_size_class_of(size_t bytes) {
  uint8_t k;
  for (k = 0; k < HERMC_SIZE_CLASSES; ++k)
    if (bytes <= class_bytes[k])
      return k;
  return HERMC_SIZE_CLASSES - 1u;
}

size_t hermc_data_header_encode(const struct hermc_data_header *h,
                                uint8_t *out, size_t cap) {
  size_t size = h->flood_id != 0 ? HERMC_FLOOD_HEADER_SIZE
                                 : HERMC_DATA_HEADER_SIZE;
  uint8_t flags;
  if (cap < size)
    return 0;
  flags = (uint8_t)(((h->priority & 3u) << 2) | (h->size_class & 3u));
  if (h->flood_id != 0)
    flags = (uint8_t)(flags | 0x10u);
  if (h->authenticated)
    flags = (uint8_t)(flags | 0x20u);
  out[0] = HERMC_NET_VERSION | HERMC_PT_DATA;
  hermc_put_u16(out + 1, h->src);
  hermc_put_u16(out + 3, h->dst);
  out[5] = h->hop_limit;
  out[6] = flags;
  out[7] = h->protocol;
  if (h->flood_id != 0)
    hermc_put_u32(out + 8, h->flood_id);
  return size;
}

enum hermc_net_error hermc_data_header_decode(const uint8_t *p, size_t n,
                                              struct hermc_data_header *h,
                                              size_t *payload_at) {
  enum hermc_packet_type t;
  enum hermc_net_error e = hermc_peek_type(p, n, &t);
  uint8_t flags;
  if (e != HERMC_NET_OK)
    return e;
  if (t != HERMC_PT_DATA)
    return HERMC_NET_BAD_TYPE;
  if (n < HERMC_DATA_HEADER_SIZE)
    return HERMC_NET_TRUNCATED;
  flags = p[6];
  if ((flags & 0xC0u) != 0)
    return HERMC_NET_RESERVED;
  h->src = hermc_get_u16(p + 1);
  h->dst = hermc_get_u16(p + 3);
  h->hop_limit = p[5];
  h->size_class = (uint8_t)(flags & 3u);
  h->priority = (uint8_t)((flags >> 2) & 3u);
  h->authenticated = (uint8_t)((flags >> 5) & 1u);
  h->protocol = p[7];
  h->flood_id = 0;
  *payload_at = HERMC_DATA_HEADER_SIZE;
  if (flags & 0x10u) {
    if (h->dst != HERMC_BROADCAST)
      return HERMC_NET_BAD_FLOOD;
    if (n < HERMC_FLOOD_HEADER_SIZE)
      return HERMC_NET_TRUNCATED;
    h->flood_id = hermc_get_u32(p + 8);
    if (h->flood_id == 0)
      return HERMC_NET_BAD_FLOOD;
    *payload_at = HERMC_FLOOD_HEADER_SIZE;
  }
  return HERMC_NET_OK;
}

/* -- hello --------------------------------------------------------------- */

size_t hermc_hello_encode(const struct hermc_hello *x, uint8_t *out,
                          size_t cap) {
  if (cap < HERMC_HELLO_SIZE)
    return 0;
  out[0] = HERMC_NET_VERSION | HERMC_PT_HELLO;
  hermc_put_u16(out + 1, x->sender);
  hermc_put_u64(out + 3, x->instance);
  hermc_put_u16(out + 11, x->seqno);
  hermc_put_u16(out + 13, x->interval_ms);
  return HERMC_HELLO_SIZE;
}

enum hermc_net_error hermc_hello_decode(const uint8_t *p, size_t n,
                                        struct hermc_hello *x) {
  enum hermc_net_error e = check_control(p, n, HERMC_PT_HELLO,
                                         HERMC_HELLO_SIZE);
  if (e != HERMC_NET_OK)
    return e;
  x->sender = hermc_get_u16(p + 1);
  x->instance = hermc_get_u64(p + 3);
  x->seqno = hermc_get_u16(p + 11);
  x->interval_ms = hermc_get_u16(p + 13);
  return HERMC_NET_OK;
}

/* -- update -------------------------------------------------------------- */

/* True if class k of `e` can be sent as it is (not as a retraction). */
static int class_sendable(const struct hermc_update_entry *e, uint8_t k) {
  uint8_t i;
  if (e->hops[k] > HERMC_MAX_ROUTE_HOPS
      || (e->hops[k] > 0 && e->path[k] == NULL))
    return 0;
  for (i = 0; i < e->hops[k]; ++i)
    if (e->path[k][i] > 7u)
      return 0;
  return 1;
}

size_t hermc_update_encode(uint16_t sender, uint64_t instance,
                           const struct hermc_update_entry *entries,
                           uint8_t count, uint8_t *out, size_t cap) {
  size_t at = HERMC_UPDATE_HEADER_SIZE;
  uint8_t i, k, h;
  if (count > HERMC_MAX_UPDATE_ENTRIES || cap < at)
    return 0;
  out[0] = HERMC_NET_VERSION | HERMC_PT_UPDATE;
  hermc_put_u16(out + 1, sender);
  hermc_put_u64(out + 3, instance);
  out[11] = count;
  for (i = 0; i < count; ++i) {
    const struct hermc_update_entry *e = &entries[i];
    if (cap - at < 4u)
      return 0;
    hermc_put_u16(out + at, e->origin);
    hermc_put_u16(out + at + 2, e->seqno);
    at += 4u;
    for (k = 0; k < HERMC_SIZE_CLASSES; ++k) {
      int reachable = e->metric[k] != HERMC_INFINITE_METRIC
                      && class_sendable(e, k);
      size_t need = reachable ? 5u + (size_t)e->hops[k] : 4u;
      if (cap - at < need)
        return 0;
      hermc_put_u32(out + at, reachable ? e->metric[k]
                                        : HERMC_INFINITE_METRIC);
      at += 4u;
      if (!reachable)
        continue;
      out[at++] = e->hops[k];
      for (h = 0; h < e->hops[k]; ++h)
        out[at++] = e->path[k][h];
    }
  }
  return at;
}

enum hermc_net_error hermc_update_decode(const uint8_t *p, size_t n,
                                         struct hermc_update_header *h,
                                         struct hermc_update_entry *entries,
                                         uint8_t max_entries) {
  enum hermc_packet_type t;
  enum hermc_net_error e = hermc_peek_type(p, n, &t);
  size_t at = HERMC_UPDATE_HEADER_SIZE;
  uint8_t i, k, c;
  if (e != HERMC_NET_OK)
    return e;
  if (t != HERMC_PT_UPDATE)
    return HERMC_NET_BAD_TYPE;
  if (n < HERMC_UPDATE_HEADER_SIZE)
    return HERMC_NET_TRUNCATED;
  h->sender = hermc_get_u16(p + 1);
  h->instance = hermc_get_u64(p + 3);
  h->count = p[11];
  if (h->count > HERMC_MAX_UPDATE_ENTRIES)
    return HERMC_NET_OVER_BOUND;
  /* At least 20 bytes per entry, checked before any is read. */
  if ((size_t)h->count * 20u > n - at)
    return HERMC_NET_TRUNCATED;
  for (i = 0; i < h->count; ++i) {
    struct hermc_update_entry scratch;
    struct hermc_update_entry *out = i < max_entries ? &entries[i] : &scratch;
    if (n - at < 4u)
      return HERMC_NET_TRUNCATED;
    out->origin = hermc_get_u16(p + at);
    out->seqno = hermc_get_u16(p + at + 2);
    at += 4u;
    for (k = 0; k < HERMC_SIZE_CLASSES; ++k) {
      if (n - at < 4u)
        return HERMC_NET_TRUNCATED;
      out->metric[k] = hermc_get_u32(p + at);
      at += 4u;
      out->hops[k] = 0;
      out->path[k] = NULL;
      if (out->metric[k] == HERMC_INFINITE_METRIC)
        continue;
      if (n - at < 1u)
        return HERMC_NET_TRUNCATED;
      out->hops[k] = p[at++];
      if (out->hops[k] > HERMC_MAX_ROUTE_HOPS)
        return HERMC_NET_OVER_BOUND;
      if (n - at < out->hops[k])
        return HERMC_NET_TRUNCATED;
      out->path[k] = p + at;
      for (c = 0; c < out->hops[k]; ++c)
        if (p[at + c] > 7u)
          return HERMC_NET_BAD_LINK_CODE;
      at += out->hops[k];
    }
  }
  return at == n ? HERMC_NET_OK : HERMC_NET_TRAILING;
}

/* -- seqno request ------------------------------------------------------- */

size_t hermc_seqno_request_encode(const struct hermc_seqno_request *x,
                                  uint8_t *out, size_t cap) {
  if (cap < HERMC_SEQNO_REQUEST_SIZE)
    return 0;
  out[0] = HERMC_NET_VERSION | HERMC_PT_SEQNO_REQUEST;
  hermc_put_u16(out + 1, x->sender);
  hermc_put_u16(out + 3, x->origin);
  hermc_put_u16(out + 5, x->seqno);
  out[7] = x->hop_count;
  return HERMC_SEQNO_REQUEST_SIZE;
}

enum hermc_net_error hermc_seqno_request_decode(const uint8_t *p, size_t n,
                                                struct hermc_seqno_request *x) {
  enum hermc_net_error e = check_control(p, n, HERMC_PT_SEQNO_REQUEST,
                                         HERMC_SEQNO_REQUEST_SIZE);
  if (e != HERMC_NET_OK)
    return e;
  x->sender = hermc_get_u16(p + 1);
  x->origin = hermc_get_u16(p + 3);
  x->seqno = hermc_get_u16(p + 5);
  x->hop_count = p[7];
  return HERMC_NET_OK;
}

int hermc_seqno_newer(uint16_t a, uint16_t b) {
  uint16_t d = (uint16_t)(a - b);
  return d != 0 && d < 0x8000u;
}

/* -- claim --------------------------------------------------------------- */

size_t hermc_claim_encode(const struct hermc_claim *x, uint8_t *out,
                          size_t cap) {
  if (cap < HERMC_CLAIM_SIZE)
    return 0;
  out[0] = HERMC_NET_VERSION | HERMC_PT_CLAIM;
  hermc_put_u16(out + 1, x->id);
  hermc_put_u64(out + 3, x->nonce);
  hermc_put_u64(out + 11, x->instance);
  out[19] = x->hop_limit;
  return HERMC_CLAIM_SIZE;
}

enum hermc_net_error hermc_claim_decode(const uint8_t *p, size_t n,
                                        struct hermc_claim *x) {
  enum hermc_net_error e = check_control(p, n, HERMC_PT_CLAIM,
                                         HERMC_CLAIM_SIZE);
  if (e != HERMC_NET_OK)
    return e;
  x->id = hermc_get_u16(p + 1);
  x->nonce = hermc_get_u64(p + 3);
  x->instance = hermc_get_u64(p + 11);
  x->hop_limit = p[19];
  return HERMC_NET_OK;
}

/* -- metrics ------------------------------------------------------------- */

void hermc_link_metrics(uint32_t cost, uint32_t mtu,
                        uint32_t metrics[HERMC_SIZE_CLASSES]) {
  uint8_t k;
  for (k = 0; k < HERMC_SIZE_CLASSES; ++k) {
    uint64_t frames, total;
    if (mtu == 0 || cost >= HERMC_INFINITE_METRIC) {
      metrics[k] = HERMC_INFINITE_METRIC;
      continue;
    }
    frames = ((uint64_t)class_bytes[k] + mtu - 1u) / mtu;
    total = (uint64_t)cost * frames;
    metrics[k] = total >= HERMC_INFINITE_METRIC ? HERMC_INFINITE_METRIC
                                                : (uint32_t)total;
  }
}
