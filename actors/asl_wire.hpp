#pragma once

// Wire format of the Application Support Layer: the messages application
// support actors of two modules exchange inside data packets of protocol
// `asl_protocol` (docs/protocol.md, "APO messages"). An APO's own message
// travels inside as an opaque APO payload (actors/marshal.hpp).
//
// Every message starts with a version byte (`asl_wire_version`) and a kind
// byte. Integers are little endian; strings are a 1-byte length and that many
// bytes (UTF-8, at most 255); byte strings that end a message take the rest
// of it. Decoders are total: any byte string yields a value or
// `ec::invalid_parameter` naming the kind and what was wrong; every length
// and count is checked against the bytes present before anything is
// allocated; a message with trailing bytes is refused. They are fuzzed
// (tests/fuzz/fuzz_asl_wire.cpp).
//
// Bounds per call (all through channels/le_codec.hpp): time O(n) in the
// message size for decode_asl and in the encoded size for encode;
// peek_asl_kind is O(1). encode allocates nothing but the growth of `out`;
// decode_asl allocates only the message it returns (strings of at most 255
// bytes, at most max_answer_entries entries, payloads of at most n bytes),
// never reads past `size`, and keeps no state.

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include "caf/expected.hpp"

#include "channels/messages.hpp"

namespace herm {

/// Upper-layer protocol number of ASL messages in data packets.
constexpr uint8_t asl_protocol = 1;

constexpr uint8_t asl_wire_version = 1;

/// Longest name, type or topic on the wire.
constexpr size_t max_asl_string = 255;

/// Most entries in one discovery answer.
constexpr size_t max_answer_entries = 64;

enum class asl_kind : uint8_t {
  query = 1,
  answer = 2,
  request = 3,
  response = 4,
  watch = 5,
  unwatch = 6,
  down = 7,
  withdraw = 8,
  subscribe = 9,
  unsubscribe = 10,
  publish = 11,
  advertise = 12,
  reliable_request = 13,
  ack = 14,
};

/// What a discovery query matches.
enum class query_by : uint8_t {
  name = 0,  ///< the APO's name equals `pattern`
  type = 1,  ///< the APO's type (interface) equals `pattern`
  any = 2,   ///< every APO (pattern ignored, sent empty)
};

/// An error as it travels: CAF's category atom (its 64-bit value), code and
/// context text (truncated to 255 bytes).
struct wire_error {
  uint64_t category = 0;
  uint8_t code = 0;
  std::string context;
};

/// Broadcast: "who hosts APOs matching this?"
struct asl_query {
  uint32_t query_id = 0;
  query_by by = query_by::name;
  std::string pattern;
};

/// One APO in an answer.
struct asl_entry {
  uint32_t apo = 0;
  std::string name;
  std::string type;
};

/// Unicast to the querier: the matches on the answering module (possibly
/// several answers per query when there are more than max_answer_entries).
struct asl_answer {
  uint32_t query_id = 0;
  std::vector<asl_entry> entries;
};

/// A message for APO `apo` on the receiving module. `request_id` 0 means
/// one-way (no response expected); otherwise the receiver answers with a
/// response carrying the same id. `payload` is an APO payload.
struct asl_request {
  uint64_t request_id = 0;
  uint32_t apo = 0;
  byte_buffer payload;
};

/// The answer to a request: either an APO payload (`ok`) or an error.
struct asl_response {
  uint64_t request_id = 0;
  bool ok = true;
  byte_buffer payload; ///< when ok
  wire_error error;    ///< when !ok
};

/// "Tell me when APO `apo` on your module exits" / "stop telling me".
struct asl_watch {
  uint32_t apo = 0;
};

struct asl_unwatch {
  uint32_t apo = 0;
};

/// APO `apo` exited (or never existed there) for `reason`; to watchers.
struct asl_down {
  uint32_t apo = 0;
  wire_error reason;
};

/// Broadcast when an APO leaves the application table.
struct asl_withdraw {
  uint32_t apo = 0;
  std::string name;
};

/// "Send me topic `topic` for `lease_ms`"; broadcast by subscribers and
/// refreshed before the lease ends, or unicast in reply to an advertise.
struct asl_subscribe {
  std::string topic;
  uint32_t lease_ms = 0;
};

struct asl_unsubscribe {
  std::string topic;
};

/// One value of a topic; `seq` counts per publishing module and topic.
struct asl_publish {
  std::string topic;
  uint32_t seq = 0;
  byte_buffer payload;
};

/// Broadcast by a module that starts publishing `topic`.
struct asl_advertise {
  std::string topic;
};

/// A request in reliable mode (docs/protocol.md, "Reliable request"): the
/// sender retransmits it until it hears back, the receiver delivers it to
/// the APO once per (sending module, request_id) and answers a copy from a
/// cache of recent responses. `request_id` is never 0; `oneway` means no
/// response is expected, only an ack.
struct asl_reliable_request {
  uint64_t request_id = 0;
  uint32_t apo = 0;
  bool oneway = false;
  byte_buffer payload;
};

/// "Reliable request `request_id` arrived": ends a one-way exchange; for a
/// request still being served it tells the sender to keep waiting.
struct asl_ack {
  uint64_t request_id = 0;
};

using asl_message
  = std::variant<asl_query, asl_answer, asl_request, asl_response, asl_watch,
                 asl_unwatch, asl_down, asl_withdraw, asl_subscribe,
                 asl_unsubscribe, asl_publish, asl_advertise,
                 asl_reliable_request, asl_ack>;

/// Appends the encoding of `x` to `out`. Strings longer than 255 bytes and
/// answers with more than max_answer_entries entries are the caller's error
/// (checked by assertions; the application support actor never makes them).
/// An error context longer than 255 bytes is truncated (without splitting a
/// UTF-8 sequence). A query by `any` is sent with an empty pattern.
void encode(const asl_message& x, byte_buffer& out);

/// Decodes one message; errors name the kind and the field, e.g.
/// "answer: entry 2: name truncated (needs 7 bytes, 3 left)" (entries count
/// from 1). Besides truncation and trailing bytes it refuses bools other
/// than 0/1, `query_by` above 2, `query_by::any` with a pattern, answers
/// with more than max_answer_entries entries, responses, reliable requests
/// and acks with request_id 0, and reliable-request flags other than 0/1.
/// What decodes re-encodes to exactly the same bytes.
caf::expected<asl_message> decode_asl(const uint8_t* data, size_t size);

/// The same, taking the whole message: a kind that ends in a payload
/// (request, response, reliable request, publish) gets `message` itself as
/// its payload, the bytes before it cut off in place, so the payload is not
/// copied. `message` is left as it was on an error and for the other kinds.
caf::expected<asl_message> decode_asl(byte_buffer&& message);

/// The kind of an encoded message, for counters; error on an empty or
/// unknown-version input or an unknown kind.
caf::expected<asl_kind> peek_asl_kind(const uint8_t* data, size_t size);

/// Field-wise equality, for tests. Responses compare only the alternative
/// `ok` selects (payload or error): the other one does not travel.
bool operator==(const wire_error& a, const wire_error& b);
bool operator==(const asl_query& a, const asl_query& b);
bool operator==(const asl_entry& a, const asl_entry& b);
bool operator==(const asl_answer& a, const asl_answer& b);
bool operator==(const asl_request& a, const asl_request& b);
bool operator==(const asl_response& a, const asl_response& b);
bool operator==(const asl_watch& a, const asl_watch& b);
bool operator==(const asl_unwatch& a, const asl_unwatch& b);
bool operator==(const asl_down& a, const asl_down& b);
bool operator==(const asl_withdraw& a, const asl_withdraw& b);
bool operator==(const asl_subscribe& a, const asl_subscribe& b);
bool operator==(const asl_unsubscribe& a, const asl_unsubscribe& b);
bool operator==(const asl_publish& a, const asl_publish& b);
bool operator==(const asl_advertise& a, const asl_advertise& b);
bool operator==(const asl_reliable_request& a, const asl_reliable_request& b);
bool operator==(const asl_ack& a, const asl_ack& b);

} // namespace herm
