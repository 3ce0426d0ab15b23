/* hermc_net.h: network packets of HERM (docs/protocol.md, "Network
 * packets") as a leaf module needs them: the data header, hello, update,
 * seqno request and claim. The C++ peer is routing/wire.hpp; the byte
 * strings of tests/routing/wire_test.cpp pin both.
 *
 * Encoders write into a buffer the caller owns and return the bytes
 * written, or 0 when `cap` is too small (nothing useful is written then).
 * Decoders are total: any byte string gives HERMC_NET_OK and a filled
 * struct, or an error code saying what was wrong; they never read past `n`
 * and keep no state. Checks of meaning (a hello from ourselves, a seqno
 * request for another module) are the module's (hermc.c), not theirs.
 * Every call is O(n) in the packet, uses no heap and a few bytes of stack.
 */
#ifndef HERMC_NET_H
#define HERMC_NET_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Module ids: 0 none, 0xFFFF every module (broadcast). */
#define HERMC_NO_MODULE 0x0000u
#define HERMC_BROADCAST 0xFFFFu

/* Hops a data packet may take (routing's default_hop_limit, max_route_hops). */
#define HERMC_DEFAULT_HOP_LIMIT 32u
#define HERMC_MAX_ROUTE_HOPS 32u
/* Update entries per packet at most (routing's max_update_entries). */
#define HERMC_MAX_UPDATE_ENTRIES 24u
/* Packet-size classes and their bounds (routing/metric.hpp). */
#define HERMC_SIZE_CLASSES 4u
/* Unreachable (a retraction). */
#define HERMC_INFINITE_METRIC 0xFFFFFFFFul
/* Upper-layer protocols of data packets. */
#define HERMC_PROTOCOL_RAW 0u
#define HERMC_PROTOCOL_ASL 1u

/* Exact sizes of the control packets without an authentication trailer. */
#define HERMC_DATA_HEADER_SIZE 8u
#define HERMC_FLOOD_HEADER_SIZE 12u
#define HERMC_HELLO_SIZE 15u
#define HERMC_UPDATE_HEADER_SIZE 12u
#define HERMC_SEQNO_REQUEST_SIZE 8u
#define HERMC_CLAIM_SIZE 20u
#define HERMC_CONFLICT_SIZE 28u
#define HERMC_CHALLENGE_SIZE 9u

/* The packet type (bits 3..0 of the first byte). */
enum hermc_packet_type {
  HERMC_PT_DATA = 0,
  HERMC_PT_HELLO = 1,
  HERMC_PT_UPDATE = 2,
  HERMC_PT_SEQNO_REQUEST = 3,
  HERMC_PT_CLAIM = 4,
  HERMC_PT_CONFLICT = 5,
  HERMC_PT_CHALLENGE_REQUEST = 6,
  HERMC_PT_CHALLENGE_REPLY = 7
};

/* Link codes (routing/metric.hpp link_code). */
enum hermc_link_code {
  HERMC_LINK_UNKNOWN = 0,
  HERMC_LINK_USB11 = 1,
  HERMC_LINK_USB20 = 2,
  HERMC_LINK_IEEE1394A = 3,
  HERMC_LINK_IEEE1394B = 4,
  HERMC_LINK_CAN20 = 5,
  HERMC_LINK_ETHERNET = 6,
  HERMC_LINK_RS232C = 7
};

/* What a decoder found wrong. */
enum hermc_net_error {
  HERMC_NET_OK = 0,
  HERMC_NET_EMPTY,         /* no byte at all */
  HERMC_NET_BAD_VERSION,   /* bits 7..4 of byte 0 are not 1 */
  HERMC_NET_BAD_TYPE,      /* a type above 7, or not the one asked for */
  HERMC_NET_TRUNCATED,     /* shorter than its layout */
  HERMC_NET_TRAILING,      /* bytes after the end of a control packet */
  HERMC_NET_RESERVED,      /* a reserved flag bit set */
  HERMC_NET_BAD_FLOOD,     /* flood id on a packet not for 0xFFFF, or 0 */
  HERMC_NET_OVER_BOUND,    /* update count above 24, hops above 32 */
  HERMC_NET_BAD_LINK_CODE  /* a path code above 7 */
};

/* The packet type of `p[0..n)`, checking only the first byte. */
enum hermc_net_error hermc_peek_type(const uint8_t *p, size_t n,
                                     enum hermc_packet_type *type);

/* -- data packets ------------------------------------------------------- */

struct hermc_data_header {
  uint16_t src;
  uint16_t dst;
  uint8_t hop_limit;
  uint8_t size_class;    /* 0..3; encoded from its low 2 bits */
  uint8_t priority;      /* 0..3, lower is more urgent; low 2 bits */
  uint8_t protocol;
  uint32_t flood_id;     /* non-zero: a flooded broadcast (dst 0xFFFF) */
  uint8_t authenticated; /* flag A: a trailer ends the packet */
};

/* Writes the header (8 bytes, 12 with a flood id); the payload follows at
 * the returned offset. 0 if cap is too small. */
size_t hermc_data_header_encode(const struct hermc_data_header *h,
                                uint8_t *out, size_t cap);

/* Decodes the header of the data packet p[0..n); on HERMC_NET_OK
 * `*payload_at` is where the payload starts (8 or 12), and the payload is
 * everything after it (with flag A, the trailer is not removed here). */
enum hermc_net_error hermc_data_header_decode(const uint8_t *p, size_t n,
                                              struct hermc_data_header *h,
                                              size_t *payload_at);

/* The size class of a payload of `bytes` (8, 64, 1024, larger: 0..3), as
 * routing/metric.hpp size_class_of. */
uint8_t hermc_size_class_of(size_t bytes);

/* -- hello -------------------------------------------------------------- */

struct hermc_hello {
  uint16_t sender;
  uint64_t instance;
  uint16_t seqno;
  uint16_t interval_ms; /* 0: goodbye */
};

size_t hermc_hello_encode(const struct hermc_hello *x, uint8_t *out,
                          size_t cap);
enum hermc_net_error hermc_hello_decode(const uint8_t *p, size_t n,
                                        struct hermc_hello *x);

/* -- update ------------------------------------------------------------- */

/* One advertised destination. `path[k]` points to `hops[k]` link codes
 * (the caller's memory when encoding; into the decoded packet when
 * decoding). A class with metric HERMC_INFINITE_METRIC is a retraction and
 * carries neither hops nor path. */
struct hermc_update_entry {
  uint16_t origin;
  uint16_t seqno;
  uint32_t metric[HERMC_SIZE_CLASSES];
  uint8_t hops[HERMC_SIZE_CLASSES];
  const uint8_t *path[HERMC_SIZE_CLASSES];
};

struct hermc_update_header {
  uint16_t sender;
  uint64_t instance;
  uint8_t count;
};

/* Writes an update of `count` entries (at most 24: more is refused, 0
 * returned). A class whose hops exceed 32 or whose path holds a code above
 * 7 is written as a retraction, as the C++ encoder does. 0 if cap is too
 * small. */
size_t hermc_update_encode(uint16_t sender, uint64_t instance,
                           const struct hermc_update_entry *entries,
                           uint8_t count, uint8_t *out, size_t cap);

/* Checks the whole update p[0..n) and reads its header. The first
 * `max_entries` entries go to `entries` (may be NULL with 0), their paths
 * pointing into `p`; the others are checked, not stored. */
enum hermc_net_error hermc_update_decode(const uint8_t *p, size_t n,
                                         struct hermc_update_header *h,
                                         struct hermc_update_entry *entries,
                                         uint8_t max_entries);

/* -- seqno request ------------------------------------------------------ */

struct hermc_seqno_request {
  uint16_t sender;
  uint16_t origin;
  uint16_t seqno;
  uint8_t hop_count;
};

size_t hermc_seqno_request_encode(const struct hermc_seqno_request *x,
                                  uint8_t *out, size_t cap);
enum hermc_net_error hermc_seqno_request_decode(const uint8_t *p, size_t n,
                                                struct hermc_seqno_request *x);

/* True if seqno `a` is newer than `b` modulo 2^16 (RFC 8966 3.2.1). */
int hermc_seqno_newer(uint16_t a, uint16_t b);

/* -- claim (a static module's announcement) ----------------------------- */

struct hermc_claim {
  uint16_t id;
  uint64_t nonce;    /* an announcement: nonce == instance */
  uint64_t instance;
  uint8_t hop_limit;
};

size_t hermc_claim_encode(const struct hermc_claim *x, uint8_t *out,
                          size_t cap);
enum hermc_net_error hermc_claim_decode(const uint8_t *p, size_t n,
                                        struct hermc_claim *x);

/* -- metrics (routing/metric.hpp) --------------------------------------- */

/* A link's metric in each class: cost * ceil(class bytes / mtu),
 * saturating at HERMC_INFINITE_METRIC; all infinite when mtu is 0. `cost`
 * is the paper's Table 1 cost of the link (RS232C 47, CAN2.0 30, ...), as
 * channels/link_profile.hpp link_cost computes it from the bit rate. */
void hermc_link_metrics(uint32_t cost, uint32_t mtu,
                        uint32_t metrics[HERMC_SIZE_CLASSES]);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_NET_H */
