#pragma once

// Module addressing (section 4.2 of the paper): a static id from the
// configuration or the category pool, or a dynamic one negotiated by claims.
// Pure: no clock, no I/O, no global randomness; time and a seed go in.
//
// Dynamic protocol: pick a random id in [first_dynamic_module,
// last_dynamic_module], flood a claim, and repeat it `claim_repeats` times,
// `claim_interval` apart. A module holding that id (or claiming it with a
// lower nonce) answers with a conflict; the claimant then picks anew. After
// the last repeat with no conflict, the id is ours.
//
// Merge of two partitions: when an assigned module learns that another
// instance holds its id (a hello, update or claim from `id` with a different
// instance), the instance with the higher value renumbers: it floods a
// conflict naming itself as loser (so both sides agree) and starts claiming a
// new id; the agent withdraws routes to its old id.
//
// Static ids (docs/protocol.md, "Static modules") never change, so two
// modules configured with one id cannot be reconciled: the newcomer must
// stay out. A static module holds its id at once (it routes from the
// start) but is on probation for claim_repeats claim intervals: it floods
// an announcement (a claim whose nonce is its instance) once per interval,
// and a live holder of the id answers with a conflict naming it loser. On
// probation it refuses to join (actions::refused) when
//   - a conflict names it (its own instance: only a live holder that heard
//     this very instance sends that), or
//   - it hears directly (a neighbour's hello or update) another instance
//     with a lower instance (two newcomers at once: the lower stays).
// A flooded announcement of another instance alone never refuses: it may
// be our own previous instance's (a restart after kill -9) still on its
// way; a live holder answers our announcement anyway. After probation the
// module is a holder: it keeps its id whatever it hears, names itself
// holder in its conflicts (a dynamic module with that id renumbers, a
// static newcomer refuses) and reports a dispute (actions::disputed) once
// per other instance, again when that one was silent for live_intervals.

#include <chrono>
#include <cstdint>
#include <optional>
#include <random>
#include <vector>

#include "routing/module_id.hpp"
#include "routing/wire.hpp"

namespace herm {

class address_allocator {
public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;

  struct config {
    /// A fixed id (static addressing), or no_module for dynamic.
    module_id static_id = no_module;
    /// Claims per attempt, the first at once, then one per claim_interval
    /// (0 counts as 1). The id is ours one interval after the last.
    uint32_t claim_repeats = 3;
    duration claim_interval = std::chrono::milliseconds(300);
    module_id first = first_dynamic_module;
    module_id last = last_dynamic_module;
    /// Static ids: another instance heard holding our id is a live holder
    /// for this many claim_intervals after it was last heard (0 counts as
    /// 1).
    uint32_t live_intervals = 3;
  };

  /// Another instance holds our static id (see the top of this file).
  struct dispute {
    module_id id = no_module;
    uint64_t other = 0;
    /// We are the newcomer and must not join.
    bool refused = false;
  };

  /// What the agent must do after an event.
  struct actions {
    /// Flood these.
    std::vector<claim> claims;
    std::vector<conflict> conflicts;
    /// We lost our id `renumbered_from` (withdraw its routes). id() is
    /// no_module until the new claim succeeds (a later `assigned`).
    std::optional<module_id> renumbered_from;
    /// We just got an id (or a new one).
    bool assigned = false;
    /// Static ids: a dispute started (or we refuse to join); report it.
    std::optional<dispute> disputed;
  };

  address_allocator(config cfg, uint64_t instance, uint64_t seed);

  /// Starts: a static id is assigned at once; a dynamic one starts claiming.
  actions start(time_point now);

  /// Timer: repeats claims, assigns after the last repeat.
  actions tick(time_point now);

  /// When tick() next has something to do.
  std::optional<time_point> next_deadline() const;

  /// A claim from the network.
  actions on_claim(const claim& x, time_point now);

  /// A conflict from the network.
  actions on_conflict(const conflict& x, time_point now);

  /// We heard `id` used by `instance`: detects merges and duplicate static
  /// ids. `direct`: from that module itself, a neighbour's hello or update;
  /// false for a flooded announcement, which may be old.
  actions on_heard(module_id id, uint64_t instance, time_point now,
                   bool direct = true);

  /// Our current id: no_module while claiming (the first id, or a new one
  /// after losing ours).
  module_id id() const noexcept;

  /// The id being claimed, if claiming.
  std::optional<module_id> claiming() const noexcept;

  bool assigned() const noexcept;

  uint64_t instance() const noexcept;

  /// Number of times this module picked a new id (conflicts, merges).
  uint32_t renumberings() const noexcept;

  /// Static modules only: evidence of another holder of our id seen after
  /// probation (a hello, update or announcement of another instance, or a
  /// conflict naming us loser), counted at most once per other instance
  /// per claim_interval.
  uint32_t static_conflicts() const noexcept;

  /// Static modules only: disputes reported (actions::disputed, refusals
  /// included).
  uint32_t disputes() const noexcept;

  /// Static modules only: the other holder of our id most recently heard,
  /// if heard within the last live_intervals claim intervals.
  std::optional<uint64_t> live_holder(time_point now) const;

  /// Static modules only: still on probation at `now` (started less than
  /// claim_repeats claim intervals ago, not refused).
  bool on_probation(time_point now) const noexcept;

  /// Static modules only: refused to join (another instance holds our id).
  bool refused() const noexcept;

private:
  /// Starts claiming a fresh random id other than `avoid`.
  actions begin_claim(time_point now, module_id avoid = no_module);

  /// Gives up our assigned id and starts claiming another one.
  actions renumber(time_point now);

  module_id pick(module_id avoid);

  /// Static ids: evidence of holder `other`, heard `direct`ly or not.
  actions static_heard(uint64_t other, bool direct, time_point now);

  /// Static ids: gives up joining; `other` holds our id.
  actions refuse(uint64_t other);

  /// Static ids: remembers holder `other` heard now; true if that starts a
  /// dispute (not heard within the live window before).
  bool note_holder(uint64_t other, time_point now);

  duration live_window() const;

  /// True if a conflict about (`other`, `nonce`, `kind`) went out less than
  /// `window` ago; otherwise remembers that one goes out now.
  bool recently(uint64_t other, uint64_t nonce, uint8_t kind, duration window,
                time_point now);

  struct sent_conflict {
    uint64_t other;
    uint64_t nonce;
    uint8_t kind;
    time_point at;
  };

  config cfg_;
  uint64_t instance_;
  std::mt19937_64 rng_;
  module_id id_ = no_module;
  module_id claiming_ = no_module;
  uint64_t nonce_ = 0;
  uint32_t sent_ = 0;
  time_point next_;
  bool assigned_ = false;
  uint32_t renumberings_ = 0;
  uint32_t static_conflicts_ = 0;
  uint32_t disputes_ = 0;
  /// Static ids: probation ends here; announcements sent in it.
  time_point probation_end_;
  uint32_t announced_ = 0;
  bool refused_ = false;
  /// Static ids: other holders of our id and when each was last heard;
  /// bounded (max_holders), the least recently heard forgotten first.
  struct holder {
    uint64_t instance;
    time_point at;
  };
  std::vector<holder> holders_;
  /// Conflicts sent (or, for kind merge, disputes counted) recently: the
  /// rate limit. Pruned on use; bounded.
  std::vector<sent_conflict> recent_;
};

} // namespace herm
