#pragma once

// Wire formats of the Network Adaptation Layer (docs/protocol.md, "Network
// packets"). Every packet a channel carries starts with one byte: version
// (bits 7..4, currently 1) and type (bits 3..0). All integers little endian.
// Decoders are total: any byte string yields a value or ec::invalid_* error,
// every length and count is checked against the bytes present before
// anything is allocated, and nothing is read out of bounds. They are
// fuzzed (tests/fuzz/fuzz_routing_wire.cpp).
//
// Bounds per call (all through channels/le_codec.hpp): time O(n) in the
// packet size for decoders and in the encoded size for encoders. Encoders
// allocate nothing but the growth of `out` (an update is at most
// 12 + max_update_entries * (4 + size_classes * (5 + max_route_hops))
// bytes); decoders allocate only the value they return (an update's entries
// and their paths, bounded the same way), and on bad input return the error
// after reading no further than `size`. They keep no state: any thread may
// call them on buffers of its own.

#include <array>
#include <cstdint>
#include <vector>

#include "caf/expected.hpp"

#include "channels/messages.hpp"
#include "routing/module_id.hpp"
#include "routing/route_table.hpp"

namespace herm {

constexpr uint8_t wire_version = 1;

enum class packet_type : uint8_t {
  data = 0,
  hello = 1,
  update = 2,
  seqno_request = 3,
  claim = 4,
  conflict = 5,
  /// RFC 8967's challenge (routing/auth.hpp): keyed networks only.
  challenge_request = 6,
  challenge_reply = 7,
};

/// Reads the first byte. Errors: empty packet, unknown version or type
/// (ec::invalid_parameter naming what was found).
caf::expected<packet_type> peek_type(const uint8_t* data, size_t size);

// -- data packets: 8-byte header, then the payload -------------------------------

/// Default hop limit of data packets: the last guard against loops.
constexpr uint8_t default_hop_limit = 32;

struct data_header {
  module_id src = no_module;
  module_id dst = no_module;
  uint8_t hop_limit = default_hop_limit;
  uint8_t size_class = 0; ///< 0..size_classes-1
  uint8_t priority = 2;   ///< 0..3, lower is more urgent
  uint8_t protocol = 0;   ///< upper-layer protocol (0 raw, 1 APO messages, ...)
  /// Non-zero on a flooded broadcast (dst == broadcast_module): with `src`
  /// it names the flood for duplicate suppression. Travels as 4 more header
  /// bytes, announced by flag bit 4. A broadcast without one is link-local:
  /// delivered to the neighbours that hear it, never relayed.
  uint32_t flood_id = 0;
  /// Flag bit 5: an authentication trailer (routing/auth.hpp) ends the
  /// packet, after the payload. Set and checked by the routing agent of a
  /// keyed network, per hop; the trailer is not part of the payload.
  bool authenticated = false;
};

/// Size of a data header without, and with, a flood id.
constexpr size_t data_header_size = 8;
constexpr size_t flood_header_size = 12;

/// Where the payload starts in a packet with header `h`.
constexpr size_t header_size(const data_header& h) {
  return h.flood_id != 0 ? flood_header_size : data_header_size;
}

/// Appends the header; the payload follows.
void encode(const data_header& h, byte_buffer& out);

/// Decodes the header; the payload starts at data + header_size(result).
caf::expected<data_header> decode_data_header(const uint8_t* data, size_t size);

/// Rewrites the hop limit in an encoded data packet (forwarding).
void set_hop_limit(uint8_t* packet, uint8_t hop_limit);

/// Sets or clears the authenticated flag in an encoded data packet.
void set_authenticated(uint8_t* packet, bool on);

// -- link-local control ----------------------------------------------------------

/// Sent on every channel every hello interval; tells neighbours who we are.
struct hello {
  module_id sender = no_module;
  /// Random per process start: tells a restarted module, or another module
  /// holding the same id, apart.
  uint64_t instance = 0;
  uint16_t seqno = 0;
  /// The sender's hello interval, ms: receivers expect the next within it.
  uint16_t interval_ms = 0;
};

void encode(const hello& x, byte_buffer& out);
caf::expected<hello> decode_hello(const uint8_t* data, size_t size);

/// Routing update: destinations as the sender sees them.
struct update {
  module_id sender = no_module;
  uint64_t instance = 0;
  std::vector<advertised> entries;
};

/// Entries per update packet that keep it within one 1,024-byte class packet.
constexpr size_t max_update_entries = 24;

void encode(const update& x, byte_buffer& out);
caf::expected<update> decode_update(const uint8_t* data, size_t size);

/// Asks neighbours for a newer seqno of `origin` (RFC 8966 3.8.2.1);
/// forwarded towards the origin while hop_count > 0.
struct seqno_request {
  module_id sender = no_module;
  module_id origin = no_module;
  seqno_t seqno = 0;
  uint8_t hop_count = 0;
};

void encode(const seqno_request& x, byte_buffer& out);
caf::expected<seqno_request> decode_seqno_request(const uint8_t* data,
                                                  size_t size);

// -- addressing (flooded, duplicate-suppressed, hop-limited) ---------------------------

/// "I want this id." Flooded through the network.
struct claim {
  module_id id = no_module;
  /// Random per claim attempt; ties between two claimants go to the lower.
  uint64_t nonce = 0;
  /// The claimant's instance (hello::instance).
  uint64_t instance = 0;
  uint8_t hop_limit = default_hop_limit;
};

void encode(const claim& x, byte_buffer& out);
caf::expected<claim> decode_claim(const uint8_t* data, size_t size);

/// "That id is taken (by `holder_instance`)." Flooded like a claim.
struct conflict {
  module_id id = no_module;
  uint64_t holder_instance = 0;
  /// The claim's nonce this answers, or 0 when two holders met (merge).
  uint64_t claim_nonce = 0;
  /// The instance that must renumber.
  uint64_t loser_instance = 0;
  uint8_t hop_limit = default_hop_limit;
};

void encode(const conflict& x, byte_buffer& out);
caf::expected<conflict> decode_conflict(const uint8_t* data, size_t size);

// -- authentication (link-local, keyed networks only) -----------------------------

/// Bytes of a challenge nonce: it proves freshness, not secrecy, so 64
/// random bits suffice (docs/protocol.md, "Authentication").
constexpr size_t challenge_nonce_size = 8;

using challenge_nonce = std::array<uint8_t, challenge_nonce_size>;

/// "Prove that you are alive: sign this nonce" (RFC 8967 Challenge
/// Request). Sent, signed, to the link address of a packet whose tag was
/// right but whose sender index this module does not know.
struct challenge_request {
  challenge_nonce nonce{};
};

void encode(const challenge_request& x, byte_buffer& out);
caf::expected<challenge_request> decode_challenge_request(const uint8_t* data,
                                                          size_t size);

/// The answer: the request's nonce, echoed in a packet signed with the
/// responder's current index and counter (RFC 8967 Challenge Reply).
struct challenge_reply {
  challenge_nonce nonce{};
};

void encode(const challenge_reply& x, byte_buffer& out);
caf::expected<challenge_reply> decode_challenge_reply(const uint8_t* data,
                                                      size_t size);

} // namespace herm
