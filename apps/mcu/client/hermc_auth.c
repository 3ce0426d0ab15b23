/* hermc_auth.c: packet authentication (contracts in hermc_auth.h; the wire
 * format in docs/protocol.md, "Authentication"; the C++ reference is
 * routing/auth.cpp and routing/agent_auth.cpp). */
#include "hermc_auth.h"

#include "hermc_bytes.h"

/* Network packet layout bits this file reads (hermc_net.h has the codecs;
 * these few bytes are read here directly so that authentication depends on
 * no decoder). */
#define PT_DATA 0u
#define PT_CHALLENGE_REQUEST 6u
#define PT_CHALLENGE_REPLY 7u
#define DATA_HEADER 8u
#define FLOOD_HEADER 12u
#define FLAG_FLOOD 0x10u
#define FLAGS_RESERVED 0xC0u
#define BROADCAST 0xFFFFu
#define PROTOCOL_ASL 1u
#define ASL_ANSWER 2u
#define CHALLENGE_BODY (1u + HERMC_AUTH_NONCE_SIZE)

/* Age of a time stamp, ms, modulo 2^32 (see the header on wrapping). */
static uint32_t age(uint32_t now_ms, uint32_t then_ms) {
  return (uint32_t)(now_ms - then_ms);
}

/* HMAC-SHA256 with the key over the 8 bytes `pre` and then p[0..n). */
static void mac(const struct hermc_auth *a, const uint8_t pre[8],
                const uint8_t *p, size_t n, uint8_t out[HERMC_SHA256_SIZE]) {
  struct hermc_sha256 c;
  hermc_hmac_sha256_begin(&c, &a->key);
  hermc_sha256_update(&c, pre, 8u);
  hermc_sha256_update(&c, p, n);
  hermc_hmac_sha256_end(&c, &a->key, out);
}

/* The pseudo-header "HERM-A1" and the link code; `tag` gets the full HMAC
 * of it and p[0..n). */
static void packet_mac(const struct hermc_auth *a, uint8_t link,
                       const uint8_t *p, size_t n,
                       uint8_t tag[HERMC_SHA256_SIZE]) {
  uint8_t pre[8];
  pre[0] = 'H';
  pre[1] = 'E';
  pre[2] = 'R';
  pre[3] = 'M';
  pre[4] = '-';
  pre[5] = 'A';
  pre[6] = '1';
  pre[7] = link;
  mac(a, pre, p, n, tag);
}

int hermc_auth_init(struct hermc_auth *a, const uint8_t *key, size_t key_len,
                    uint8_t tag_bytes, uint32_t index, uint64_t salt) {
  uint8_t *raw = (uint8_t *)a;
  size_t i;
  for (i = 0; i < sizeof *a; ++i)
    raw[i] = 0;
  if (key == NULL || key_len < HERMC_AUTH_KEY_MIN || key_len > HERMC_AUTH_KEY_MAX
      || (tag_bytes != 8u && tag_bytes != 16u))
    return HERMC_AUTH_ERR_ARG;
  hermc_hmac_sha256_key(&a->key, key, key_len);
  a->salt = salt;
  a->counter = 1;
  a->index = index;
  a->key_id = 1;
  a->tag_bytes = tag_bytes;
  return 0;
}

size_t hermc_auth_trailer_size(const struct hermc_auth *a) {
  return HERMC_AUTH_HEAD_SIZE + a->tag_bytes;
}

/* The policy of routing/auth.cpp data_needs_auth for the data packet
 * p[0..n) whose header is `hdr` bytes (checked by the caller). */
static int data_needs_auth(const struct hermc_auth *a, const uint8_t *p,
                           size_t n, size_t hdr) {
  if (a->data_all || hermc_get_u16(p + 3) == BROADCAST)
    return 1;
  return p[7] == PROTOCOL_ASL && n - hdr >= 2u && p[hdr + 1u] == ASL_ANSWER;
}

/* The header size of the data packet p[0..n) (n >= 8), or 0 when its
 * header does not decode (as routing/wire.cpp decode_data_header). */
static size_t data_header_size(const uint8_t *p, size_t n) {
  uint8_t flags = p[6];
  if ((flags & FLAGS_RESERVED) != 0)
    return 0;
  if ((flags & FLAG_FLOOD) == 0)
    return DATA_HEADER;
  if (n < FLOOD_HEADER || hermc_get_u16(p + 3) != BROADCAST
      || hermc_get_u32(p + 8) == 0)
    return 0;
  return FLOOD_HEADER;
}

/* The packet type of p[0..n), or -1 for no network packet. */
static int packet_type(const uint8_t *p, size_t n) {
  if (n == 0 || (p[0] >> 4) != 1u || (p[0] & 0x0Fu) > 7u)
    return -1;
  return p[0] & 0x0F;
}

int hermc_auth_must_sign(const struct hermc_auth *a, const uint8_t *pkt,
                         size_t len) {
  int type = packet_type(pkt, len);
  size_t hdr;
  if (type < 0)
    return 0;
  if (type != (int)PT_DATA)
    return 1;
  if (len < DATA_HEADER || (hdr = data_header_size(pkt, len)) == 0)
    return 0;
  return data_needs_auth(a, pkt, len, hdr);
}

size_t hermc_auth_sign(struct hermc_auth *a, uint8_t *pkt, size_t len,
                       size_t cap, uint8_t link) {
  uint8_t tag[HERMC_SHA256_SIZE];
  size_t i, trailer = hermc_auth_trailer_size(a);
  if (cap < len || cap - len < trailer)
    return 0;
  if (len >= DATA_HEADER && packet_type(pkt, len) == (int)PT_DATA)
    pkt[6] = (uint8_t)(pkt[6] | HERMC_AUTH_FLAG_A);
  pkt[len] = a->key_id;
  hermc_put_u32(pkt + len + 1u, a->index);
  hermc_put_u64(pkt + len + 5u, a->counter);
  ++a->counter;
  packet_mac(a, link, pkt, len + HERMC_AUTH_HEAD_SIZE, tag);
  for (i = 0; i < a->tag_bytes; ++i)
    pkt[len + HERMC_AUTH_HEAD_SIZE + i] = tag[i];
  ++a->counters.signed_packets;
  return len + trailer;
}

/* The peer slot of `index`, or NULL. */
static struct hermc_auth_peer *find_peer(struct hermc_auth *a,
                                         uint32_t index) {
  uint8_t i;
  for (i = 0; i < HERMC_AUTH_PEERS; ++i)
    if (a->peers[i].used && a->peers[i].index == index)
      return &a->peers[i];
  return NULL;
}

enum hermc_auth_result hermc_auth_verify(struct hermc_auth *a,
                                         const uint8_t *pkt, size_t len,
                                         uint8_t link, uint32_t now_ms,
                                         size_t min_body,
                                         struct hermc_auth_trailer *t) {
  uint8_t want[HERMC_SHA256_SIZE];
  size_t trailer = hermc_auth_trailer_size(a), body;
  const uint8_t *tr;
  struct hermc_auth_peer *peer;
  uint32_t index;
  uint64_t pc;
  if (pkt == NULL || len < trailer || len - trailer < min_body) {
    ++a->counters.truncated;
    return HERMC_AUTH_TRUNCATED;
  }
  body = len - trailer;
  tr = pkt + body;
  if (tr[0] != a->key_id) {
    ++a->counters.wrong_key_id;
    return HERMC_AUTH_WRONG_KEY_ID;
  }
  packet_mac(a, link, pkt, body + HERMC_AUTH_HEAD_SIZE, want);
  if (!hermc_equal_ct(want, tr + HERMC_AUTH_HEAD_SIZE, a->tag_bytes)) {
    ++a->counters.bad_tag;
    return HERMC_AUTH_BAD_TAG;
  }
  index = hermc_get_u32(tr + 1);
  pc = hermc_get_u64(tr + 5);
  t->index = index;
  t->counter = pc;
  t->body_len = body;
  /* Only a right tag gets here: a sender without the key can neither fill
   * the table nor move a counter. */
  peer = find_peer(a, index);
  if (peer == NULL) {
    ++a->counters.unknown_index;
    return HERMC_AUTH_UNKNOWN_INDEX;
  }
  if (pc <= peer->counter) {
    ++a->counters.replayed;
    return HERMC_AUTH_REPLAYED;
  }
  peer->counter = pc;
  peer->heard_ms = now_ms;
  ++a->counters.accepted;
  return HERMC_AUTH_OK;
}

/* Records `counter` as the last of `index`; 0 when `index` is new and every
 * slot holds a sender heard within HERMC_AUTH_FORGET_MS. */
static int admit(struct hermc_auth *a, uint32_t index, uint64_t counter,
                 uint32_t now_ms) {
  struct hermc_auth_peer *p = find_peer(a, index);
  uint8_t i;
  if (p == NULL) {
    for (i = 0; i < HERMC_AUTH_PEERS; ++i) {
      struct hermc_auth_peer *q = &a->peers[i];
      if (!q->used) {
        p = q;
        break;
      }
      if (p == NULL || age(now_ms, q->heard_ms) > age(now_ms, p->heard_ms))
        p = q;
    }
    if (p->used && age(now_ms, p->heard_ms) < HERMC_AUTH_FORGET_MS)
      return 0;
    p->used = 1;
    p->index = index;
    p->counter = 0;
  }
  if (counter > p->counter) /* never lowered */
    p->counter = counter;
  p->heard_ms = now_ms;
  return 1;
}

int hermc_auth_challenge(struct hermc_auth *a, uint32_t index,
                         uint32_t now_ms,
                         uint8_t nonce[HERMC_AUTH_NONCE_SIZE]) {
  static const uint8_t domain[7] = {'H', 'E', 'R', 'M', '-', 'N', '1'};
  struct hermc_auth_pending *slot = NULL;
  uint8_t pre[8], seed[12], full[HERMC_SHA256_SIZE];
  uint8_t i;
  for (i = 0; i < HERMC_AUTH_CHALLENGES; ++i)
    if (a->challenges[i].used && a->challenges[i].index == index)
      slot = &a->challenges[i];
  if (slot != NULL
      && age(now_ms, slot->sent_ms) < HERMC_AUTH_CHALLENGE_INTERVAL_MS) {
    ++a->counters.challenges_limited;
    return 0;
  }
  if (slot == NULL) {
    /* A free slot, else an expired one, else the oldest. */
    for (i = 0; i < HERMC_AUTH_CHALLENGES; ++i) {
      struct hermc_auth_pending *c = &a->challenges[i];
      if (!c->used) {
        slot = c;
        break;
      }
      if (slot == NULL || age(now_ms, c->sent_ms) > age(now_ms, slot->sent_ms))
        slot = c;
    }
  }
  /* nonce = HMAC(key, "HERM-N1" 00 | salt | nonces)[0..8): a PRF of a
   * count that never repeats within a boot, and a salt that differs
   * between boots. */
  for (i = 0; i < 7u; ++i)
    pre[i] = domain[i];
  pre[7] = 0;
  hermc_put_u64(seed, a->salt);
  hermc_put_u32(seed + 8, a->nonces);
  ++a->nonces;
  mac(a, pre, seed, sizeof seed, full);
  for (i = 0; i < HERMC_AUTH_NONCE_SIZE; ++i)
    slot->nonce[i] = nonce[i] = full[i];
  slot->used = 1;
  slot->index = index;
  slot->sent_ms = now_ms;
  ++a->counters.challenges_sent;
  return 1;
}

enum hermc_auth_result hermc_auth_accept_reply(
  struct hermc_auth *a, const struct hermc_auth_trailer *t,
  const uint8_t nonce[HERMC_AUTH_NONCE_SIZE], uint32_t now_ms) {
  struct hermc_auth_pending *c = NULL;
  uint8_t i;
  for (i = 0; i < HERMC_AUTH_CHALLENGES; ++i)
    if (a->challenges[i].used && a->challenges[i].index == t->index)
      c = &a->challenges[i];
  if (c == NULL) {
    ++a->counters.challenges_failed;
    return HERMC_AUTH_CHALLENGE_FAILED;
  }
  if (age(now_ms, c->sent_ms) > HERMC_AUTH_CHALLENGE_TIMEOUT_MS) {
    c->used = 0;
    ++a->counters.challenges_failed;
    return HERMC_AUTH_CHALLENGE_FAILED;
  }
  if (!hermc_equal_ct(c->nonce, nonce, HERMC_AUTH_NONCE_SIZE)) {
    ++a->counters.challenges_failed;
    return HERMC_AUTH_CHALLENGE_FAILED;
  }
  c->used = 0;
  if (!admit(a, t->index, t->counter, now_ms)) {
    ++a->counters.challenges_failed;
    return HERMC_AUTH_TABLE_FULL;
  }
  ++a->counters.challenges_passed;
  return HERMC_AUTH_OK;
}

int hermc_auth_may_reply(struct hermc_auth *a, uint32_t index,
                         uint32_t now_ms) {
  struct hermc_auth_requester *r = NULL;
  uint8_t i;
  for (i = 0; i < HERMC_AUTH_REQUESTERS; ++i)
    if (a->requesters[i].used && a->requesters[i].index == index)
      r = &a->requesters[i];
  if (r != NULL) {
    if (age(now_ms, r->answered_ms) < HERMC_AUTH_CHALLENGE_INTERVAL_MS) {
      ++a->counters.replies_limited;
      return 0;
    }
  } else {
    /* A free slot, else one answered an interval ago or more. */
    for (i = 0; i < HERMC_AUTH_REQUESTERS && r == NULL; ++i) {
      struct hermc_auth_requester *q = &a->requesters[i];
      if (!q->used
          || age(now_ms, q->answered_ms) >= HERMC_AUTH_CHALLENGE_INTERVAL_MS)
        r = q;
    }
    if (r == NULL) {
      ++a->counters.replies_limited;
      return 0;
    }
  }
  r->used = 1;
  r->index = index;
  r->answered_ms = now_ms;
  ++a->counters.replies;
  return 1;
}

/* -- receiving ----------------------------------------------------------------- */

/* Writes a signed challenge request or reply (`type`) with `nonce` into
 * out[0..HERMC_AUTH_CHALLENGE_MAX); returns its length. */
static uint8_t make_challenge(struct hermc_auth *a, uint8_t type,
                              const uint8_t *nonce, uint8_t link,
                              uint8_t out[HERMC_AUTH_CHALLENGE_MAX]) {
  uint8_t i;
  out[0] = (uint8_t)(0x10u | type);
  for (i = 0; i < HERMC_AUTH_NONCE_SIZE; ++i)
    out[1u + i] = nonce[i];
  return (uint8_t)hermc_auth_sign(a, out, CHALLENGE_BODY,
                                  HERMC_AUTH_CHALLENGE_MAX, link);
}

int hermc_auth_receive(struct hermc_auth *a, const uint8_t *pkt, size_t len,
                       uint8_t link, uint32_t now_ms, size_t *body_len,
                       struct hermc_auth_out *out) {
  struct hermc_auth_trailer t = {0, 0, 0};
  enum hermc_auth_result res;
  size_t min_body = 1;
  int type = packet_type(pkt, len), right_tag,
      challenge = type == (int)PT_CHALLENGE_REQUEST
                  || type == (int)PT_CHALLENGE_REPLY;
  out->challenge_len = 0;
  out->reply_len = 0;
  *body_len = 0;
  if (type < 0) {
    ++a->counters.rx_malformed;
    return 0;
  }
  if (type == (int)PT_DATA) {
    if (len < DATA_HEADER || (min_body = data_header_size(pkt, len)) == 0) {
      ++a->counters.rx_malformed;
      return 0;
    }
    if ((pkt[6] & HERMC_AUTH_FLAG_A) == 0) {
      if (data_needs_auth(a, pkt, len, min_body)) {
        ++a->counters.rx_unsigned;
        return 0;
      }
      *body_len = len;
      return 1;
    }
  }
  res = hermc_auth_verify(a, pkt, len, link, now_ms, min_body, &t);
  right_tag = res == HERMC_AUTH_OK || res == HERMC_AUTH_REPLAYED
              || res == HERMC_AUTH_TABLE_FULL || res == HERMC_AUTH_UNKNOWN_INDEX;
  if (res == HERMC_AUTH_UNKNOWN_INDEX && type != (int)PT_CHALLENGE_REPLY) {
    /* Not acted on until its sender shows it is alive. Our challenge goes
     * out before our answer to theirs, so that their reply to it, and
     * the full update they send on meeting us, find their index known. */
    uint8_t nonce[HERMC_AUTH_NONCE_SIZE];
    if (hermc_auth_challenge(a, t.index, now_ms, nonce))
      out->challenge_len =
        make_challenge(a, PT_CHALLENGE_REQUEST, nonce, link, out->challenge);
  }
  if (challenge && right_tag && t.body_len != CHALLENGE_BODY) {
    ++a->counters.rx_malformed;
    return 0;
  }
  /* A challenge request with a right tag is answered whatever its index and
   * counter (RFC 8967 4.3): the requester may be new to us. */
  if (type == (int)PT_CHALLENGE_REQUEST && right_tag
      && hermc_auth_may_reply(a, t.index, now_ms))
    out->reply_len =
      make_challenge(a, PT_CHALLENGE_REPLY, pkt + 1, link, out->reply);
  if (res == HERMC_AUTH_UNKNOWN_INDEX && type == (int)PT_CHALLENGE_REPLY)
    (void)hermc_auth_accept_reply(a, &t, pkt + 1, now_ms);
  if (res != HERMC_AUTH_OK || challenge)
    return 0; /* answered above; a reply from a known index: nothing to do */
  *body_len = t.body_len;
  return 1;
}
