/* hermc_asl.h: APO messages (docs/protocol.md, "APO messages"), the
 * payload of data packets of protocol 1. The C++ peer is actors/asl_wire.hpp;
 * the byte strings of tests/actors/asl_wire_test.cpp pin both.
 *
 * Encoders write into a buffer the caller owns and return the bytes written,
 * or 0 when `cap` is too small or a string is longer than 255 bytes. The
 * decoder is total: any byte string gives HERMC_ASL_OK and a message whose
 * strings and payload point INTO the input (zero-copy: valid while the input
 * is), or an error code; it refuses exactly what the C++ decoder refuses
 * (trailing bytes, bools other than 00/01, query_by above 2, a query by any
 * with a pattern, answers above 64 entries or above the bytes present,
 * request id 0 on responses, reliable requests and acks). O(n), no heap,
 * no state.
 */
#ifndef HERMC_ASL_H
#define HERMC_ASL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define HERMC_ASL_VERSION 1u
#define HERMC_ASL_MAX_STRING 255u
#define HERMC_ASL_MAX_ANSWER_ENTRIES 64u

/* The error category "herm" as CAF's atom value, and the herm::ec codes a
 * leaf module sends or reads (channels/error.hpp, routing/error.hpp,
 * actors/runtime/error.hpp). */
#define HERMC_ERROR_CATEGORY_HERM 0x000000000FB6ADF2ull
#define HERMC_EC_INVALID_PARAMETER 4u
#define HERMC_EC_QUEUE_FULL 10u
#define HERMC_EC_TIMEOUT 13u
#define HERMC_EC_NO_ROUTE 14u
#define HERMC_EC_UNKNOWN_TYPE 15u
#define HERMC_EC_APO_GONE 16u
#define HERMC_EC_NOT_FOUND 17u
#define HERMC_EC_UNAVAILABLE 19u

enum hermc_asl_kind {
  HERMC_ASL_QUERY = 1,
  HERMC_ASL_ANSWER = 2,
  HERMC_ASL_REQUEST = 3,
  HERMC_ASL_RESPONSE = 4,
  HERMC_ASL_WATCH = 5,
  HERMC_ASL_UNWATCH = 6,
  HERMC_ASL_DOWN = 7,
  HERMC_ASL_WITHDRAW = 8,
  HERMC_ASL_SUBSCRIBE = 9,
  HERMC_ASL_UNSUBSCRIBE = 10,
  HERMC_ASL_PUBLISH = 11,
  HERMC_ASL_ADVERTISE = 12,
  HERMC_ASL_RELIABLE_REQUEST = 13,
  HERMC_ASL_ACK = 14
};

enum hermc_query_by { HERMC_BY_NAME = 0, HERMC_BY_TYPE = 1, HERMC_BY_ANY = 2 };

enum hermc_asl_error {
  HERMC_ASL_OK = 0,
  HERMC_ASL_EMPTY,
  HERMC_ASL_BAD_VERSION,
  HERMC_ASL_BAD_KIND,
  HERMC_ASL_TRUNCATED,
  HERMC_ASL_TRAILING,
  HERMC_ASL_BAD_BOOL,
  HERMC_ASL_BAD_QUERY_BY,
  HERMC_ASL_PATTERN_ON_ANY,
  HERMC_ASL_OVER_BOUND,
  HERMC_ASL_ZERO_REQUEST_ID
};

/* A byte string inside a decoded message (not NUL-terminated). */
struct hermc_bytes {
  const uint8_t *data;
  size_t size;
};

/* One decoded APO message. Which fields hold depends on `kind`:
 *   query:       id32 = query_id, by, text = pattern
 *   answer:      id32 = query_id, count, entries (raw: walk them with
 *                hermc_asl_answer_entry)
 *   request, reliable request: request_id, id32 = apo, oneway (reliable:
 *                the flag; plain: request_id == 0), payload
 *   response:    request_id, ok, payload (ok) or err_category, err_code,
 *                text = context (not ok)
 *   watch, unwatch: id32 = apo
 *   down:        id32 = apo, err_category, err_code, text = context
 *   withdraw:    id32 = apo, text = name
 *   subscribe:   text = topic, u32 = lease_ms
 *   unsubscribe, advertise: text = topic
 *   publish:     text = topic, u32 = seq, payload
 *   ack:         request_id
 * Every field a kind does not carry is 0 (byte strings {NULL, 0}): a
 * response with a payload has err_category and err_code 0, an error
 * response an empty payload. */
struct hermc_asl_msg {
  enum hermc_asl_kind kind;
  uint32_t id32;
  uint64_t request_id;
  uint32_t u32;
  uint8_t by;
  uint8_t ok;
  uint8_t oneway;
  uint8_t count;
  uint8_t err_code;
  uint64_t err_category;
  struct hermc_bytes text;
  struct hermc_bytes payload;
  struct hermc_bytes entries;
};

/* Decodes the APO message p[0..n). */
enum hermc_asl_error hermc_asl_decode(const uint8_t *p, size_t n,
                                      struct hermc_asl_msg *m);

/* One entry of an answer. */
struct hermc_asl_entry {
  uint32_t apo;
  struct hermc_bytes name;
  struct hermc_bytes type;
};

/* Reads the entry at `*at` of a decoded answer's `entries` (start with
 * *at = 0) and moves `*at` past it. Returns 0 when none is left; every
 * entry hermc_asl_decode accepted reads. */
int hermc_asl_answer_entry(const struct hermc_asl_msg *m, size_t *at,
                           struct hermc_asl_entry *e);

/* -- encoders ------------------------------------------------------------ */

size_t hermc_asl_query_encode(uint32_t query_id, enum hermc_query_by by,
                              const char *pattern, size_t pattern_len,
                              uint8_t *out, size_t cap);

/* The header of an answer with `count` entries; append each entry with
 * hermc_asl_answer_entry_encode. */
size_t hermc_asl_answer_begin(uint32_t query_id, uint8_t count, uint8_t *out,
                              size_t cap);
size_t hermc_asl_answer_entry_encode(uint32_t apo, const char *name,
                                     size_t name_len, const char *type,
                                     size_t type_len, uint8_t *out,
                                     size_t cap);

/* A request (reliable = 0) or a reliable request (reliable = 1); the APO
 * payload follows at the returned offset (header only: 14 or 15 bytes). */
size_t hermc_asl_request_header(uint64_t request_id, uint32_t apo,
                                int reliable, int oneway, uint8_t *out,
                                size_t cap);

/* A response with a payload: the header (11 bytes); the payload follows. */
size_t hermc_asl_response_ok_header(uint64_t request_id, uint8_t *out,
                                    size_t cap);

/* A response with an error; a context above 255 bytes is cut to 255. */
size_t hermc_asl_response_error_encode(uint64_t request_id, uint64_t category,
                                       uint8_t code, const char *context,
                                       size_t context_len, uint8_t *out,
                                       size_t cap);

size_t hermc_asl_subscribe_encode(const char *topic, size_t topic_len,
                                  uint32_t lease_ms, uint8_t *out,
                                  size_t cap);

/* The header of a publish (3 + topic + 4 bytes); the payload follows. */
size_t hermc_asl_publish_header(const char *topic, size_t topic_len,
                                uint32_t seq, uint8_t *out, size_t cap);

size_t hermc_asl_advertise_encode(const char *topic, size_t topic_len,
                                  uint8_t *out, size_t cap);

size_t hermc_asl_ack_encode(uint64_t request_id, uint8_t *out, size_t cap);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_ASL_H */
