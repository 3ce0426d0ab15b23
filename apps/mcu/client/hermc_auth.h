/* hermc_auth.h: packet authentication for a leaf module (docs/protocol.md,
 * "Authentication"): the truncated HMAC-SHA256 trailer after Babel's RFC
 * 8967, replay protection by per-sender packet counters, and RFC 8967's
 * challenge of sender indexes not known yet. The C++ peer is
 * routing/auth.hpp (the pure core) with routing/agent_auth.cpp (what the
 * routing agent does with it); hermc_auth_receive is the latter's
 * `authenticate` for one link.
 *
 * Every signed packet ends in a trailer
 *
 *   key id (1) | sender index (4, LE) | packet counter (8, LE) | tag (8/16)
 *
 * the tag being the first 8 or 16 bytes of HMAC-SHA256 with the network's
 * key over "HERM-A1", the link code of the link (hermc_net.h
 * HERMC_LINK_*), and the packet up to the tag.
 *
 * Model (as libcanard): pure. No heap, no I/O, no clock (the time is an
 * argument: a wrapping uint32_t of milliseconds, the same clock as
 * hermc_tick), no random source: the caller draws this boot's sender index,
 * and challenge nonces are derived from the key, a per-boot salt and a
 * count (HMAC-SHA256 as a PRF: unpredictable without the key, and unique as
 * long as the salt differs from boot to boot, which is what a nonce needs:
 * freshness, not secrecy). All state is one `struct hermc_auth` the caller
 * allocates; one context of execution uses it at a time.
 *
 * Bounds: the tables of senders (index, last counter), live challenges and
 * answered requesters have HERMC_AUTH_PEERS, HERMC_AUTH_CHALLENGES and
 * HERMC_AUTH_REQUESTERS entries (compile-time; a leaf has one neighbour,
 * and 2 lets a restarted neighbour's new index in while the old one is
 * remembered). Whatever does not fit is refused and counted, never
 * undefined: a packet of any length and content is checked without reading
 * outside [pkt, pkt + len). Only packets with a right tag touch the tables,
 * so a sender without the key can fill none of them, move no counter and
 * prompt no challenge or reply. Cost per call: one HMAC over the packet
 * (ceil((len + 8 + 9) / 64) + 2 compressions; the key's pads are
 * precomputed), plus O(table) scans; hermc_auth_receive at most three
 * HMACs (verify, a challenge's nonce and its signature, a reply's
 * signature: 4). Stack on AVR (avr-gcc -Os, -fstack-usage): about 330
 * bytes at the deepest (receive -> verify or challenge -> HMAC -> one
 * compression), besides the caller's struct hermc_auth_out (78 bytes).
 *
 * Times are compared as (uint32_t)(now - then), so ages wrap after 49.7
 * days: an entry silent that long looks young for at most the length of the
 * interval compared (60 s for a sender, 30 s for a challenge), which can
 * only delay a table eviction or refuse a late reply.
 */
#ifndef HERMC_AUTH_H
#define HERMC_AUTH_H

#include <stddef.h>
#include <stdint.h>

#include "hermc_sha256.h"

#ifdef __cplusplus
extern "C" {
#endif

/* -- bounds (each overridable with -D) ------------------------------------------ */

/* Senders (indexes) whose last counter is remembered (C++: max_senders,
 * 256). A new index enters only by passing a challenge; when the table is
 * full it replaces the sender silent the longest if that one has been silent
 * HERMC_AUTH_FORGET_MS, else the reply is refused (table_full). 1..255. */
#ifndef HERMC_AUTH_PEERS
#define HERMC_AUTH_PEERS 2
#endif

/* Live challenges (one per index challenged); when full the expired one,
 * else the oldest, is replaced. 1..255. */
#ifndef HERMC_AUTH_CHALLENGES
#define HERMC_AUTH_CHALLENGES 2
#endif

/* Requesting indexes whose last answer is remembered (the reply rate
 * limit); when all were answered within HERMC_AUTH_CHALLENGE_INTERVAL_MS a
 * new requester gets no reply (replies_limited). 1..255. */
#ifndef HERMC_AUTH_REQUESTERS
#define HERMC_AUTH_REQUESTERS 2
#endif

/* RFC 8967's recommended values, as routing/auth.hpp's defaults: at most
 * one challenge per index and one reply per requesting index per interval;
 * a reply counts within the timeout of its request; a sender silent for
 * FORGET_MS may be replaced when the table is full. Milliseconds. */
#ifndef HERMC_AUTH_CHALLENGE_INTERVAL_MS
#define HERMC_AUTH_CHALLENGE_INTERVAL_MS 300u
#endif
#ifndef HERMC_AUTH_CHALLENGE_TIMEOUT_MS
#define HERMC_AUTH_CHALLENGE_TIMEOUT_MS 30000u
#endif
#ifndef HERMC_AUTH_FORGET_MS
#define HERMC_AUTH_FORGET_MS 60000u
#endif

#if HERMC_AUTH_PEERS < 1 || HERMC_AUTH_PEERS > 255 || HERMC_AUTH_CHALLENGES < 1 \
  || HERMC_AUTH_CHALLENGES > 255 || HERMC_AUTH_REQUESTERS < 1               \
  || HERMC_AUTH_REQUESTERS > 255
#error "HERMC_AUTH_PEERS, _CHALLENGES and _REQUESTERS must be 1..255"
#endif

/* -- wire constants ------------------------------------------------------------- */

/* Key lengths accepted (hermd's key files: 16..64 bytes). */
#define HERMC_AUTH_KEY_MIN 16u
#define HERMC_AUTH_KEY_MAX 64u
/* The trailer without the tag: key id, index, counter. */
#define HERMC_AUTH_HEAD_SIZE 13u
#define HERMC_AUTH_TRAILER_MAX (HERMC_AUTH_HEAD_SIZE + 16u)
#define HERMC_AUTH_NONCE_SIZE 8u
/* A signed challenge request or reply, at most (9 + 29). */
#define HERMC_AUTH_CHALLENGE_MAX (1u + HERMC_AUTH_NONCE_SIZE + HERMC_AUTH_TRAILER_MAX)
/* Data header flag A (byte 6, bit 5): a trailer ends the packet. */
#define HERMC_AUTH_FLAG_A 0x20u

#define HERMC_AUTH_ERR_ARG (-3)

/** Why a packet was accepted or refused; the order of routing/auth.hpp's
 *  auth_result. */
enum hermc_auth_result {
  HERMC_AUTH_OK = 0,
  HERMC_AUTH_TRUNCATED,        /* shorter than min_body plus a trailer */
  HERMC_AUTH_WRONG_KEY_ID,
  HERMC_AUTH_BAD_TAG,
  HERMC_AUTH_REPLAYED,         /* counter not above the index's last */
  HERMC_AUTH_TABLE_FULL,       /* a new index, the table full of live ones */
  HERMC_AUTH_UNKNOWN_INDEX,    /* right tag, index not known: challenge it */
  HERMC_AUTH_CHALLENGE_FAILED  /* a reply answering no live challenge */
};

/* Counters are as wide as the module's (HERMC_COUNTER_BITS, 32 by default;
 * 16 halves their RAM on an 8-bit core, and they wrap at 65535). */
#if defined(HERMC_COUNTER_BITS) && HERMC_COUNTER_BITS == 16
typedef uint16_t hermc_auth_count_t;
#else
typedef uint32_t hermc_auth_count_t;
#endif

/** Counters. Every hermc_auth_verify is counted once, under its result
 *  (accepted .. unknown_index); challenge, accept_reply and may_reply once
 *  each below. The routing agent's stats map as: rx_auth_failed =
 *  truncated + wrong_key_id + bad_tag; rx_replayed = replayed;
 *  rx_auth_challenged = unknown_index (less the replies among them);
 *  tx_challenges = challenges_sent; tx_challenge_replies = replies. */
struct hermc_auth_counters {
  hermc_auth_count_t signed_packets;
  hermc_auth_count_t accepted;
  hermc_auth_count_t truncated;
  hermc_auth_count_t wrong_key_id;
  hermc_auth_count_t bad_tag;
  hermc_auth_count_t replayed;
  hermc_auth_count_t table_full;
  hermc_auth_count_t unknown_index;
  hermc_auth_count_t challenges_sent;
  hermc_auth_count_t challenges_limited; /* refused by the rate limit */
  hermc_auth_count_t challenges_passed;
  hermc_auth_count_t challenges_failed;  /* accept_reply: anything but ok */
  hermc_auth_count_t replies;
  hermc_auth_count_t replies_limited;
  /* hermc_auth_receive only: */
  hermc_auth_count_t rx_unsigned;        /* data that must be signed, without flag A */
  hermc_auth_count_t rx_malformed;       /* no network packet, or a challenge with a
                                  right tag but not 9 bytes */
};

/** What a right tag says (hermc_auth_verify fills it for ok, replayed,
 *  table_full and unknown_index). */
struct hermc_auth_trailer {
  uint64_t counter;
  uint32_t index;
  /** The packet's length without the trailer. */
  size_t body_len;
};

struct hermc_auth_peer {
  uint64_t counter;   /* the last accepted */
  uint32_t index;
  uint32_t heard_ms;
  uint8_t used;
};

struct hermc_auth_pending {
  uint8_t nonce[HERMC_AUTH_NONCE_SIZE];
  uint32_t index;
  uint32_t sent_ms;
  uint8_t used;
};

struct hermc_auth_requester {
  uint32_t index;
  uint32_t answered_ms;
  uint8_t used;
};

/** One module's authentication state. Set up by hermc_auth_init; the
 *  fields key_id and data_all may be changed after it, the others are the
 *  library's (read counters freely). RAM with the defaults: about 250
 *  bytes on AVR. */
struct hermc_auth {
  struct hermc_hmac_key key;
  uint64_t salt;
  /** The counter the next signed packet carries (1, 2, ...). */
  uint64_t counter;
  uint32_t index;
  uint32_t nonces;     /* challenge nonces derived so far */
  /** In every trailer; packets with another id are refused. Default 1. */
  uint8_t key_id;
  /** 8 or 16. */
  uint8_t tag_bytes;
  /** 1: every data packet is signed and must be (hermd `auth.data: all`);
   *  0 (default, `discovery`): broadcasts and discovery answers only. */
  uint8_t data_all;
  struct hermc_auth_peer peers[HERMC_AUTH_PEERS];
  struct hermc_auth_pending challenges[HERMC_AUTH_CHALLENGES];
  struct hermc_auth_requester requesters[HERMC_AUTH_REQUESTERS];
  struct hermc_auth_counters counters;
};

/** Resets `a` for key `key[0..key_len)` (copied into HMAC pads, not kept:
 *  the caller may wipe its copy), tag length `tag_bytes` (8 or 16), this
 *  boot's sender index `index` (random per boot, as the C++ draws it: a
 *  repeated index restarts its counter at 1 and is refused as a replay by a
 *  neighbour that still remembers it), and `salt`, a number that differs
 *  from boot to boot (the module's instance will do) from which challenge
 *  nonces are derived. key_id 1, data_all 0, counters zero, tables empty.
 *  HERMC_AUTH_ERR_ARG (and `a` unusable) for a NULL key, a key length
 *  outside 16..64 or another tag length; 0 otherwise. O(1): two
 *  compressions. */
int hermc_auth_init(struct hermc_auth *a, const uint8_t *key, size_t key_len,
                    uint8_t tag_bytes, uint32_t index, uint64_t salt);

/** Bytes a signed packet carries more: 21 or 29. */
size_t hermc_auth_trailer_size(const struct hermc_auth *a);

/** Whether the network packet `pkt[0..len)` this module is about to send
 *  must be signed: every control packet (types 1..7); a data packet with
 *  data_all, or for 0xFFFF, or a discovery answer (protocol 1, APO message
 *  kind 2 at payload byte 1; routing/auth.cpp data_needs_auth). 0 for
 *  anything too short to tell. */
int hermc_auth_must_sign(const struct hermc_auth *a, const uint8_t *pkt,
                         size_t len);

/** Signs the network packet `pkt[0..len)` for a link of code `link`: sets
 *  flag A when it is a data packet (len >= 8; the flag is covered by the
 *  tag), appends the trailer with the next counter, and returns the new
 *  length (len + trailer size). When `cap` has no room for the trailer,
 *  returns 0 and changes nothing (no counter used). O(len). */
size_t hermc_auth_sign(struct hermc_auth *a, uint8_t *pkt, size_t len,
                       size_t cap, uint8_t link);

/** Checks the trailer that ends `pkt[0..len)` (received on a link of code
 *  `link` at `now_ms`), in the protocol's order: length (at least `min_body`
 *  bytes before a trailer: 1 for control packets, the header for data), key
 *  id, tag (in constant time). With a right tag `*t` is filled; then a
 *  known index must carry a counter above its last (ok records it and the
 *  time; else replayed), and an index not known gives unknown_index and
 *  changes nothing (challenge it; only hermc_auth_accept_reply makes an
 *  index known). Never reads outside pkt[0..len); pkt may be NULL with len
 *  0. Counted once. */
enum hermc_auth_result hermc_auth_verify(struct hermc_auth *a,
                                         const uint8_t *pkt, size_t len,
                                         uint8_t link, uint32_t now_ms,
                                         size_t min_body,
                                         struct hermc_auth_trailer *t);

/** Starts a challenge of sender `index` (verify said unknown_index):
 *  derives a fresh nonce into `nonce` and remembers it for
 *  HERMC_AUTH_CHALLENGE_TIMEOUT_MS. 0, and nothing changes
 *  (challenges_limited), when a challenge of `index` started less than
 *  HERMC_AUTH_CHALLENGE_INTERVAL_MS ago; 1 otherwise. A new challenge of
 *  the same index replaces its nonce; a full table loses its expired, else
 *  oldest, challenge. */
int hermc_auth_challenge(struct hermc_auth *a, uint32_t index,
                         uint32_t now_ms,
                         uint8_t nonce[HERMC_AUTH_NONCE_SIZE]);

/** A challenge reply carrying `nonce` in a packet whose trailer `t` verify
 *  found right (unknown_index). ok when it answers the live challenge of
 *  t->index (same nonce, compared in constant time, at most the timeout
 *  after it): the index is known from now on with t->counter (never
 *  lowered), and the challenge is used up. table_full when the sender table
 *  is full of senders heard within HERMC_AUTH_FORGET_MS; challenge_failed
 *  otherwise (a wrong nonce leaves the challenge live; a late reply ends
 *  it). */
enum hermc_auth_result hermc_auth_accept_reply(
  struct hermc_auth *a, const struct hermc_auth_trailer *t,
  const uint8_t nonce[HERMC_AUTH_NONCE_SIZE], uint32_t now_ms);

/** Whether to answer a challenge request from sender `index` now, and if
 *  so records it: at most one reply per requesting index per
 *  HERMC_AUTH_CHALLENGE_INTERVAL_MS; when the requester table is full of
 *  indexes answered within that interval, 0. */
int hermc_auth_may_reply(struct hermc_auth *a, uint32_t index,
                         uint32_t now_ms);

/* -- one call per received packet (the routing agent's `authenticate`) ----- */

/** Packets to send back on the link the checked packet came on, in this
 *  order: `challenge` (a signed challenge request, when challenge_len > 0),
 *  then `reply` (a signed challenge reply, when reply_len > 0) and right
 *  after the reply this module's hello (signed as usual), so that the
 *  requester, which knows our index once the reply is in, takes us as its
 *  neighbour at once. Owned by the caller; filled by hermc_auth_receive. */
struct hermc_auth_out {
  uint8_t challenge_len;
  uint8_t reply_len;
  uint8_t challenge[HERMC_AUTH_CHALLENGE_MAX];
  uint8_t reply[HERMC_AUTH_CHALLENGE_MAX];
};

/** Checks a network packet `pkt[0..len)` received on a link of code `link`
 *  at `now_ms`, as docs/protocol.md "Receiving" and routing/agent_auth.cpp
 *  do. Returns 1 when the caller handles the packet as usual, its first
 *  `*body_len` bytes only (the trailer cut off; a data packet keeps flag A
 *  set, which tells it was verified): a data packet without flag A that
 *  need not be signed (data_all 0: unicast, not a discovery answer), or a
 *  packet with a right tag and a fresh counter from a known index that is
 *  not a challenge request or reply. Returns 0 when the packet is dropped:
 *  counted in a->counters, and `out` may hold a challenge for an unknown
 *  index (rate-limited) and a reply to a challenge request (whatever its
 *  index and counter; rate-limited); a challenge reply may have made its
 *  index known. `pkt` is only read (never outside [pkt, pkt + len)); `out`
 *  is always reset first. */
int hermc_auth_receive(struct hermc_auth *a, const uint8_t *pkt, size_t len,
                       uint8_t link, uint32_t now_ms, size_t *body_len,
                       struct hermc_auth_out *out);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_AUTH_H */
