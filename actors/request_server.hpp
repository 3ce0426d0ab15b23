#pragma once

// The serving side of requests between modules (pure core of the
// application support actor; docs/protocol.md, "Requests"): who may reach a
// local APO, which copies of a reliable request are duplicates (answered
// from reliable_requests' cache, never delivered again), the requests being
// served with their deadlines, and the responses that go back.
//
// No clock and no I/O: time comes in as arguments, responses and acks go
// into the caller's asl_outbox, and what to deliver locally is returned.
// The caller unmarshals and marshals (that needs an actor system). Holds
// references to the module's apo_registry, reliable_requests and
// app_support_stats, which must outlive it. Not thread-safe (one actor owns it). At most
// `max_serving` requests served at once (more are refused, counted);
// calls O(log n), expire O(n); the table's nodes are reused
// (spare_nodes.hpp).

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <variant>

#include "caf/error.hpp"

#include "actors/apo_registry.hpp"
#include "actors/asl_outbox.hpp"
#include "actors/reliable_requests.hpp"
#include "actors/spare_nodes.hpp"

namespace herm {

class request_server {
public:
  using time_point = std::chrono::steady_clock::time_point;

  struct config {
    /// Most requests served at once (then ec::queue_full to the requester).
    size_t max_serving = 4096;
    /// A response later than this after its request goes nowhere.
    std::chrono::milliseconds request_timeout{10000};
    /// A module without a key lets unsigned requests reach its
    /// signed_only APOs (app_support_config::allow_unsigned_remote).
    bool allow_unsigned_remote = false;
  };

  /// Counts requests_served, oneway_delivered, acks_sent,
  /// rx_unauthorized, rx_unknown_apo and serving_refused into `stats`.
  request_server(config cfg, const apo_registry& apos,
                 reliable_requests& reliable, app_support_stats& stats);

  /// First look at a request (`rid` 0: a plain one-way message) from
  /// module `src` for local APO `apo`, signed and verified when
  /// `authenticated`. True: unmarshal it, then accept it (or tell
  /// malformed). False: already dealt with: refused as unauthorized or
  /// for an unknown APO (answered with the error), or a copy of a reliable
  /// request seen before (answered with its cached response, or acked).
  /// `self` names this module in error texts.
  bool admit(module_id src, uint64_t rid, uint32_t apo, bool reliable,
             bool authenticated, module_id self, asl_outbox& out);

  /// The payload of an admitted request did not unmarshal (`err`): the
  /// requester learns why.
  void malformed(module_id src, uint64_t rid, uint32_t apo,
                 const caf::error& err, module_id self, asl_outbox& out);

  /// Accepts an admitted, unmarshalled request at `now`. 0: a one-way
  /// message, to be delivered (a reliable one is acked). Otherwise the
  /// local request number to deliver it under (its reply comes back with
  /// it). nullopt: refused, max_serving requests are being served (a
  /// reliable one is not remembered: a later copy may find room).
  std::optional<uint64_t> accept(module_id src, uint64_t rid, uint32_t apo,
                                 bool oneway, bool reliable, time_point now,
                                 module_id self, asl_outbox& out);

  /// The APO answered local request `local` with a value (marshalled) or
  /// an error: the response goes back (and into the duplicate cache for a
  /// reliable request). Ignored if `local` is not served any more.
  void reply(uint64_t local, std::variant<byte_buffer, caf::error> answer,
             asl_outbox& out);

  /// Forgets the requests whose deadline is not after `now`.
  void expire(time_point now);

  size_t serving() const {
    return serving_.size();
  }

private:
  /// A request a remote module made of one of our APOs.
  struct served {
    module_id origin = no_module;
    uint64_t origin_id = 0;
    time_point deadline;
    /// The response goes into the duplicate-suppression cache too.
    bool reliable = false;
    /// For a signed_only APO: the response travels signed.
    bool sign = false;
  };

  void respond_error(module_id dst, uint64_t rid, const caf::error& err,
                     bool sign, asl_outbox& out);

  void ack(module_id dst, uint64_t rid, asl_outbox& out);

  config cfg_;
  const apo_registry& apos_;
  reliable_requests& reliable_;
  app_support_stats* stats_;
  uint64_t next_ = 1;
  std::map<uint64_t, served> serving_;
  spare_nodes<std::map<uint64_t, served>> spare_;
};

} // namespace herm
