#include "routing/address_allocator.hpp"

#include <algorithm>
#include <cassert>

namespace herm {

namespace {

/// Kinds of rate-limited events (sent_conflict::kind).
constexpr uint8_t kind_answer = 0; // a conflict answering a claim
constexpr uint8_t kind_merge = 1;  // a merge with another holder of our id

/// Bound of the rate-limit memory: distinct claimants or holders of our id
/// heard within one claim_interval. Beyond it the oldest is forgotten, which
/// costs at most one extra conflict.
constexpr size_t max_recent = 64;

/// Bound of the other holders of a static id remembered at once (each a
/// misconfigured module, or a forger); beyond it the least recently heard
/// is forgotten, which at worst reports its dispute again.
constexpr size_t max_holders = 8;

address_allocator::config normalized(address_allocator::config cfg) {
  cfg.first = std::max(cfg.first, module_id{1});
  cfg.last = std::min(cfg.last, module_id{broadcast_module - 1});
  if (cfg.first > cfg.last) {
    cfg.first = first_dynamic_module;
    cfg.last = last_dynamic_module;
  }
  cfg.claim_repeats = std::max(cfg.claim_repeats, uint32_t{1});
  cfg.live_intervals = std::max(cfg.live_intervals, uint32_t{1});
  return cfg;
}

} // namespace

address_allocator::address_allocator(config cfg, uint64_t instance,
                                     uint64_t seed)
  : cfg_(normalized(cfg)), instance_(instance), rng_(seed) {
  // A static id must be one a module may hold.
  assert(cfg.static_id == no_module || is_unicast(cfg.static_id));
  // An empty or impossible dynamic range is a configuration error; release
  // builds fall back to the default range.
  assert(cfg.first <= cfg.last && is_unicast(cfg.first)
         && is_unicast(cfg.last));
}

// -- time ------------------------------------------------------------------------

address_allocator::actions address_allocator::start(time_point now) {
  recent_.clear();
  if (is_unicast(cfg_.static_id)) {
    id_ = cfg_.static_id;
    claiming_ = no_module;
    assigned_ = true;
    refused_ = false;
    holders_.clear();
    // Probation: one announcement per interval, the first now.
    probation_end_ = now + cfg_.claim_interval * cfg_.claim_repeats;
    announced_ = 1;
    next_ = now + cfg_.claim_interval;
    actions a;
    a.assigned = true;
    a.claims.push_back(claim{id_, instance_, instance_, default_hop_limit});
    return a;
  }
  id_ = no_module;
  assigned_ = false;
  return begin_claim(now);
}

address_allocator::actions address_allocator::tick(time_point now) {
  actions a;
  if (is_unicast(cfg_.static_id)) {
    if (refused_ || announced_ >= cfg_.claim_repeats || now < next_)
      return a;
    ++announced_;
    next_ = now + cfg_.claim_interval;
    a.claims.push_back(claim{id_, instance_, instance_, default_hop_limit});
    return a;
  }
  if (claiming_ == no_module || now < next_)
    return a;
  next_ = now + cfg_.claim_interval;
  if (sent_ < cfg_.claim_repeats) {
    ++sent_;
    a.claims.push_back(claim{claiming_, nonce_, instance_, default_hop_limit});
    return a;
  }
  // A whole interval after the last claim without a conflict: ours.
  id_ = claiming_;
  claiming_ = no_module;
  nonce_ = 0;
  assigned_ = true;
  recent_.clear();
  a.assigned = true;
  return a;
}

std::optional<address_allocator::time_point>
address_allocator::next_deadline() const {
  if (is_unicast(cfg_.static_id) && assigned_
      && announced_ < cfg_.claim_repeats)
    return next_;
  if (claiming_ == no_module)
    return std::nullopt;
  return next_;
}

// -- network ---------------------------------------------------------------------

address_allocator::actions address_allocator::on_claim(const claim& x,
                                                       time_point now) {
  actions a;
  // Our own claims flooded back, and claims no module could make.
  if (x.instance == instance_ || !is_unicast(x.id) || x.nonce == 0)
    return a;
  auto answer = [&] {
    if (!recently(x.instance, x.nonce, kind_answer, cfg_.claim_interval / 2,
                  now))
      a.conflicts.push_back(conflict{x.id, instance_, x.nonce, x.instance,
                                     default_hop_limit});
  };
  if (assigned_ && x.id == id_) {
    answer();
    return a;
  }
  if (claiming_ != no_module && x.id == claiming_) {
    // Two claimants: the lower nonce wins (the lower instance on a tie).
    bool we_win = nonce_ != x.nonce ? nonce_ < x.nonce : instance_ < x.instance;
    if (we_win) {
      // Our repeats would make them lose too; answering at once also
      // covers claim_repeats == 1 and lost claims.
      answer();
      return a;
    }
    ++renumberings_;
    return begin_claim(now, claiming_);
  }
  return a;
}

address_allocator::actions address_allocator::on_conflict(const conflict& x,
                                                          time_point now) {
  actions a;
  if (!is_unicast(x.id))
    return a;
  if (claiming_ != no_module && x.id == claiming_ && x.claim_nonce != 0
      && x.claim_nonce == nonce_) {
    // Our claim was refused: try another id.
    ++renumberings_;
    return begin_claim(now, claiming_);
  }
  if (assigned_ && x.id == id_ && x.loser_instance == instance_
      && x.holder_instance != instance_) {
    if (!is_unicast(cfg_.static_id))
      return renumber(now);
    // It names this very instance: its sender is alive and heard us.
    if (on_probation(now))
      return refuse(x.holder_instance);
    if (!recently(x.holder_instance, 0, kind_merge, cfg_.claim_interval, now))
      ++static_conflicts_;
    if (note_holder(x.holder_instance, now))
      a.disputed = dispute{id_, x.holder_instance, false};
  }
  return a;
}

address_allocator::actions address_allocator::on_heard(module_id id,
                                                       uint64_t instance,
                                                       time_point now,
                                                       bool direct) {
  actions a;
  if (instance == instance_ || !is_unicast(id))
    return a;
  if (is_unicast(cfg_.static_id)) {
    if (!assigned_ || id != id_)
      return a;
    return static_heard(instance, direct, now);
  }
  if (claiming_ != no_module && id == claiming_) {
    // Somebody holds the id we are claiming: no need to wait for its
    // conflict.
    ++renumberings_;
    return begin_claim(now, claiming_);
  }
  if (!assigned_ || id != id_)
    return a;
  // Two holders of one id met (partitions merged): the higher instance
  // loses. Both sides compute the same conflict, so either copy will do.
  if (recently(instance, 0, kind_merge, cfg_.claim_interval, now))
    return a;
  auto winner = std::min(instance, instance_);
  auto loser = std::max(instance, instance_);
  conflict c{id, winner, 0, loser, default_hop_limit};
  if (loser == instance_) {
    if (!is_unicast(cfg_.static_id)) {
      a = renumber(now);
      a.conflicts.insert(a.conflicts.begin(), c);
      return a;
    }
    ++static_conflicts_;
  }
  a.conflicts.push_back(c);
  return a;
}

// -- state -----------------------------------------------------------------------

module_id address_allocator::id() const noexcept {
  return id_;
}

std::optional<module_id> address_allocator::claiming() const noexcept {
  if (claiming_ == no_module)
    return std::nullopt;
  return claiming_;
}

bool address_allocator::assigned() const noexcept {
  return assigned_;
}

uint64_t address_allocator::instance() const noexcept {
  return instance_;
}

uint32_t address_allocator::renumberings() const noexcept {
  return renumberings_;
}

uint32_t address_allocator::static_conflicts() const noexcept {
  return static_conflicts_;
}

uint32_t address_allocator::disputes() const noexcept {
  return disputes_;
}

std::optional<uint64_t> address_allocator::live_holder(time_point now) const {
  const holder* last = nullptr;
  for (auto& h : holders_)
    if (now < h.at + live_window() && (last == nullptr || h.at >= last->at))
      last = &h;
  if (last == nullptr)
    return std::nullopt;
  return last->instance;
}

bool address_allocator::on_probation(time_point now) const noexcept {
  return is_unicast(cfg_.static_id) && assigned_ && !refused_
         && now < probation_end_;
}

bool address_allocator::refused() const noexcept {
  return refused_;
}

// -- internals -------------------------------------------------------------------

address_allocator::actions address_allocator::begin_claim(time_point now,
                                                          module_id avoid) {
  claiming_ = pick(avoid);
  do {
    nonce_ = rng_(); // 0 marks merge conflicts: never a claim's nonce
  } while (nonce_ == 0);
  sent_ = 1;
  next_ = now + cfg_.claim_interval;
  actions a;
  a.claims.push_back(claim{claiming_, nonce_, instance_, default_hop_limit});
  return a;
}

address_allocator::actions address_allocator::renumber(time_point now) {
  auto lost = id_;
  id_ = no_module;
  assigned_ = false;
  ++renumberings_;
  recent_.clear(); // everything remembered concerned the old id
  auto a = begin_claim(now, lost);
  a.renumbered_from = lost;
  return a;
}

module_id address_allocator::pick(module_id avoid) {
  // Uniform over [first, last] without `avoid` (modulo bias below 2^-48).
  uint32_t n = uint32_t{cfg_.last} - cfg_.first + 1;
  bool skip = avoid >= cfg_.first && avoid <= cfg_.last && n > 1;
  if (skip)
    --n;
  auto x = static_cast<uint32_t>(cfg_.first + rng_() % n);
  if (skip && x >= avoid)
    ++x;
  return static_cast<module_id>(x);
}

address_allocator::actions
address_allocator::static_heard(uint64_t other, bool direct, time_point now) {
  actions a;
  conflict ours{id_, instance_, 0, other, default_hop_limit};
  if (on_probation(now)) {
    // Two newcomers hear each other: the lower instance stays. Only direct
    // evidence refuses: a flooded announcement may be our previous life's.
    if (other < instance_) {
      if (direct)
        return refuse(other);
      return a; // a live holder answers our announcement with a conflict
    }
    if (!recently(other, 0, kind_merge, cfg_.claim_interval, now))
      a.conflicts.push_back(ours);
    // Heard from itself: a live module with our id (not an old flood).
    if (direct && note_holder(other, now))
      a.disputed = dispute{id_, other, false};
    return a;
  }
  // A holder: keeps its id, tells the other to stay out, reports.
  if (!recently(other, 0, kind_merge, cfg_.claim_interval, now)) {
    ++static_conflicts_;
    a.conflicts.push_back(ours);
  }
  if (note_holder(other, now))
    a.disputed = dispute{id_, other, false};
  return a;
}

address_allocator::actions address_allocator::refuse(uint64_t other) {
  actions a;
  refused_ = true;
  assigned_ = false;
  ++disputes_;
  a.disputed = dispute{id_, other, true};
  return a;
}

bool address_allocator::note_holder(uint64_t other, time_point now) {
  for (auto& h : holders_)
    if (h.instance == other) {
      bool lapsed = now >= h.at + live_window();
      h.at = now;
      if (lapsed)
        ++disputes_;
      return lapsed;
    }
  if (holders_.size() >= max_holders)
    holders_.erase(std::min_element(holders_.begin(), holders_.end(),
                                    [](const holder& x, const holder& y) {
                                      return x.at < y.at;
                                    }));
  holders_.push_back(holder{other, now});
  ++disputes_;
  return true;
}

address_allocator::duration address_allocator::live_window() const {
  return cfg_.claim_interval * cfg_.live_intervals;
}

bool address_allocator::recently(uint64_t other, uint64_t nonce, uint8_t kind,
                                 duration window, time_point now) {
  // Everything older than the longest window (claim_interval) is useless.
  recent_.erase(std::remove_if(recent_.begin(), recent_.end(),
                               [&](const sent_conflict& e) {
                                 return now >= e.at + cfg_.claim_interval;
                               }),
                recent_.end());
  for (auto& e : recent_)
    if (e.other == other && e.nonce == nonce && e.kind == kind
        && now < e.at + window)
      return true;
  if (recent_.size() >= max_recent)
    recent_.erase(recent_.begin()); // the oldest: entries are in time order
  recent_.push_back(sent_conflict{other, nonce, kind, now});
  return false;
}

} // namespace herm
