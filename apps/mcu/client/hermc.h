/* hermc.h: a board as a HERM module, driven by the application's main loop.
 *
 * The module is a LEAF (a stub): it holds a static module id, says hello on
 * its one serial link, advertises itself so that its neighbour (a hermd)
 * routes to it, answers discovery queries for its APOs, serves requests,
 * sends requests to remote APOs and publishes topics. It never forwards a
 * packet for another module and never relays a flood.
 *
 * What the application provides (docs/mcu.md, "Porting"):
 *   - a byte source: every byte its UART received goes to hermc_feed;
 *   - a byte sink: hermc_poll_tx hands out the bytes to write to the UART;
 *   - a millisecond clock: hermc_tick(now_ms) at least every 100 ms;
 *   - an instance: a number that differs from boot to boot (a counter kept
 *     in EEPROM, ADC noise, a timer's value at the first received byte). A
 *     neighbour tells a rebooted board from a live one by it.
 *
 * Model (as libcanard): no heap, no I/O, no clock, no floating point, no
 * recursion. All state is one `struct hermc_module` the application
 * allocates (statically: its size is sizeof(struct hermc_module), fixed by
 * the macros of hermc_config.h). One module is used from one context (the
 * main loop); no call is reentrant for one module. An APO handler must
 * call no hermc_ function of its module (its response is being built in
 * the module's scratch buffer); a response callback may call hermc_request
 * and hermc_publish, but not hermc_feed, hermc_tick or hermc_poll_tx.
 *
 * Bad input of any kind (bytes that do not frame, packets that do not
 * decode, APO messages for someone else, replies nobody asked for) is
 * dropped and counted in `struct hermc_counters` (and in the link's own
 * counters, hermc_link.h), never undefined behaviour. Every table that the
 * network can fill (floods remembered, subscribers) is bounded by a macro
 * of hermc_config.h and counts what it refused or evicted.
 */
#ifndef HERMC_H
#define HERMC_H

#include <stddef.h>
#include <stdint.h>

#include "hermc_config.h"
#include "hermc_link.h"
#include "hermc_net.h"
#include "hermc_asl.h"
#if HERMC_AUTH
#include "hermc_auth.h"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* -- configuration ------------------------------------------------------ */

struct hermc_config {
  /** This module's id, 0x0001..0xFFFE (static: the board never claims). */
  uint16_t module_id;
  /** Differs from boot to boot; never 0 (see the top of this file). */
  uint64_t instance;
  /** Between two hellos, ms (1..65535); HERM's default 1000. */
  uint16_t hello_interval_ms;
  /** An update for our own id every this many hellos (1..255); HERM's
   *  default 4. A neighbour keeps our route for its own hello interval x
   *  update_every x 3.5, so keep ours no longer than its. */
  uint8_t update_every;
  /** Default deadline of a request to a remote APO, ms. */
  uint32_t request_timeout_ms;
  /** Discovery of a remote APO asks again after this many ms, doubling up
   *  to discovery_max_ms until it is answered. */
  uint16_t discovery_min_ms;
  uint32_t discovery_max_ms;
  /** Escaped (XON/XOFF) serial framing; both ends must agree (only with
   *  HERMC_ESCAPED, hermc_config.h). */
  uint8_t escaped;
};

/** The defaults above for module `id` and `instance`. */
void hermc_config_default(struct hermc_config *cfg, uint16_t id,
                          uint64_t instance);

/* -- results ------------------------------------------------------------ */

/* HERMC_OK (0), HERMC_ERR_FULL, HERMC_ERR_TOO_BIG and HERMC_ERR_ARG come
 * from hermc_link.h. */
/** A remote APO is not discovered yet: nothing was sent (retry later). */
#define HERMC_ERR_NOT_READY (-4)
/** A bounded table is full: nothing was done (counted). */
#define HERMC_ERR_NO_ROOM (-5)

/** How a request to a remote APO ended, given to its callback. */
enum hermc_status {
  HERMC_STATUS_OK = 0,      /**< a response with a payload */
  HERMC_STATUS_ERROR = 1,   /**< a response with an error (category, code) */
  HERMC_STATUS_TIMEOUT = 2  /**< no response before the deadline */
};

/* -- APOs ---------------------------------------------------------------- */

/** Serves one request to a local APO. `req[0..req_len)` is its APO payload
 *  (valid during the call only). Write the response's APO payload into
 *  `resp[0..resp_cap)` and its length into `*resp_len`, then return 0; or
 *  return a herm::ec code (HERMC_EC_INVALID_PARAMETER, ...) and the
 *  requester gets a typed error in category herm. For one-way requests the
 *  return value and the response are ignored. */
typedef uint8_t (*hermc_handler)(void *ctx, const uint8_t *req,
                                 size_t req_len, uint8_t *resp,
                                 size_t resp_cap, size_t *resp_len);

/** The end of a request to a remote APO. `payload` (OK: the response's APO
 *  payload) is valid during the call only; on ERROR `err_code` is the code
 *  in category `err_category` (HERMC_ERROR_CATEGORY_HERM: a herm::ec). */
typedef void (*hermc_response_fn)(void *ctx, enum hermc_status status,
                                  const uint8_t *payload, size_t len,
                                  uint64_t err_category, uint8_t err_code);

struct hermc_apo {
  const char *name;   /* not owned: must outlive the module */
  const char *type;
  hermc_handler handler;
  void *ctx;
};

struct hermc_remote_slot {
  const char *name;   /* not owned */
  uint16_t module;    /* 0 while not discovered */
  uint32_t apo;
  uint32_t query_id;  /* of the query under way */
  uint32_t next_query_ms;
  uint32_t backoff_ms;
};

struct hermc_pending {
  uint32_t request_id; /* 0: free slot (the wire's 64-bit id, upper half 0) */
  uint32_t deadline_ms;
  uint16_t module;     /* the module it went to: its response comes from it */
  uint8_t remote;
  hermc_response_fn fn;
  void *ctx;
};

#if HERMC_TOPICS
struct hermc_topic_slot {
  const char *name;   /* not owned */
  uint32_t seq;
  uint8_t advertised;
};

struct hermc_subscriber {
  uint16_t module;    /* 0: free slot */
  uint8_t topic;
  uint32_t lease_end_ms;
};
#endif

struct hermc_flood {
  uint16_t src;
  uint32_t flood_id;
  uint32_t seen_ms;
};

/* -- counters ------------------------------------------------------------ */

/** What the module did and refused since hermc_init. Link-level drops
 *  (framing, CRC, reassembly) are in m->rx.frame_stats and m->rx.reasm. */
struct hermc_counters {
  hermc_count_t rx_packets;        /* packets from the link */
  hermc_count_t rx_malformed;      /* network packets that did not decode */
  hermc_count_t rx_ignored;        /* nothing for a leaf: updates (a leaf sends
                                 everything to its neighbour; not decoded),
                                 claims, conflicts, challenges, seqno
                                 requests for others, goodbyes of others */
  hermc_count_t rx_not_for_us;     /* data for another module: a leaf never
                                 forwards */
  hermc_count_t rx_auth_unsupported; /* data with flag A, and no key (no
                                 HERMC_AUTH, or hermc_set_key not called):
                                 where its payload ends is unknown. With a
                                 key, refusals are in m->auth.counters */
  hermc_count_t rx_flood_duplicates; /* floods seen before (or our own) */
  hermc_count_t flood_evictions;   /* remembered floods replaced while younger
                                 than HERMC_FLOOD_MEMORY_MS (table full) */
  hermc_count_t rx_asl_malformed;  /* APO messages that did not decode */
  hermc_count_t rx_asl_ignored;    /* APO messages a leaf does not act on
                                     (also subscriptions without HERMC_TOPICS
                                     and reliable requests without
                                     HERMC_RELIABLE) */
  hermc_count_t rx_unknown_apo;    /* requests for an APO we do not have */
  hermc_count_t rx_unexpected_response; /* responses matching no pending one */
  hermc_count_t requests_served;
  hermc_count_t queries_answered;
  hermc_count_t responses_received;
  hermc_count_t request_timeouts;
  hermc_count_t requests_refused;  /* pending table full, or not discovered */
  hermc_count_t subscribers_refused; /* subscribe past HERMC_MAX_SUBSCRIBERS */
  hermc_count_t publications_sent;
  hermc_count_t tx_packets;
  hermc_count_t tx_dropped;        /* packets the link refused (ring full) or
                                 that did not fit HERMC_MAX_PACKET */
  hermc_count_t tx_hellos;
  hermc_count_t tx_updates;
  hermc_count_t seqno_requests_answered;
  hermc_count_t neighbour_changes; /* a new neighbour, or a new instance of it */
};

/* -- the module ----------------------------------------------------------- */

struct hermc_module {
  struct hermc_config cfg;
  hermc_link_rx rx;
  hermc_link_tx tx;
  struct hermc_counters counters;
  uint32_t now_ms;
  uint32_t next_hello_ms;
  uint16_t hello_seqno;
  uint16_t own_seqno;       /* our route's seqno (Babel) */
  uint8_t hellos_to_update;
  uint8_t started;          /* the first tick happened */
  /* The neighbour heard last (a point-to-point link has one). */
  uint16_t neighbour;
  uint64_t neighbour_instance;
  uint32_t neighbour_heard_ms;
  uint16_t neighbour_interval_ms;
  uint32_t next_query_id;
  uint32_t next_flood_id;
  uint32_t next_request_id;
  uint8_t napos, nremotes, ntopics;
  uint8_t flood_next;       /* the ring's next slot in floods */
#if HERMC_MAX_APOS > 0
  struct hermc_apo apos[HERMC_MAX_APOS];
#endif
  struct hermc_remote_slot remotes[HERMC_MAX_REMOTES];
  struct hermc_pending pending[HERMC_MAX_PENDING];
#if HERMC_TOPICS
  struct hermc_topic_slot topics[HERMC_MAX_TOPICS];
  struct hermc_subscriber subscribers[HERMC_MAX_SUBSCRIBERS];
#endif
  struct hermc_flood floods[HERMC_FLOOD_CACHE];
#if HERMC_AUTH
  uint8_t keyed;            /* hermc_set_key succeeded */
  struct hermc_auth auth;   /* its counters: what was signed and refused */
  struct hermc_auth_out auth_out;
#endif
  /* Scratch: one outgoing packet is built here, then framed into tx. */
  uint8_t scratch[HERMC_MAX_PACKET];
};

/** Resets `m` with `cfg` (copied): no APO, nothing heard, counters zero.
 *  HERMC_ERR_ARG when the id is 0 or 0xFFFF, the instance 0, the hello
 *  interval or update_every 0, or escaped framing asked for in a build
 *  without HERMC_ESCAPED. Nothing is sent before the first hermc_tick.
 *  O(sizeof *m). */
int hermc_init(struct hermc_module *m, const struct hermc_config *cfg);

/** Consumes bytes received from the link, in any chunking; handles every
 *  packet they complete (answers go to the transmit ring). O(n) plus the
 *  handling of each packet: O(APOs) for a query, a handler call per
 *  request. `bytes` is only read during the call. */
void hermc_feed(struct hermc_module *m, const uint8_t *bytes, size_t n);

/** Moves up to `cap` bytes to send on the link into `out`; returns how many
 *  (0: nothing to send). */
size_t hermc_poll_tx(struct hermc_module *m, uint8_t *out, size_t cap);

/** The millisecond clock (wrapping uint32_t, called at least every 100 ms
 *  for timely hellos). Sends hellos, updates, discovery retries; expires
 *  requests (their callbacks run from here with HERMC_STATUS_TIMEOUT),
 *  subscriber leases and reassemblies. The first call starts the module
 *  (first hello, advertisements). O(tables). */
void hermc_tick(struct hermc_module *m, uint32_t now_ms);

/** Registers a local APO; `name`, `type` (at most 255 bytes each) and
 *  `ctx` must outlive the module. Returns its APO number (1..) as
 *  requests address it, or HERMC_ERR_NO_ROOM past HERMC_MAX_APOS,
 *  HERMC_ERR_ARG for a NULL handler or an over-long name. */
int hermc_register_apo(struct hermc_module *m, const char *name,
                       const char *type, hermc_handler handler, void *ctx);

/** Names a remote APO to send requests to, and starts discovering it (a
 *  flooded query by name, repeated with backoff until answered; again after
 *  a timeout or an error saying it is gone). Returns a handle (0..) for
 *  hermc_request, or HERMC_ERR_NO_ROOM past HERMC_MAX_REMOTES. */
int hermc_remote(struct hermc_module *m, const char *name);

/** 1 when remote `r` is discovered (requests can go), else 0. */
int hermc_remote_ready(const struct hermc_module *m, int r);

/** Sends APO payload `payload[0..len)` to remote APO `r`. With `fn` NULL it
 *  is one-way (no response, no pending slot); otherwise `fn(ctx, ...)` runs
 *  exactly once: with the response, or with HERMC_STATUS_TIMEOUT after
 *  `timeout_ms` (0: the config's request_timeout_ms). Returns HERMC_OK,
 *  HERMC_ERR_NOT_READY (not discovered yet), HERMC_ERR_NO_ROOM (every
 *  HERMC_MAX_PENDING slot busy), HERMC_ERR_TOO_BIG (does not fit one
 *  packet) or HERMC_ERR_FULL (the transmit ring is full); nothing is sent
 *  and `fn` never runs unless it returns HERMC_OK. `payload` is copied. */
int hermc_request(struct hermc_module *m, int r, const uint8_t *payload,
                  size_t len, hermc_response_fn fn, void *ctx,
                  uint32_t timeout_ms);

#if HERMC_TOPICS
/** Declares a topic this module publishes (`name` outlives the module);
 *  advertised when a neighbour is met (at once if one is known already).
 *  Returns its handle (0..) or
 *  HERMC_ERR_NO_ROOM past HERMC_MAX_TOPICS. */
int hermc_topic(struct hermc_module *m, const char *name);

/** Publishes APO payload `payload[0..len)` on topic `t` to every module
 *  whose subscription lease holds. Returns the number of subscribers sent
 *  to (0 when none), or a negative HERMC_ERR_* (nothing sent). */
int hermc_publish(struct hermc_module *m, int t, const uint8_t *payload,
                  size_t len);
#endif /* HERMC_TOPICS */

#if HERMC_AUTH
/** Keys the module for a keyed network (hermd's `auth` section; every
 *  setting must match the network's): `key[0..key_len)` (16..64 bytes,
 *  copied into HMAC pads; the caller may wipe its copy), `key_id` (0..255),
 *  `tag_bytes` (8 or 16), `data_all` (0: hermd's `data: discovery`, 1:
 *  `data: all`), and `index`, this boot's sender index: it must differ from
 *  boot to boot (a random number; a repeated index restarts the packet
 *  counter at 1 and a neighbour that remembers it refuses its packets as
 *  replays for up to HERMC_AUTH_FORGET_MS). Call after hermc_init and
 *  before the first hermc_tick. From then on:
 *   - every control packet, broadcast and discovery answer (every data
 *     packet with data_all) leaves with a trailer (hermc_auth_must_sign);
 *     APO payloads have hermc_auth_trailer_size() bytes less room;
 *   - every received packet is checked first (hermc_auth_receive): packets
 *     with a wrong key, a replayed counter, or that must be signed and are
 *     not, are dropped and counted in m->auth.counters; a right tag from an
 *     index not known yet is challenged (RFC 8967), and the neighbour's
 *     challenges are answered, followed by a hello.
 *  HERMC_ERR_ARG (and the module stays unkeyed) for a NULL key, a key
 *  length outside 16..64, or a tag length other than 8 or 16. O(1). */
int hermc_set_key(struct hermc_module *m, const uint8_t *key, size_t key_len,
                  uint8_t key_id, uint8_t tag_bytes, uint8_t data_all,
                  uint32_t index);
#endif /* HERMC_AUTH */

/** Handles one network packet `pkt[0..len)` as if the link had delivered
 *  it (the link calls this; tests and CAN boards may too). */
void hermc_handle_packet(struct hermc_module *m, const uint8_t *pkt,
                         size_t len);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_H */
