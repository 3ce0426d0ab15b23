#pragma once

// The requests one application support actor sent to remote APOs and waits
// to hear about (pure core): who asked, through which binding, by when, and
// in reliable mode the message to send again with its copy schedule
// (reliable_requests decides that schedule).
//
// No clock and no I/O: time comes in as arguments, and the caller answers
// the requesters with what it takes out. Requesters' handles and messages
// are held as plain values, never used. Holds references to the module's
// reliable_requests and app_support_stats, which must outlive it. Not
// thread-safe (one actor owns it). At most `max_pending` requests (add
// refuses more); lookups O(log n), the take_* scans and due O(n). The
// nodes of requests taken out are reused (spare_nodes.hpp): no allocation
// per request for the table once warmed up.

#include <chrono>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "caf/actor_control_block.hpp"
#include "caf/message.hpp"
#include "caf/message_id.hpp"

#include "actors/app_table.hpp"
#include "actors/binding_table.hpp"
#include "actors/reliable_requests.hpp"
#include "actors/spare_nodes.hpp"

namespace herm {

struct app_support_stats;

/// A request sent to a remote APO, waiting for its response.
struct outgoing {
  caf::strong_actor_ptr sender;
  caf::message_id mid;
  uint32_t binding = 0;
  std::chrono::steady_clock::time_point deadline;
  // -- reliable mode: what to send again, and when --
  bool reliable = false;
  bool oneway = false;
  /// Sent as a raw_payload (marshalled elsewhere): the response goes back
  /// as a raw_payload too, not unmarshalled here.
  bool raw = false;
  /// The message (handed over unchanged if a rebinding proxy's new target
  /// is local) and its marshalled form.
  caf::message msg;
  byte_buffer payload;
  /// The module it went to (tx.dst; plain requests too) and, in reliable
  /// mode, the schedule of its copies.
  reliable_requests::transmission tx;
};

class outgoing_requests {
public:
  using time_point = std::chrono::steady_clock::time_point;

  /// Request ids come from a scrambled_sequence keyed with `key`: they go
  /// on the wire, and a forged response should need more than one packet
  /// sniffed.
  /// Counts rx_unexpected_response and acks_received into `stats`.
  outgoing_requests(uint64_t key, size_t max_pending,
                    reliable_requests& reliable, app_support_stats& stats);

  bool full() const {
    return requests_.size() >= max_;
  }

  size_t size() const {
    return requests_.size();
  }

  /// Adds `out` (room permitting: see full) under a fresh request id.
  std::pair<uint64_t, outgoing&> add(outgoing out);

  /// The request a response (or, with `ack`, an ack) from module `src`
  /// answers: nullptr if `rid` does not wait for one from there (unknown,
  /// another module's, a reliable one with no copy out yet; for an ack,
  /// a plain one), counted as a late duplicate (reliable_requests::late)
  /// or else as unexpected.
  outgoing* expecting(uint64_t rid, module_id src, bool ack);

  /// What a response asks of the caller.
  struct response_step {
    enum kind_t { none, rebind, reply };
    /// none: nothing (a stray, counted as by expecting; or an error for a
    /// one-way message: nobody to tell).
    kind_t kind = none;
    /// rebind: the APO of `binding`, a rebinding one, is gone (`error`):
    /// its reliable request stays, to go to the next target.
    uint32_t binding = 0;
    caf::error error;
    /// reply: the request, taken out (counted in responses_received): its
    /// sender gets the response.
    outgoing out;
  };

  /// A response from module `src` at `now` (a reliable request's round
  /// trip is sampled, and it is remembered as completed).
  response_step on_response(module_id src, const asl_response& r,
                            time_point now, const binding_table& bindings);

  /// An ack from module `src` at `now`: a one-way message is done (and
  /// leaves), a request is being served (probed at the slowest pace from
  /// now on). Strays are counted as by expecting.
  void on_ack(module_id src, const asl_ack& a, time_point now);

  void erase(uint64_t rid) {
    spare_.erase(requests_, rid);
  }

  /// Removes `rid` and returns it (it must be there).
  outgoing take(uint64_t rid);

  /// Removes and returns, in id order, the requests on binding `binding`
  /// (or, when it is 0, those sent to module `dst`); reliable ones stay
  /// when `keep_reliable`.
  std::vector<outgoing> take_waiting_on(uint32_t binding, module_id dst,
                                        bool keep_reliable);

  /// Removes and returns, in id order, the requests whose deadline is not
  /// after `now`.
  std::vector<outgoing> take_expired(time_point now);

  /// Removes and returns all.
  std::vector<outgoing> take_all();

  /// The reliable requests to look at now, in id order: those whose
  /// next_send is not after `now`, and those of the bindings in `forced`
  /// (all of them, or with `unacked_only` those the receiver did not ack).
  std::vector<uint64_t> due(time_point now,
                            const std::vector<uint32_t>& forced,
                            bool unacked_only) const;

  /// The request, or nullptr.
  outgoing* find(uint64_t rid) {
    auto i = requests_.find(rid);
    return i != requests_.end() ? &i->second : nullptr;
  }

private:
  template <class Pred>
  std::vector<outgoing> take_if(Pred pred);

  scrambled_sequence<uint64_t> ids_;
  size_t max_;
  reliable_requests& reliable_;
  app_support_stats* stats_;
  std::map<uint64_t, outgoing> requests_;
  spare_nodes<std::map<uint64_t, outgoing>> spare_;
};

} // namespace herm
