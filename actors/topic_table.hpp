#pragma once

// The publish/subscribe state of one application support actor (pure core;
// docs/protocol.md, "Topics"). Per topic: on the subscriber side, the local
// subscribers, when to renew the subscription, and the last sequence number
// of each publishing module (to count lost publications and drop repeats);
// on the publisher side, the sequence number, the last value (given to late
// joiners) and the subscribed modules with the end of their lease.
//
// No clock and no I/O: time comes in as arguments, what is to be sent goes
// into the caller's asl_outbox, and local deliveries are returned as the
// subscribers to give a value to. Actor handles and messages are held as
// plain values, never used. Not thread-safe (one actor owns it). Remote
// peers per topic are bounded by `max_peers` on either side (refusals
// counted); local subscribers are as many as local actors subscribe. A
// topic is dropped once it has no local subscriber and was never published
// here. Calls are O(log t + p) for t topics and p peers of the topic; those
// over all topics O(t p).

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "caf/actor.hpp"
#include "caf/actor_addr.hpp"
#include "caf/message.hpp"

#include "actors/asl_outbox.hpp"
#include "actors/asl_wire.hpp"
#include "routing/module_id.hpp"

namespace herm {

struct app_support_stats;
struct topic_info;

class topic_table {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using subscribers = std::vector<caf::actor>;

  /// The longest lease a subscriber can ask for; longer ones are cut.
  static constexpr std::chrono::milliseconds max_lease{24 * 3600 * 1000};

  struct topic {
    // -- subscriber side --
    /// Local subscribers given each value as the message published.
    subscribers local_subs;
    /// Local subscribers given each value as a topic_sample (its payload,
    /// publisher, sequence number and time): tools and typed subscribers.
    subscribers sample_subs;
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
    /// The type name of the first element of the last value seen.
    std::string last_type;

    /// Some local actor subscribed.
    bool interested() const {
      return !local_subs.empty() || !sample_subs.empty();
    }
  };

  /// `lease`: how long this module's subscriptions last (renewed at a
  /// third of it). Counts published, publications_sent/received/lost,
  /// subscribers_refused and publishers_refused into `stats`, which must
  /// outlive it.
  topic_table(size_t max_peers, std::chrono::milliseconds lease,
              app_support_stats& stats);

  /// The topic, or nullptr.
  const topic* find(const std::string& name) const;

  // -- this module's publishers and subscribers -------------------------------

  /// Publishes `msg` (marshalled: `payload`; an empty `msg` when this
  /// process cannot decode the payload) at `now`: the next sequence
  /// number, kept as the last value; an advertisement when this module did
  /// not publish the topic before, and a publication to every subscribed
  /// module whose lease holds (the others are dropped). Returns the topic,
  /// whose local subscribers are to be given the value.
  const topic& publish(const std::string& name, caf::message msg,
                       byte_buffer payload, time_point now, asl_outbox& out);

  /// Adds local subscriber `sub` at `now`, given values as messages or,
  /// with `samples`, as topic_sample: nullptr if it subscribed so already,
  /// else the topic (give `sub` its last value if it has one). The first
  /// local subscriber's subscription is broadcast.
  const topic* subscribe(const std::string& name, const caf::actor& sub,
                         time_point now, asl_outbox& out,
                         bool samples = false);

  /// Removes local subscriber `who` (of either kind) from topic `*only`, or
  /// from every topic when `only` is nullptr. A topic that loses its last
  /// local subscriber is unsubscribed from on the network.
  void unsubscribe(const caf::actor_addr& who, const std::string* only,
                   asl_outbox& out);

  // -- other modules ----------------------------------------------------------

  /// Module `src` subscribes at `now`. Ignored unless this module publishes
  /// the topic; a new subscriber is refused (counted) when max_peers hold
  /// leases, or else gets the last value at once (a late joiner).
  void on_subscribe(module_id src, const asl_subscribe& s, time_point now,
                    asl_outbox& out);

  void on_unsubscribe(module_id src, const asl_unsubscribe& u);

  /// Module `src` publishes a topic: subscribed here, it hears so at once.
  void on_advertise(module_id src, const asl_advertise& a, time_point now,
                    asl_outbox& out);

  /// A publication from module `src`: the topic whose local subscribers to
  /// give it to, or nullptr (none, or the same value again). Gaps count as
  /// lost publications; past max_peers publishing modules, a new one's
  /// value is delivered untracked (counted).
  const topic* on_publish(module_id src, const asl_publish& p);

  /// Every topic this module publishes or subscribes to, by name: whether
  /// it publishes, its local subscribers, the modules subscribed to it and
  /// those heard publishing it, and the type last seen. O(t p).
  std::vector<topic_info> list() const;

  /// Module `m` is gone: forget its leases and sequence numbers.
  void module_lost(module_id m);

  /// Drops leases ended before `now` and renews the subscriptions due.
  void housekeep(time_point now, asl_outbox& out);

private:
  void announce(const std::string& name, topic& t, module_id dst,
                time_point now, asl_outbox& out);

  void send_last(const std::string& name, const topic& t, module_id dst,
                 asl_outbox& out);

  size_t max_peers_;
  std::chrono::milliseconds lease_;
  app_support_stats* stats_;
  std::map<std::string, topic> topics_;
};

} // namespace herm
