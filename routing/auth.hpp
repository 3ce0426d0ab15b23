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
// An index the receiver does not know is not accepted on the strength of
// its tag alone (a recording from a sender's previous process start has a
// right tag): the receiver challenges it (RFC 8967 sections 4.3, Challenge
// Request and Reply). It sends a fresh random nonce (`challenge`); the
// sender echoes it in a packet signed with its current index and counter;
// a reply with the live nonce (`accept_reply`) makes the index known, with
// the reply's counter. Challenge requests are answered whatever their index
// and counter (`may_reply` rate-limits that). Every table is bounded by
// auth_config::max_senders.
//
// Pure: no clock (time comes in as an argument) and no I/O but load_key,
// which reads one file, and nonces, drawn from a caller-supplied random
// source (default: OpenSSL's RAND_bytes). Not thread-safe: one
// authenticator per routing agent. Verification never reads out of bounds
// and never allocates from a length on the wire: the trailer has a fixed
// size (read and written through channels/le_codec.hpp).
//
// Bounds per call: sign and verify are O(n) in the packet size (one
// HMAC-SHA256 pass) plus O(log max_senders) for the table lookup; sign
// appends trailer_size() bytes to the packet and allocates nothing else.
// verify allocates at most one table entry, and when the table is full
// scans it once (O(max_senders)) for the oldest sender to forget; the same
// holds for challenge (its table) and may_reply (its table).

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "caf/expected.hpp"

#include "channels/messages.hpp"
#include "routing/module_id.hpp"
#include "routing/wire.hpp"

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
  /// Senders (indexes) whose counters are remembered at most; also bounds
  /// the live challenges and the requesters answered (0 counts as 1).
  size_t max_senders = 256;
  /// A sender silent this long may be forgotten when the table is full.
  std::chrono::milliseconds forget_after{60000};
  /// RFC 8967's challenge: a packet with a right tag from an index not
  /// known is not accepted (verify says unknown_index) until that sender
  /// has echoed a nonce. Off: such a packet is accepted and its index
  /// recorded (a recording from an index never heard is then accepted
  /// once); a module with the challenge off still answers challenges.
  bool challenge = true;
  /// At most one challenge request per unknown index, and one reply per
  /// requesting index, per this interval (RFC 8967's recommended 300 ms).
  std::chrono::milliseconds challenge_interval{300};
  /// A reply counts only if it arrives within this long of its request
  /// (RFC 8967's 30 s); the challenge is forgotten then.
  std::chrono::milliseconds challenge_timeout{30000};

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
  /// Right tag, but the sender index is not known (challenge on): not
  /// accepted; the caller challenges the sender.
  unknown_index,
  /// A challenge reply that answers no live challenge of its index: none
  /// was sent, its nonce is another, or it came after challenge_timeout.
  challenge_failed,
};

const char* to_string(auth_result x);

/// Counters: every verification is counted once, under its result
/// (accepted .. unknown_index); every challenge, reply and accept_reply
/// once in the counters below them.
struct auth_stats {
  uint64_t signed_packets = 0;
  uint64_t accepted = 0;
  uint64_t truncated = 0;
  uint64_t wrong_key_id = 0;
  uint64_t bad_tag = 0;
  uint64_t replayed = 0;
  uint64_t table_full = 0;
  uint64_t unknown_index = 0;
  /// challenge(): nonces handed out, and calls refused by the rate limit.
  uint64_t challenges_sent = 0;
  uint64_t challenges_limited = 0;
  /// accept_reply(): ok, and anything else (challenge_failed, table_full).
  uint64_t challenges_passed = 0;
  uint64_t challenges_failed = 0;
  /// may_reply(): true, and false.
  uint64_t replies = 0;
  uint64_t replies_limited = 0;
};

/// What a trailer with a right tag says (verify fills it whenever the tag
/// is right: results ok, replayed, table_full, unknown_index).
struct auth_trailer {
  uint32_t index = 0;
  uint64_t counter = 0;
  /// The packet's size without the trailer.
  size_t body_size = 0;
};

/// Fills `out[0..n)` with random bytes; false when it could not.
using random_source = std::function<bool(uint8_t* out, size_t n)>;

/// Signs and verifies packets of one module. See the file comment.
class authenticator {
public:
  using time_point = std::chrono::steady_clock::time_point;

  /// `cfg.key` must not be empty; `index` is this process's sender index
  /// (random per start; the caller draws it). Challenge nonces come from
  /// `random` (tests pass a deterministic one), by default RAND_bytes.
  authenticator(auth_config cfg, uint32_t index, random_source random = {});
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

  /// As above; fills `out` whenever the tag is right, so that the caller
  /// can answer a challenge request whatever its index and counter, and
  /// challenge an unknown index (result unknown_index: nothing recorded).
  auth_result verify(const uint8_t* data, size_t size, uint8_t link,
                     time_point now, auth_trailer& out, size_t min_body = 1);

  // -- RFC 8967 challenges --------------------------------------------------------

  /// Starts a challenge of sender `index` (verify said unknown_index):
  /// draws a fresh nonce into `nonce` and remembers it for
  /// challenge_timeout. False, and nothing changes, when a challenge of
  /// `index` started less than challenge_interval ago (the rate limit: a
  /// recording replayed fast costs one request per interval) or the random
  /// source failed. A new challenge of the same index replaces the old
  /// nonce. At most max_senders challenges are remembered; when full, the
  /// expired ones go, then the oldest.
  bool challenge(uint32_t index, time_point now, challenge_nonce& nonce);

  /// A challenge reply carrying `nonce`, in a packet whose trailer `t`
  /// verify found right (unknown_index). ok when it answers the live
  /// challenge of `t.index` (same nonce, at most challenge_timeout after
  /// it): the index is known from now on, with `t.counter` as its last
  /// counter (a counter already recorded is never lowered), and the
  /// challenge is used up. table_full when the sender
  /// table is full of live senders; challenge_failed otherwise (a wrong
  /// nonce leaves the challenge live: the reply to a newer request may
  /// still come).
  auth_result accept_reply(const auth_trailer& t, const challenge_nonce& nonce,
                           time_point now);

  /// Whether to answer a challenge request from sender `index` now, and if
  /// so records the reply: at most one per challenge_interval per
  /// requesting index (a replayed request makes this module sign a reply to
  /// an old nonce, which is harmless but costs a packet). At most
  /// max_senders requesters are remembered; when all of them were answered
  /// within challenge_interval, false.
  bool may_reply(uint32_t index, time_point now);

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

  /// Challenges currently remembered (sent, not answered, maybe expired).
  size_t challenges() const noexcept {
    return challenges_.size();
  }

private:
  struct sender {
    uint64_t counter = 0;
    time_point last;
  };

  struct pending {
    challenge_nonce nonce{};
    time_point sent;
  };

  /// Records `counter` as the last of `index`; false when `index` is new
  /// and the table is full of senders heard within forget_after.
  bool admit(uint32_t index, uint64_t counter, time_point now);

  /// Full HMAC-SHA256 of the pseudo-header and `data[0..size)`; false
  /// (and zeros) when OpenSSL failed.
  bool mac(uint8_t link, const uint8_t* data, size_t size,
           std::array<uint8_t, 32>& out);

  auth_config cfg_;
  uint32_t index_;
  uint64_t counter_ = 1;
  std::map<uint32_t, sender> senders_;
  /// Live challenges by the index challenged.
  std::map<uint32_t, pending> challenges_;
  /// When a challenge request from an index was last answered.
  std::map<uint32_t, time_point> replied_;
  random_source random_;
  auth_stats stats_;
  struct impl;
  std::unique_ptr<impl> impl_;
};

} // namespace herm
