#pragma once

// Authentication of network packets with a pre-shared key (docs/protocol.md,
// "Authentication"), after Babel's RFC 8967: every authenticated packet ends
// in a trailer
//
//   key id (1) | sender index (4) | packet counter (8) | tag (8 or 16)
//
// where the tag is HMAC-SHA256, truncated, over a pseudo-header (the link
// code of the link the packet travels on) and the packet up to the tag. The
// sender index is random per process start; the counter starts at 1 and
// grows by one per signed packet. A receiver accepts a packet only when the
// tag is right and its counter is above the last one it accepted for that
// index (replay protection); the index table is bounded.
//
// Pure: no clock (time comes in as an argument) and no I/O but load_key,
// which reads one file. Not thread-safe: one authenticator per routing
// agent. Verification never reads out of bounds and never allocates from a
// length on the wire: the trailer has a fixed size.

#include <array>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "caf/expected.hpp"

#include "channels/messages.hpp"
#include "routing/module_id.hpp"

namespace herm {

/// Which data packets a keyed network signs (control packets always are).
enum class auth_data : uint8_t {
  /// Flooded broadcasts (ASL queries, advertisements, withdrawals) and
  /// discovery answers (ASL messages of kind `answer`).
  discovery = 0,
  /// Every data packet.
  all = 1,
};

/// Key lengths a key file may hold, bytes.
constexpr size_t min_key_bytes = 16;
constexpr size_t max_key_bytes = 64;

/// Trailer without the tag: key id, sender index, packet counter.
constexpr size_t auth_head_size = 13;

/// The upper-layer protocol and ASL kind of discovery answers
/// (actors/asl_wire.hpp: asl_protocol, asl_kind::answer; a test checks that
/// they agree). The routing layer reads these two bytes only.
constexpr uint8_t discovery_protocol = 1;
constexpr uint8_t discovery_answer_kind = 2;

/// A network's authentication settings; no key: no authentication.
struct auth_config {
  /// The shared key (min_key_bytes..max_key_bytes); never logged.
  std::vector<uint8_t> key;
  /// Sent in every trailer, so that a key can be rolled over later; packets
  /// with another id are refused.
  uint8_t key_id = 1;
  /// Tag length, bytes: 8 or 16.
  uint8_t tag_bytes = 8;
  auth_data data = auth_data::discovery;
  /// Senders (indexes) whose counters are remembered at most.
  size_t max_senders = 256;
  /// A sender silent this long may be forgotten when the table is full.
  std::chrono::milliseconds forget_after{60000};

  bool enabled() const noexcept {
    return !key.empty();
  }

  /// Bytes an authenticated packet carries more.
  size_t trailer_size() const noexcept {
    return auth_head_size + tag_bytes;
  }
};

/// Whether a keyed network signs a data packet to `dst` of `protocol` whose
/// payload is `payload[0..size)`: always with auth_data::all; otherwise
/// broadcasts and discovery answers (an ASL header: version, then kind).
bool data_needs_auth(const auth_config& cfg, module_id dst, uint8_t protocol,
                     const uint8_t* payload, size_t size);

/// Reads a key file: hex digits (32 to 128 of them, 16 to 64 bytes, an
/// optional final newline), e.g. made with `openssl rand -hex 32`. Refuses,
/// with ec::invalid_config naming the file and the reason, anything that is
/// not a regular file (symlinks are not followed), not owned by the
/// effective user, readable or writable by group or others (mode must be
/// 0600 or 0400), larger than 1 KiB, of another length or not hex.
caf::expected<std::vector<uint8_t>> load_key(const std::string& path);

/// As load_key; returns the error text ("PATH: key file has mode 0640:
/// ...") or an empty string when `key` holds the key.
std::string read_key(const std::string& path, std::vector<uint8_t>& key);

/// Why a packet was accepted or refused.
enum class auth_result : uint8_t {
  ok,
  /// Shorter than a trailer (after the `min_body` bytes the packet needs).
  truncated,
  wrong_key_id,
  bad_tag,
  /// Counter not above the last accepted one of its sender index.
  replayed,
  /// A new sender index while the table is full of live senders.
  table_full,
};

const char* to_string(auth_result x);

/// Counters: every verification is counted once, under its result.
struct auth_stats {
  uint64_t signed_packets = 0;
  uint64_t accepted = 0;
  uint64_t truncated = 0;
  uint64_t wrong_key_id = 0;
  uint64_t bad_tag = 0;
  uint64_t replayed = 0;
  uint64_t table_full = 0;
};

/// Signs and verifies packets of one module. See the file comment.
class authenticator {
public:
  using time_point = std::chrono::steady_clock::time_point;

  /// `cfg.key` must not be empty; `index` is this process's sender index
  /// (random per start; the caller draws it).
  authenticator(auth_config cfg, uint32_t index);
  ~authenticator();

  authenticator(const authenticator&) = delete;
  authenticator& operator=(const authenticator&) = delete;

  /// Appends a trailer to `packet` for a link of link code `link`.
  void sign(byte_buffer& packet, uint8_t link);

  /// Checks the trailer at the end of `data[0..size)` received on a link of
  /// code `link`. On ok, records the counter and returns the packet's size
  /// without the trailer. `min_body` is the fewest bytes the packet itself
  /// has (its header), so a short packet counts as truncated.
  auth_result verify(const uint8_t* data, size_t size, uint8_t link,
                     time_point now, size_t& body_size, size_t min_body = 1);

  const auth_stats& stats() const noexcept {
    return stats_;
  }

  const auth_config& config() const noexcept {
    return cfg_;
  }

  uint32_t index() const noexcept {
    return index_;
  }

  /// The next counter value sign() will use.
  uint64_t counter() const noexcept {
    return counter_;
  }

  /// Senders currently remembered.
  size_t senders() const noexcept {
    return senders_.size();
  }

private:
  struct sender {
    uint64_t counter = 0;
    time_point last;
  };

  /// Full HMAC-SHA256 of the pseudo-header and `data[0..size)`; false
  /// (and zeros) when OpenSSL failed.
  bool mac(uint8_t link, const uint8_t* data, size_t size,
           std::array<uint8_t, 32>& out);

  auth_config cfg_;
  uint32_t index_;
  uint64_t counter_ = 1;
  std::map<uint32_t, sender> senders_;
  auth_stats stats_;
  struct impl;
  std::unique_ptr<impl> impl_;
};

} // namespace herm
