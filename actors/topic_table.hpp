#pragma once

// The publish/subscribe state of one application support actor (pure core;
// docs/protocol.md, "Topics"). Per topic: on the subscriber side, the local
// subscribers, when to renew the subscription, and the last sequence number
// of each publishing module (to count lost publications and drop repeats);
// on the publisher side, the sequence number, the last value (given to late
// joiners) and the subscribed modules with the end of their lease.
//
// No clock and no I/O: time comes in as arguments, and the caller sends and
// delivers what the class says to. Actor handles and messages are held as
// plain values, never used. Not thread-safe (one actor owns it). Remote
// peers per topic are bounded by `max_peers` on either side (refusals
// counted); local subscribers are as many as local actors subscribe. A
// topic is dropped once it has no local subscriber and was never published
// here. Calls are O(log t + p) for t topics and p peers of the topic, those
// over all topics O(t p).

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "caf/actor.hpp"
#include "caf/actor_addr.hpp"
#include "caf/message.hpp"

#include "actors/asl_wire.hpp"
#include "routing/module_id.hpp"

namespace herm {

class topic_table {
public:
  using time_point = std::chrono::steady_clock::time_point;

  /// The longest lease a subscriber can ask for; longer ones are cut.
  static constexpr std::chrono::milliseconds max_lease{24 * 3600 * 1000};

  struct topic {
    // -- subscriber side --
    std::vector<caf::actor> local_subs;
    time_point next_refresh;
    /// Last sequence number per publishing module.
    std::map<module_id, uint32_t> last_seq;
    // -- publisher side --
    bool publishing = false;
    uint32_t seq = 0;
    bool has_last = false;
    caf::message last;
    byte_buffer last_payload;
    /// Subscribed modules and when their lease ends.
    std::map<module_id, time_point> remote_subs;
  };

  /// What the class counted (app_support_stats names them the same).
  struct counters {
    uint64_t publications_lost = 0;
    uint64_t subscribers_refused = 0;
    uint64_t publishers_refused = 0;
  };

  explicit topic_table(size_t max_peers = SIZE_MAX);

  /// The topic, or nullptr.
  topic* find(const std::string& name);

  // -- publisher side ---------------------------------------------------------

  /// A local publication of `msg` (marshalled: `payload`) at `now`: the next
  /// sequence number, kept as the last value. Expired subscribers are
  /// dropped; the topic's remote_subs are those to send it to. `first`
  /// says this module did not publish it before (advertise it).
  topic& publish(const std::string& name, caf::message msg,
                 byte_buffer payload, time_point now, bool& first);

  /// Module `src` subscribes for `lease` (at most max_lease) at `now`.
  /// Ignored unless this module publishes the topic; a new subscriber is
  /// refused (counted) when max_peers hold leases. Returns the topic when
  /// the new subscriber is to get the last value now, else nullptr.
  const topic* subscribed(const std::string& name, module_id src,
                          std::chrono::milliseconds lease, time_point now);

  void unsubscribed(const std::string& name, module_id src);

  // -- subscriber side --------------------------------------------------------

  /// Adds local subscriber `sub`: the topic, or nullptr if `sub` subscribed
  /// already. Its local_subs has one entry when the subscription is to be
  /// announced.
  topic* subscribe(const std::string& name, const caf::actor& sub);

  /// Removes local subscriber `who` from topic `*only`, or from every topic
  /// when `only` is nullptr. Returns the topics it was the last local
  /// subscriber of (to be unsubscribed from on the network).
  std::vector<std::string> unsubscribe(const caf::actor_addr& who,
                                       const std::string* only);

  /// Publication `seq` from module `src` arrived: the topic whose local
  /// subscribers get it, or nullptr (no local subscriber, or the same
  /// value again). Gaps count as lost publications; past max_peers
  /// publishing modules, a new one's value is delivered untracked (counted).
  const topic* received(const std::string& name, module_id src, uint32_t seq);

  // -- both -------------------------------------------------------------------

  /// Module `m` is gone: forget its leases and sequence numbers.
  void module_lost(module_id m);

  /// Drops leases ended before `now`; returns the topics whose
  /// subscription is due for renewal (the caller announces it and sets
  /// next_refresh).
  std::vector<std::string> housekeep(time_point now);

  const counters& stats() const {
    return stats_;
  }

  size_t size() const {
    return topics_.size();
  }

private:
  size_t max_peers_;
  counters stats_;
  std::map<std::string, topic> topics_;
};

} // namespace herm
