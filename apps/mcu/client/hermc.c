/* hermc.c: a leaf HERM module driven by the main loop (see hermc.h).
 *
 * What the C++ peers expect of a neighbour, and where this file meets it:
 *   - routing/neighbour_table: a hello every interval makes us a neighbour;
 *     1.5 silent intervals lose us. A hello with a new instance is a
 *     restart.
 *   - routing/route_table: our update (our id, our seqno, metric 0 in every
 *     class, 0 hops: the receiver adds its own link cost, formula (1)) is
 *     accepted from a neighbour only, so a hello goes out right before the
 *     update we send on meeting a neighbour. A seqno request for our id
 *     raises our seqno (RFC 8966 3.8.1.2) so that our route is feasible
 *     again after a reboot.
 *   - actors/app_support: queries are flooded broadcasts, answered by
 *     unicast only when something matches; requests are answered with the
 *     APO's payload or an error in category herm; subscriptions hold for
 *     their lease.
 */
#include "hermc.h"

#include "hermc_bytes.h"

/* Our data packets' priority (app_support's prio_normal). */
#define PRIORITY_NORMAL 2u
/* Longest lease honoured (topic_table::max_lease). */
#define MAX_LEASE_MS (24ul * 3600ul * 1000ul)

/* True when time `t` has come at `now` (wrapping millisecond clock). */
static int due(uint32_t now, uint32_t t) {
  return (uint32_t)(now - t) < 0x80000000ul;
}

static size_t cstr_len(const char *s) {
  size_t n = 0;
  while (s[n] != '\0')
    ++n;
  return n;
}

HERMC_NOINLINE
static int bytes_equal(struct hermc_bytes b, const char *s) {
  size_t i;
  for (i = 0; i < b.size; ++i)
    if (s[i] == '\0' || (uint8_t)s[i] != b.data[i])
      return 0;
  return s[b.size] == '\0';
}

/* -- sending ------------------------------------------------------------------ */

/* Sends scratch[0..len) on the link; keyed, signed when it must be (a
 * packet without room for the trailer is dropped: tx_dropped). */
static int send_scratch(struct hermc_module *m, size_t len) {
  int rc;
#if HERMC_AUTH
  if (m->keyed && len > 0 && hermc_auth_must_sign(&m->auth, m->scratch, len)
      && (len = hermc_auth_sign(&m->auth, m->scratch, len, HERMC_MAX_PACKET,
                                HERMC_LINK_RS232C))
           == 0) {
    ++m->counters.tx_dropped;
    return HERMC_ERR_TOO_BIG;
  }
#endif
  rc = hermc_link_tx_packet(&m->tx, m->scratch, len);
  if (rc != HERMC_OK) {
    ++m->counters.tx_dropped;
    return rc;
  }
  ++m->counters.tx_packets;
  return HERMC_OK;
}

/* Where the APO message of a data packet to `dst` starts in scratch. */
static size_t body_at(uint16_t dst, int flooded) {
  return dst == HERMC_BROADCAST && flooded ? HERMC_FLOOD_HEADER_SIZE
                                           : HERMC_DATA_HEADER_SIZE;
}

/* Writes the data header in front of the APO message of `body` bytes at
 * scratch[body_at(dst, flooded)] and sends the packet. */
static int send_data(struct hermc_module *m, uint16_t dst, int flooded,
                     size_t body) {
  struct hermc_data_header h;
  size_t at = body_at(dst, flooded);
  if (body == 0) {
    ++m->counters.tx_dropped; /* the encoder found no room */
    return HERMC_ERR_TOO_BIG;
  }
  h.src = m->cfg.module_id;
  h.dst = dst;
  h.hop_limit = HERMC_DEFAULT_HOP_LIMIT;
  h.size_class = hermc_size_class_of(body);
  h.priority = PRIORITY_NORMAL;
  h.protocol = HERMC_PROTOCOL_ASL;
  h.flood_id = 0;
  h.authenticated = 0;
  if (at == HERMC_FLOOD_HEADER_SIZE) {
    h.flood_id = m->next_flood_id++;
    if (m->next_flood_id == 0)
      m->next_flood_id = 1;
  }
  (void)hermc_data_header_encode(&h, m->scratch, at);
  return send_scratch(m, at + body);
}

/* Room for an APO message after a header of `at` bytes (keyed: and the
 * trailer, whether or not this packet needs one). */
static size_t body_cap(const struct hermc_module *m, size_t at) {
#if HERMC_AUTH
  if (m->keyed)
    return (size_t)HERMC_MAX_PACKET - at - hermc_auth_trailer_size(&m->auth);
#else
  (void)m;
#endif
  return (size_t)HERMC_MAX_PACKET - at;
}

static void send_hello(struct hermc_module *m, uint16_t interval_ms) {
  struct hermc_hello h;
  h.sender = m->cfg.module_id;
  h.instance = m->cfg.instance;
  h.seqno = m->hello_seqno++;
  h.interval_ms = interval_ms;
  if (send_scratch(m, hermc_hello_encode(&h, m->scratch, HERMC_MAX_PACKET))
      == HERMC_OK)
    ++m->counters.tx_hellos;
}

/* Our own route: metric 0 in every class, no hop (the neighbour adds its
 * link's cost), as route_table::advertisement(self) does; the layout is
 * hermc_update_encode's for this one entry, written directly (36 bytes). */
static void send_update(struct hermc_module *m) {
  uint8_t *p = m->scratch;
  uint8_t i;
  p[0] = 0x10u | HERMC_PT_UPDATE;
  hermc_put_u16(p + 1, m->cfg.module_id);
  hermc_put_u64(p + 3, m->cfg.instance);
  p[11] = 1;
  hermc_put_u16(p + 12, m->cfg.module_id);
  hermc_put_u16(p + 14, m->own_seqno);
  for (i = 16; i < 36u; ++i)
    p[i] = 0; /* 4 classes: metric 0 (4 bytes), 0 hops (1 byte) */
  if (send_scratch(m, 36u) == HERMC_OK)
    ++m->counters.tx_updates;
}

#if HERMC_TOPICS
static void send_advertise(struct hermc_module *m, uint8_t t) {
  size_t at = body_at(HERMC_BROADCAST, 1);
  const char *name = m->topics[t].name;
  if (send_data(m, HERMC_BROADCAST, 1,
                hermc_asl_advertise_encode(name, cstr_len(name),
                                           m->scratch + at, body_cap(m, at)))
      == HERMC_OK)
    m->topics[t].advertised = 1;
}
#endif /* HERMC_TOPICS */

static void send_query(struct hermc_module *m, struct hermc_remote_slot *r) {
  size_t at = body_at(HERMC_BROADCAST, 1);
  r->query_id = m->next_query_id++;
  (void)send_data(m, HERMC_BROADCAST, 1,
                  hermc_asl_query_encode(r->query_id, HERMC_BY_NAME, r->name,
                                         cstr_len(r->name), m->scratch + at,
                                         body_cap(m, at)));
}

/* Contexts are short: on an AVR every string literal also takes RAM. */
static void send_error(struct hermc_module *m, uint16_t dst, uint64_t rid,
                       uint8_t code, const char *context) {
  size_t at = body_at(dst, 0);
  (void)send_data(m, dst, 0,
                  hermc_asl_response_error_encode(
                    rid, HERMC_ERROR_CATEGORY_HERM, code, context,
                    cstr_len(context), m->scratch + at, body_cap(m, at)));
}

/* -- remote APOs ------------------------------------------------------------- */

/* Forgets where remote `r` is and asks again now. */
HERMC_NOINLINE
static void rediscover(struct hermc_module *m, struct hermc_remote_slot *r) {
  r->module = HERMC_NO_MODULE;
  r->apo = 0;
  r->backoff_ms = m->cfg.discovery_min_ms;
  r->next_query_ms = m->now_ms;
}

HERMC_NOINLINE
static void on_answer(struct hermc_module *m, uint16_t src,
                      const struct hermc_asl_msg *a) {
  uint8_t i;
  for (i = 0; i < m->nremotes; ++i) {
    struct hermc_remote_slot *r = &m->remotes[i];
    struct hermc_asl_entry e;
    size_t at = 0;
    if (r->module != HERMC_NO_MODULE || r->query_id != a->id32)
      continue;
    while (hermc_asl_answer_entry(a, &at, &e))
      if (bytes_equal(e.name, r->name)) {
        r->module = src;
        r->apo = e.apo;
        break;
      }
  }
}

static void on_response(struct hermc_module *m, uint16_t src,
                        const struct hermc_asl_msg *x) {
  uint8_t i;
  /* Our request ids are 32-bit (the wire's upper half 0): anything else
   * answers no request of ours. */
  uint32_t rid = (uint32_t)x->request_id;
  if ((uint32_t)(x->request_id >> 32) == 0)
    for (i = 0; i < HERMC_MAX_PENDING; ++i) {
      struct hermc_pending *p = &m->pending[i];
      struct hermc_remote_slot *r = &m->remotes[p->remote];
      /* The module the request went to, not the remote's current one: a
       * rediscovery for another request must not orphan this response. */
      if (p->request_id == 0 || rid != p->request_id || p->module != src)
        continue;
      p->request_id = 0; /* free before the callback, which may reuse it */
      ++m->counters.responses_received;
      if (!x->ok && x->err_category == HERMC_ERROR_CATEGORY_HERM
          && (x->err_code == HERMC_EC_APO_GONE
              || x->err_code == HERMC_EC_NO_ROUTE
              || x->err_code == HERMC_EC_UNAVAILABLE))
        rediscover(m, r);
      /* The decoder leaves what a response does not carry zero: no payload
       * on an error, no category and code on success. */
      p->fn(p->ctx, x->ok ? HERMC_STATUS_OK : HERMC_STATUS_ERROR,
            x->payload.data, x->payload.size, x->err_category, x->err_code);
      return;
    }
  ++m->counters.rx_unexpected_response;
}

/* A remote APO withdrawn or down: find it again. */
static void on_gone(struct hermc_module *m, uint16_t src, uint32_t apo) {
  uint8_t i;
  for (i = 0; i < m->nremotes; ++i)
    if (m->remotes[i].module == src && m->remotes[i].apo == apo)
      rediscover(m, &m->remotes[i]);
}

/* -- local APOs ------------------------------------------------------------- */

#if HERMC_MAX_APOS > 0
static int apo_matches(const struct hermc_apo *a,
                       const struct hermc_asl_msg *q) {
  if (q->by == HERMC_BY_ANY)
    return 1;
  return bytes_equal(q->text, q->by == HERMC_BY_NAME ? a->name : a->type);
}

/* Answers a query with every matching APO, as many per answer as fit: an
 * entry that does not fit sends the answer so far and starts the next one
 * with it. */
static void on_query(struct hermc_module *m, uint16_t src,
                     const struct hermc_asl_msg *q) {
  size_t at = body_at(src, 0);
  size_t cap = body_cap(m, at);
  uint8_t *out = m->scratch + at;
  size_t len = 0;
  uint8_t i, count = 0;
  for (i = 0; i < m->napos; ++i) {
    const struct hermc_apo *a = &m->apos[i];
    size_t n;
    if (!apo_matches(a, q))
      continue;
    for (;;) {
      if (count == 0)
        len = hermc_asl_answer_begin(q->id32, 0, out, cap);
      n = hermc_asl_answer_entry_encode((uint32_t)i + 1u, a->name,
                                        cstr_len(a->name), a->type,
                                        cstr_len(a->type), out + len,
                                        cap - len);
      if (n != 0 || count == 0)
        break;
      out[6] = count; /* full: send what we have */
      (void)send_data(m, src, 0, len);
      count = 0;
    }
    if (n == 0) {
      ++m->counters.tx_dropped; /* one entry alone does not fit a packet */
      continue;
    }
    len += n;
    ++count;
  }
  if (count > 0) {
    out[6] = count;
    if (send_data(m, src, 0, len) == HERMC_OK)
      ++m->counters.queries_answered;
  }
}
#else
/* No local APO: nothing matches, a query is never answered. */
static void on_query(struct hermc_module *m, uint16_t src,
                     const struct hermc_asl_msg *q) {
  (void)m;
  (void)src;
  (void)q;
}
#endif

/* Serves a request: the handler's response, or one typed error (an APO we
 * do not have, the handler's refusal, a response larger than the room). */
static void on_request(struct hermc_module *m, uint16_t src,
                       const struct hermc_asl_msg *x) {
  uint8_t code = HERMC_EC_APO_GONE;
  const char *why = "no such APO";
#if HERMC_MAX_APOS > 0
  if (x->id32 != 0 && x->id32 <= m->napos) {
    size_t at = body_at(src, 0);
    size_t cap = body_cap(m, at) - 11u;
    size_t resp_len = 0;
    const struct hermc_apo *a = &m->apos[x->id32 - 1u];
    ++m->counters.requests_served;
    code = a->handler(a->ctx, x->payload.data, x->payload.size,
                      m->scratch + at + 11u, cap, &resp_len);
    if (x->oneway) {
      /* One-way: a reliable one is acknowledged, a plain one not at all.
       * (No duplicate cache: a retransmitted copy reaches the handler
       * again.) */
#if HERMC_RELIABLE
      if (x->kind == HERMC_ASL_RELIABLE_REQUEST)
        (void)send_data(m, src, 0,
                        hermc_asl_ack_encode(x->request_id, m->scratch + at,
                                             body_cap(m, at)));
#endif
      return;
    }
    why = "refused";
    if (code == 0) {
      if (resp_len <= cap) {
        (void)hermc_asl_response_ok_header(x->request_id, m->scratch + at, 11u);
        (void)send_data(m, src, 0, 11u + resp_len);
        return;
      }
      code = HERMC_EC_INVALID_PARAMETER;
      why = "too large";
    }
  } else
#endif
    ++m->counters.rx_unknown_apo;
  if (x->request_id != 0)
    send_error(m, src, x->request_id, code, why);
}

#if HERMC_TOPICS
/* -- topics -------------------------------------------------------------------- */

static int find_topic(const struct hermc_module *m, struct hermc_bytes name) {
  uint8_t t;
  for (t = 0; t < m->ntopics; ++t)
    if (bytes_equal(name, m->topics[t].name))
      return t;
  return -1;
}

static void on_subscribe(struct hermc_module *m, uint16_t src,
                         const struct hermc_asl_msg *x, int subscribe) {
  int t = find_topic(m, x->text);
  uint8_t i;
  struct hermc_subscriber *free_slot = NULL;
  uint32_t lease = x->u32 < MAX_LEASE_MS ? x->u32 : MAX_LEASE_MS;
  if (t < 0) {
    ++m->counters.rx_asl_ignored; /* not a topic of ours */
    return;
  }
  for (i = 0; i < HERMC_MAX_SUBSCRIBERS; ++i) {
    struct hermc_subscriber *s = &m->subscribers[i];
    if (s->module == HERMC_NO_MODULE) {
      if (!free_slot)
        free_slot = s;
      continue;
    }
    if (s->module == src && s->topic == (uint8_t)t) {
      if (subscribe)
        s->lease_end_ms = m->now_ms + lease;
      else
        s->module = HERMC_NO_MODULE;
      return;
    }
  }
  if (!subscribe)
    return;
  if (!free_slot) {
    ++m->counters.subscribers_refused;
    return;
  }
  free_slot->module = src;
  free_slot->topic = (uint8_t)t;
  free_slot->lease_end_ms = m->now_ms + lease;
}
#endif /* HERMC_TOPICS */

/* -- receiving ------------------------------------------------------------------ */

static void on_asl(struct hermc_module *m, uint16_t src, const uint8_t *p,
                   size_t n) {
  struct hermc_asl_msg x;
  if (hermc_asl_decode(p, n, &x) != HERMC_ASL_OK || src == HERMC_NO_MODULE
      || src == HERMC_BROADCAST) {
    ++m->counters.rx_asl_malformed;
    return;
  }
  switch (x.kind) {
    case HERMC_ASL_QUERY:
      on_query(m, src, &x);
      break;
    case HERMC_ASL_ANSWER:
      on_answer(m, src, &x);
      break;
    case HERMC_ASL_REQUEST:
#if HERMC_RELIABLE
    case HERMC_ASL_RELIABLE_REQUEST:
#endif
      on_request(m, src, &x);
      break;
    case HERMC_ASL_RESPONSE:
      on_response(m, src, &x);
      break;
#if HERMC_TOPICS
    case HERMC_ASL_SUBSCRIBE:
      on_subscribe(m, src, &x, 1);
      break;
    case HERMC_ASL_UNSUBSCRIBE:
      on_subscribe(m, src, &x, 0);
      break;
#endif
    case HERMC_ASL_DOWN:
    case HERMC_ASL_WITHDRAW:
      on_gone(m, src, x.id32);
      break;
    default:
      ++m->counters.rx_asl_ignored;
      break;
  }
}

/* True if the flood (src, id) is new; remembers it. The cache is a ring:
 * floods enter in time order, so the slot written next holds the oldest. */
static int fresh_flood(struct hermc_module *m, uint16_t src, uint32_t id) {
  uint8_t i;
  struct hermc_flood *slot;
  for (i = 0; i < HERMC_FLOOD_CACHE; ++i) {
    const struct hermc_flood *f = &m->floods[i];
    if (f->src == src && f->flood_id == id
        && (uint32_t)(m->now_ms - f->seen_ms) < HERMC_FLOOD_MEMORY_MS)
      return 0;
  }
  slot = &m->floods[m->flood_next];
  m->flood_next = (uint8_t)((m->flood_next + 1u) % HERMC_FLOOD_CACHE);
  if (slot->src != HERMC_NO_MODULE
      && (uint32_t)(m->now_ms - slot->seen_ms) < HERMC_FLOOD_MEMORY_MS)
    ++m->counters.flood_evictions;
  slot->src = src;
  slot->flood_id = id;
  slot->seen_ms = m->now_ms;
  return 1;
}

static void on_data(struct hermc_module *m, const uint8_t *p, size_t n) {
  struct hermc_data_header h;
  size_t at;
  if (hermc_data_header_decode(p, n, &h, &at) != HERMC_NET_OK) {
    ++m->counters.rx_malformed;
    return;
  }
  /* Keyed, flag A says the trailer was verified (and cut off); without a
   * key, where the payload ends is unknown. */
#if HERMC_AUTH
  if (h.authenticated && !m->keyed) {
#else
  if (h.authenticated) {
#endif
    ++m->counters.rx_auth_unsupported;
    return;
  }
  if (h.dst == HERMC_BROADCAST) {
    if (h.flood_id != 0
        && (h.src == m->cfg.module_id || !fresh_flood(m, h.src, h.flood_id))) {
      ++m->counters.rx_flood_duplicates;
      return;
    }
  } else if (h.dst != m->cfg.module_id) {
    ++m->counters.rx_not_for_us;
    return;
  }
  if (h.protocol != HERMC_PROTOCOL_ASL) {
    ++m->counters.rx_ignored;
    return;
  }
  on_asl(m, h.src, p + at, n - at);
}

static void meet_neighbour(struct hermc_module *m) {
  ++m->counters.neighbour_changes;
  /* It may not know us yet: a hello first, so that it takes our update. */
  send_hello(m, m->cfg.hello_interval_ms);
  send_update(m);
#if HERMC_TOPICS
  {
    uint8_t t;
    for (t = 0; t < m->ntopics; ++t)
      send_advertise(m, t);
  }
#endif
}

static void on_hello(struct hermc_module *m, const uint8_t *p, size_t n) {
  struct hermc_hello h;
  if (hermc_hello_decode(p, n, &h) != HERMC_NET_OK) {
    ++m->counters.rx_malformed;
    return;
  }
  /* Our neighbour as we know it (none: m->neighbour is 0, never a sender
   * we take). */
  int same = h.sender == m->neighbour && h.instance == m->neighbour_instance;
  if (h.interval_ms == 0) {
    if (m->neighbour != HERMC_NO_MODULE && same)
      m->neighbour = HERMC_NO_MODULE;
    else
      ++m->counters.rx_ignored;
    return;
  }
  if (h.sender == HERMC_NO_MODULE || h.sender == HERMC_BROADCAST
      || h.sender == m->cfg.module_id) {
    ++m->counters.rx_ignored; /* claiming, or a duplicate of our id */
    return;
  }
  {
    int fresh = !same;
    m->neighbour = h.sender;
    m->neighbour_instance = h.instance;
    m->neighbour_heard_ms = m->now_ms;
    m->neighbour_interval_ms = h.interval_ms;
    if (fresh)
      meet_neighbour(m);
  }
}

static void on_seqno_request(struct hermc_module *m, const uint8_t *p,
                             size_t n) {
  struct hermc_seqno_request r;
  if (hermc_seqno_request_decode(p, n, &r) != HERMC_NET_OK) {
    ++m->counters.rx_malformed;
    return;
  }
  if (r.origin != m->cfg.module_id) {
    ++m->counters.rx_ignored; /* a leaf forwards nothing */
    return;
  }
  if (hermc_seqno_newer(r.seqno, m->own_seqno))
    m->own_seqno = r.seqno;
  ++m->counters.seqno_requests_answered;
  send_update(m);
}

#if HERMC_AUTH
/* Checks p[0..*n) (routing/agent_auth.cpp `authenticate`): 1 when it is
 * handled further, its first *n bytes; 0 when dropped (counted in
 * m->auth.counters). Our challenge and our reply to the neighbour's (then
 * our hello, as the C++ sends it) go out at once, already signed. */
static int authenticate(struct hermc_module *m, const uint8_t *p, size_t *n) {
  struct hermc_auth_out *o = &m->auth_out;
  size_t body = 0;
  int pass = hermc_auth_receive(&m->auth, p, *n, HERMC_LINK_RS232C, m->now_ms,
                                &body, o);
  if (o->challenge_len > 0) {
    if (hermc_link_tx_packet(&m->tx, o->challenge, o->challenge_len)
        == HERMC_OK)
      ++m->counters.tx_packets;
    else
      ++m->counters.tx_dropped;
  }
  if (o->reply_len > 0) {
    if (hermc_link_tx_packet(&m->tx, o->reply, o->reply_len) == HERMC_OK)
      ++m->counters.tx_packets;
    else
      ++m->counters.tx_dropped;
    send_hello(m, m->cfg.hello_interval_ms);
  }
  *n = body;
  return pass;
}
#endif

void hermc_handle_packet(struct hermc_module *m, const uint8_t *p,
                         size_t n) {
  enum hermc_packet_type t;
  ++m->counters.rx_packets;
#if HERMC_AUTH
  if (m->keyed && !authenticate(m, p, &n))
    return;
#endif
  if (hermc_peek_type(p, n, &t) != HERMC_NET_OK) {
    ++m->counters.rx_malformed;
    return;
  }
  switch (t) {
    case HERMC_PT_DATA:
      on_data(m, p, n);
      break;
    case HERMC_PT_HELLO:
      on_hello(m, p, n);
      break;
    case HERMC_PT_SEQNO_REQUEST:
      on_seqno_request(m, p, n);
      break;
    default:
      ++m->counters.rx_ignored;
      break;
  }
}

static void on_link_packet(void *ctx, uint8_t src, const uint8_t *pkt,
                           size_t len) {
  (void)src;
  hermc_handle_packet((struct hermc_module *)ctx, pkt, len);
}

/* -- public ---------------------------------------------------------------------- */

void hermc_config_default(struct hermc_config *cfg, uint16_t id,
                          uint64_t instance) {
  cfg->module_id = id;
  cfg->instance = instance;
  cfg->hello_interval_ms = 1000u;
  cfg->update_every = 4u;
  cfg->request_timeout_ms = 2000u;
  cfg->discovery_min_ms = 250u;
  cfg->discovery_max_ms = 8000u;
  cfg->escaped = 0;
}

int hermc_init(struct hermc_module *m, const struct hermc_config *cfg) {
  size_t i;
  uint8_t *raw = (uint8_t *)m;
  if (cfg->module_id == HERMC_NO_MODULE || cfg->module_id == HERMC_BROADCAST
      || cfg->instance == 0 || cfg->hello_interval_ms == 0
      || cfg->update_every == 0 || (!HERMC_ESCAPED && cfg->escaped))
    return HERMC_ERR_ARG;
  for (i = 0; i < sizeof *m; ++i)
    raw[i] = 0;
  m->cfg = *cfg;
  if (m->cfg.discovery_min_ms == 0)
    m->cfg.discovery_min_ms = 1;
  /* Deadlines are compared on half the 32-bit clock (due()). */
  if (m->cfg.discovery_max_ms > MAX_LEASE_MS)
    m->cfg.discovery_max_ms = MAX_LEASE_MS;
  if (m->cfg.request_timeout_ms > MAX_LEASE_MS)
    m->cfg.request_timeout_ms = MAX_LEASE_MS;
  hermc_link_rx_init(&m->rx, cfg->escaped != 0);
  hermc_link_tx_init(&m->tx, cfg->escaped != 0);
  /* Ids of this boot start from its whole instance, mixed, so that a
   * reply to the previous boot's query or request is not taken for one of
   * ours even when instances differ in a few bits (a boot counter). */
  {
    uint32_t s = ((uint32_t)cfg->instance ^ (uint32_t)(cfg->instance >> 32))
                 * 2654435761u;
    m->next_flood_id = s | 1u;
    m->next_query_id = s ^ 0x9E3779B9u;
    m->next_request_id = (s ^ 0x7F4A7C15u) | 1u;
  }
  return HERMC_OK;
}

void hermc_feed(struct hermc_module *m, const uint8_t *bytes, size_t n) {
  hermc_link_rx_feed(&m->rx, bytes, n, on_link_packet, m);
}

size_t hermc_poll_tx(struct hermc_module *m, uint8_t *out, size_t cap) {
  return hermc_link_tx_pop(&m->tx, out, cap);
}

void hermc_tick(struct hermc_module *m, uint32_t now_ms) {
  uint8_t i;
  m->now_ms = now_ms;
  hermc_link_rx_tick(&m->rx, now_ms);
  if (!m->started) {
    m->started = 1;
    m->next_hello_ms = now_ms;
    m->hellos_to_update = 1;
    for (i = 0; i < m->nremotes; ++i)
      m->remotes[i].next_query_ms = now_ms;
  }
  if (due(now_ms, m->next_hello_ms)) {
    m->next_hello_ms = now_ms + m->cfg.hello_interval_ms;
    send_hello(m, m->cfg.hello_interval_ms);
    if (--m->hellos_to_update == 0) {
      m->hellos_to_update = m->cfg.update_every;
      send_update(m);
    }
  }
  /* The neighbour is lost after 1.5 of its (or our longer) interval. */
  if (m->neighbour != HERMC_NO_MODULE) {
    uint32_t iv = m->neighbour_interval_ms > m->cfg.hello_interval_ms
                    ? m->neighbour_interval_ms
                    : m->cfg.hello_interval_ms;
    if ((uint32_t)(now_ms - m->neighbour_heard_ms) > iv + iv / 2u)
      m->neighbour = HERMC_NO_MODULE;
  }
  for (i = 0; i < m->nremotes; ++i) {
    struct hermc_remote_slot *r = &m->remotes[i];
    if (r->module != HERMC_NO_MODULE || !due(now_ms, r->next_query_ms))
      continue;
    send_query(m, r);
    r->next_query_ms = now_ms + r->backoff_ms;
    r->backoff_ms = r->backoff_ms < m->cfg.discovery_max_ms / 2u
                      ? r->backoff_ms * 2u
                      : m->cfg.discovery_max_ms;
  }
  for (i = 0; i < HERMC_MAX_PENDING; ++i) {
    struct hermc_pending *p = &m->pending[i];
    if (p->request_id == 0 || !due(now_ms, p->deadline_ms))
      continue;
    p->request_id = 0; /* free before the callback, which may reuse it */
    ++m->counters.request_timeouts;
    rediscover(m, &m->remotes[p->remote]);
    p->fn(p->ctx, HERMC_STATUS_TIMEOUT, NULL, 0, 0, 0);
  }
#if HERMC_TOPICS
  for (i = 0; i < HERMC_MAX_SUBSCRIBERS; ++i)
    if (m->subscribers[i].module != HERMC_NO_MODULE
        && due(now_ms, m->subscribers[i].lease_end_ms))
      m->subscribers[i].module = HERMC_NO_MODULE;
#endif
}

#if HERMC_AUTH
int hermc_set_key(struct hermc_module *m, const uint8_t *key, size_t key_len,
                  uint8_t key_id, uint8_t tag_bytes, uint8_t data_all,
                  uint32_t index) {
  m->keyed = 0;
  if (hermc_auth_init(&m->auth, key, key_len, tag_bytes, index,
                      m->cfg.instance)
      != 0)
    return HERMC_ERR_ARG;
  m->auth.key_id = key_id;
  m->auth.data_all = data_all != 0;
  m->keyed = 1;
  return HERMC_OK;
}
#endif

int hermc_register_apo(struct hermc_module *m, const char *name,
                       const char *type, hermc_handler handler, void *ctx) {
  if (!handler || !name || !type || cstr_len(name) > HERMC_ASL_MAX_STRING
      || cstr_len(type) > HERMC_ASL_MAX_STRING)
    return HERMC_ERR_ARG;
#if HERMC_MAX_APOS > 0
  if (m->napos >= HERMC_MAX_APOS)
    return HERMC_ERR_NO_ROOM;
  {
    struct hermc_apo *a = &m->apos[m->napos++];
    a->name = name;
    a->type = type;
    a->handler = handler;
    a->ctx = ctx;
  }
  return m->napos;
#else
  (void)m;
  (void)ctx;
  return HERMC_ERR_NO_ROOM;
#endif
}

int hermc_remote(struct hermc_module *m, const char *name) {
  struct hermc_remote_slot *r;
  if (!name || cstr_len(name) > HERMC_ASL_MAX_STRING)
    return HERMC_ERR_ARG;
  if (m->nremotes >= HERMC_MAX_REMOTES)
    return HERMC_ERR_NO_ROOM;
  r = &m->remotes[m->nremotes];
  r->name = name;
  rediscover(m, r);
  return m->nremotes++;
}

int hermc_remote_ready(const struct hermc_module *m, int r) {
  return r >= 0 && r < m->nremotes
         && m->remotes[r].module != HERMC_NO_MODULE;
}

int hermc_request(struct hermc_module *m, int r, const uint8_t *payload,
                  size_t len, hermc_response_fn fn, void *ctx,
                  uint32_t timeout_ms) {
  struct hermc_remote_slot *rem;
  struct hermc_pending *slot = NULL;
  uint32_t rid = 0;
  size_t at, i;
  int rc;
  if (r < 0 || r >= m->nremotes || (len > 0 && !payload))
    return HERMC_ERR_ARG;
  rem = &m->remotes[r];
  if (rem->module == HERMC_NO_MODULE) {
    ++m->counters.requests_refused;
    return HERMC_ERR_NOT_READY;
  }
  at = body_at(rem->module, 0);
  if (len > body_cap(m, at) - 14u)
    return HERMC_ERR_TOO_BIG;
  if (fn) {
    for (i = 0; i < HERMC_MAX_PENDING && !slot; ++i)
      if (m->pending[i].request_id == 0)
        slot = &m->pending[i];
    if (!slot) {
      ++m->counters.requests_refused;
      return HERMC_ERR_NO_ROOM;
    }
    rid = m->next_request_id++;
    if (m->next_request_id == 0)
      m->next_request_id = 1;
  }
  (void)hermc_asl_request_header(rid, rem->apo, 0, fn == NULL,
                                 m->scratch + at, 14u);
  for (i = 0; i < len; ++i)
    m->scratch[at + 14u + i] = payload[i];
  rc = send_data(m, rem->module, 0, 14u + len);
  if (rc != HERMC_OK || !slot)
    return rc;
  if (!timeout_ms)
    timeout_ms = m->cfg.request_timeout_ms;
  /* Deadlines are compared on half the 32-bit clock (due()). */
  if (timeout_ms > MAX_LEASE_MS)
    timeout_ms = MAX_LEASE_MS;
  slot->request_id = rid;
  slot->deadline_ms = m->now_ms + timeout_ms;
  slot->module = rem->module;
  slot->remote = (uint8_t)r;
  slot->fn = fn;
  slot->ctx = ctx;
  return HERMC_OK;
}

#if HERMC_TOPICS
int hermc_topic(struct hermc_module *m, const char *name) {
  struct hermc_topic_slot *t;
  if (!name || cstr_len(name) == 0 || cstr_len(name) > HERMC_ASL_MAX_STRING)
    return HERMC_ERR_ARG;
  if (m->ntopics >= HERMC_MAX_TOPICS)
    return HERMC_ERR_NO_ROOM;
  t = &m->topics[m->ntopics];
  t->name = name;
  t->seq = 0;
  t->advertised = 0;
  if (m->neighbour != HERMC_NO_MODULE)
    send_advertise(m, m->ntopics);
  return m->ntopics++;
}

int hermc_publish(struct hermc_module *m, int t, const uint8_t *payload,
                  size_t len) {
  struct hermc_topic_slot *topic;
  const char *name;
  size_t name_len, i, k;
  int sent = 0;
  if (t < 0 || t >= m->ntopics || (len > 0 && !payload))
    return HERMC_ERR_ARG;
  topic = &m->topics[t];
  name = topic->name;
  name_len = cstr_len(name);
  {
    /* Subtracted, not added: no wrap with a 16-bit size_t. */
    size_t cap = body_cap(m, HERMC_DATA_HEADER_SIZE);
    if (name_len + 7u > cap || len > cap - 7u - name_len)
      return HERMC_ERR_TOO_BIG;
  }
  ++topic->seq;
  for (i = 0; i < HERMC_MAX_SUBSCRIBERS; ++i) {
    const struct hermc_subscriber *s = &m->subscribers[i];
    size_t at, h;
    if (s->module == HERMC_NO_MODULE || s->topic != (uint8_t)t)
      continue;
    at = body_at(s->module, 0);
    h = hermc_asl_publish_header(name, name_len, topic->seq, m->scratch + at,
                                 body_cap(m, at));
    for (k = 0; k < len; ++k)
      m->scratch[at + h + k] = payload[k];
    if (send_data(m, s->module, 0, h + len) == HERMC_OK) {
      ++m->counters.publications_sent;
      ++sent;
    }
  }
  return sent;
}
#endif /* HERMC_TOPICS */
