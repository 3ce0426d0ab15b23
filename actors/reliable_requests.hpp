#pragma once

// The reliable-request machine of one application support actor (pure
// core; docs/reliability.md, "Reliable requests"). The sender's half: round
// trip estimates and retransmission timeouts per module (RFC 6298 with
// Karn's rule), the copy schedule of each reliable request, and a bounded
// memory of requests completed lately (so that late copies of a response or
// an ack are told apart from forged or stray ones). The receiver's half: the
// duplicate-suppression cache of (sending module, request id) entries with
// the response sent, bounded in size and age.
//
// No clock and no I/O: time comes in as arguments, and the caller sends
// what the class says to send. Not thread-safe (one actor owns it). Every
// call is O(log n) in the entries held, except expire (O(k log n) for the k
// entries it drops) and remember (O(log n) amortized: it evicts at most one
// entry per entry it adds). Memory: at most cache_size cached entries (each
// with its response) and cache_size completed ids; one round trip estimate
// per module answered (module ids are 16 bits).

#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <set>
#include <utility>

#include "actors/asl_wire.hpp"
#include "routing/module_id.hpp"

namespace herm {

struct app_support_stats;

class reliable_requests {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using ms = std::chrono::milliseconds;

  /// Timers and bounds (app_support_config's reliable-mode fields).
  struct config {
    /// Granularity of the schedule: a request that cannot go now is looked
    /// at again one tick later.
    ms tick{100};
    /// First timeout to a module without a measured round trip; then RTO =
    /// SRTT + 4 RTTVAR within [rto_min, rto_max]. Each retransmission of a
    /// request doubles its timeout, up to rto_max.
    ms rto_initial{300};
    ms rto_min{50};
    ms rto_max{2000};
    /// Most copies of one request (the first included); then it only waits
    /// for its deadline.
    uint32_t max_transmissions = 64;
    /// Receiver: most cached entries (the oldest goes first), and their
    /// lifetime. Sender: most completed request ids remembered.
    size_t cache_size = 2048;
    ms cache_ttl{15000};
  };

  /// The copies of one reliable request, owned by the caller (one per
  /// request it waits for). A default one has sent nothing yet.
  struct transmission {
    /// Where the copies went (a rebinding proxy's request may change
    /// module; then it starts over).
    module_id dst = no_module;
    /// Copies sent (0: waiting for a reachable target).
    uint32_t sends = 0;
    time_point first_sent;
    /// When to look at it again.
    time_point next_send;
    ms rto{0};
    /// The receiver said it is serving the request: only probe now and then.
    bool acked = false;
    /// Counted in reliable_waited already.
    bool waited = false;
  };

  /// Round trip estimate to one module, in ms.
  struct rtt_estimate {
    double srtt = 0;
    double rttvar = 0;
  };

  /// What the receiver remembers of one reliable request.
  struct cached_reply {
    /// False while the APO works on it.
    bool done = false;
    bool oneway = false;
    /// When done and not one-way: sent again for every copy that arrives.
    asl_response response;
    /// The response travels signed (a signed_only APO's).
    bool sign = false;
  };

  /// Counts retransmissions, reliable_waited, duplicates_suppressed and
  /// late_duplicates into `stats`, which must outlive it.
  reliable_requests(config cfg, app_support_stats& stats);

  // -- sender: round trips ----------------------------------------------------

  /// The first timeout of a request to `dst`.
  ms rto(module_id dst) const;

  /// The estimate for `dst`; nullptr before its first sample.
  const rtt_estimate* estimate(module_id dst) const;

  /// One measured round trip to `dst` (RFC 6298: the first sets SRTT = R,
  /// RTTVAR = R/2; later ones smooth with alpha 1/8, beta 1/4).
  void sample(module_id dst, std::chrono::duration<double, std::milli> rtt);

  // -- sender: the schedule of one request -----------------------------------

  /// `tx` may go to `dst` (reachable) at `now`. True: send a copy now (the
  /// first one, the first one to a new `dst`, or a retransmission, counted,
  /// with its timeout doubled, or rto_max once acked); `tx` says when to
  /// look again. False: max_transmissions copies went already, look again
  /// a tick later (the request waits for its deadline).
  bool send(transmission& tx, module_id dst, time_point now);

  /// `tx` has nowhere to go at `now` (no target, or no route to it): look
  /// again a tick later; counted in reliable_waited once per request.
  void wait(transmission& tx, time_point now);

  /// Look at `tx` again a tick later, not counted.
  void defer(transmission& tx, time_point now) const;

  /// The receiver acknowledged a request it is serving: probe at the
  /// slowest pace (rto_max) until its response comes.
  void acknowledged(transmission& tx, time_point now) const;

  /// A response or ack for `tx` arrived at `now`: a round trip sample if
  /// only one copy went (Karn's rule: a retransmitted request's answer
  /// could be for either copy).
  void answered(const transmission& tx, time_point now);

  /// Request `rid` is done: late copies of its answer are recognized until
  /// cache_size later completions.
  void complete(uint64_t rid);

  /// An answer for `rid`, which nobody waits for: true (counted as a late
  /// duplicate) if `rid` completed lately, false if unknown.
  bool late(uint64_t rid);

  size_t completed() const {
    return completed_.size();
  }

  // -- receiver: duplicate suppression ---------------------------------------

  /// The entry of a copy of (src, rid) that arrived before, counted as a
  /// suppressed duplicate; nullptr for a request not seen (or forgotten).
  const cached_reply* duplicate(module_id src, uint64_t rid);

  /// Remembers new request (src, rid) until `now` + cache_ttl; when
  /// cache_size entries are held, the oldest goes first.
  cached_reply& remember(module_id src, uint64_t rid, bool done, bool oneway,
                         time_point now);

  /// The response to (src, rid) is ready: given to its later copies. No
  /// effect if the entry is gone.
  void respond(module_id src, uint64_t rid, const asl_response& r);

  /// Drops the entries expired at `now`.
  void expire(time_point now);

  size_t cached() const {
    return cache_.size();
  }

private:
  using key = std::pair<module_id, uint64_t>;

  config cfg_;
  app_support_stats* stats_;
  std::map<module_id, rtt_estimate> rtt_;
  /// Completed request ids, and in completion order.
  std::set<uint64_t> completed_;
  std::deque<uint64_t> completed_order_;
  /// The cache, and its keys in arrival order with their expiry (the ttl is
  /// constant, so the front expires first).
  std::map<key, cached_reply> cache_;
  std::deque<std::pair<key, time_point>> cache_order_;
};

} // namespace herm
