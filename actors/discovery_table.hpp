#pragma once

// Discovery for one application support actor (pure core; docs/protocol.md,
// "Discovery"): the discoveries running, per query id what is looked for,
// the matches collected so far and whom to tell at the end; the answers to
// other modules' queries; and what their answers teach the application
// table about remote APOs.
//
// No clock and no I/O: time comes in as arguments, queries and answers go
// into the caller's asl_outbox, and the caller ends each discovery when its
// time is over (or as soon as it is satisfied). Works on the module's
// app_table, which must outlive it. Not thread-safe (one actor owns it).
// Each discovery holds at most `max_found` matches and the table at most
// `max_found` remote APOs (more are refused, counted); start and answers
// are O(e log f) for e entries and f found.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <vector>

#include "actors/app_support.hpp"
#include "actors/app_table.hpp"
#include "actors/asl_outbox.hpp"

namespace herm {

class discovery_table {
public:
  using time_point = app_table::time_point;

  /// Called once with the matches when a discovery ends.
  using callback = std::function<void(std::vector<apo_ref>)>;

  /// Query ids come from a scrambled_sequence keyed with `key` (one id
  /// seen gives away no other). Counts queries_sent, queries_answered,
  /// answers_received, remote_apos_refused and discovery_entries_refused
  /// into `stats`, which must outlive it.
  discovery_table(uint64_t key, size_t max_found, app_table& table,
                  app_support_stats& stats);

  /// Starts a discovery of `q` with the matches on this module (`self`'s,
  /// not bounded): returns its query id, never 0 or one running. Unless it
  /// is satisfied already, the query is broadcast.
  uint32_t start(apo_query q, module_id self, callback finish,
                 asl_outbox& out);

  /// Whether discovery `qid` may end now: it wants the first answer and
  /// has a match. False for an unknown id.
  bool satisfied(uint32_t qid) const;

  /// Module `src` asks for the APOs here: they are answered in answers of
  /// at most max_answer_entries entries; nothing is sent without a match.
  void on_query(module_id src, const asl_query& q, asl_outbox& out);

  /// Module `src` answered at `now`: its entries are learned (refreshed
  /// entries always fit) and those matching a running discovery collected.
  /// Returns satisfied(a.query_id); an unknown (ended, forged) id collects
  /// nothing.
  bool on_answer(module_id src, const asl_answer& a, time_point now);

  struct finished {
    callback finish;
    /// The matches of module `self` first, then by module and number.
    std::vector<apo_ref> found;
  };

  /// Ends discovery `qid`; nullopt if it is not running.
  std::optional<finished> finish(uint32_t qid, module_id self);

  /// The ids of every discovery running, in id order.
  std::vector<uint32_t> running() const;

private:
  struct discovery {
    apo_query query;
    std::set<apo_ref> found;
    callback finish;
  };

  scrambled_sequence<uint32_t> ids_;
  size_t max_found_;
  app_table& table_;
  app_support_stats* stats_;
  std::map<uint32_t, discovery> running_;
};

} // namespace herm
