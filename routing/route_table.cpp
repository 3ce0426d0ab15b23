#include "routing/route_table.hpp"

#include <algorithm>
#include <set>
#include <tuple>
#include <utility>

// Babel's route selection (RFC 8966 3.5 and 3.6), one topology per size class.
//
// Layout: destinations in an ordered map (O(log n) per update), each holding
// its few routes (one per neighbour that advertises it) in a small vector.
// Expiry, tombstones and idle sources sit in ordered sets keyed by time, kept
// exact (an entry is erased whenever what it describes changes), so expire()
// only touches what is due. Every neighbour indexes the destinations it
// advertises so that neighbour changes touch only its own routes.
//
// Paths: `path` in rows and advertisements runs from this module towards the
// destination (first the kind of the link to the next hop). The paper prints
// the same list origin-first ("CAN2.0-Ethernet" for our [Ethernet, CAN2.0]).

namespace herm {

bool seqno_newer(seqno_t a, seqno_t b) {
  auto d = static_cast<seqno_t>(a - b);
  return d != 0 && d < 0x8000;
}

namespace {

using time_point = route_table::time_point;
using duration = route_table::duration;

// -- pure decisions ---------------------------------------------------------------

/// Feasibility distance of one origin in one class: the best (seqno, metric)
/// this module has selected (and therefore advertised).
struct distance {
  seqno_t seqno = 0;
  metric value = infinite_metric;
};

using fd_slot = std::optional<distance>;

/// (s, m) is strictly better than `fd`: a newer seqno, or the same with a
/// smaller metric. No FD at all is beaten by anything.
bool beats(seqno_t s, metric m, const fd_slot& fd) {
  return !fd || seqno_newer(s, fd->seqno) || (s == fd->seqno && m < fd->value);
}

/// RFC 8966 3.5.1. `refmetric` is the neighbour's metric, before adding the
/// cost of the link to it. A retraction is always feasible.
bool update_feasible(const fd_slot& fd, seqno_t s, metric refmetric) {
  return refmetric == infinite_metric || beats(s, refmetric, fd);
}

/// Our metric for a class: the neighbour's plus the link's, saturating.
/// Unreachable when the route would exceed max_route_hops.
metric route_metric(metric refmetric, uint8_t advertised_hops, metric cost) {
  if (refmetric == infinite_metric || advertised_hops >= max_route_hops)
    return infinite_metric;
  return add_metric(refmetric, cost);
}

/// Links cost at least 1: a metric must grow along a path or a selected route
/// would fail its own feasibility condition once its FD is recorded.
metric_vector clamp_cost(metric_vector cost) {
  for (auto& c : cost)
    c = std::max<metric>(c, 1);
  return cost;
}

/// Absurd input check of update() (everything but the neighbour).
bool well_formed(const advertised& adv, module_id self) {
  if (!is_unicast(adv.origin) || adv.origin == self)
    return false;
  for (size_t k = 0; k < size_classes; ++k) {
    if (adv.metrics[k] == infinite_metric)
      continue;
    if (adv.hops[k] > max_route_hops || adv.path[k].size() != adv.hops[k])
      return false;
  }
  return true;
}

bool is_retraction(const advertised& adv) {
  return adv.metrics == infinite_metrics;
}

/// Same content for neighbours: metrics, hops and paths in every class, and
/// the seqno unless both are plain retractions (whose seqno nobody checks).
bool same_advertisement(const advertised& x, const advertised& y) {
  if (x.metrics != y.metrics || x.hops != y.hops || x.path != y.path)
    return false;
  return x.seqno == y.seqno || x.metrics == infinite_metrics;
}

// -- state ------------------------------------------------------------------------

struct route {
  next_hop via;
  link_code kind = link_code::unknown; ///< of the link to `via`
  seqno_t seqno = 0;
  metric_vector refmetrics = infinite_metrics; ///< the neighbour's metrics
  metric_vector metrics = infinite_metrics;    ///< ours (advertised + cost)
  std::array<uint8_t, size_classes> advertised_hops{};
  /// The neighbour's paths, classes with equal paths sharing their bytes:
  /// class k's is tail[tail_at[k], tail_at[k] + advertised_hops[k]).
  std::array<uint8_t, size_classes> tail_at{};
  std::vector<link_code> tail;
  time_point expires;
  duration hold{};

  uint8_t hops(size_t k) const {
    return metrics[k] == infinite_metric ? 0 : advertised_hops[k] + 1;
  }

  std::vector<link_code> path(size_t k) const {
    std::vector<link_code> result;
    if (metrics[k] == infinite_metric)
      return result;
    result.reserve(advertised_hops[k] + 1u);
    result.push_back(kind);
    auto first = tail.begin() + tail_at[k];
    result.insert(result.end(), first, first + advertised_hops[k]);
    return result;
  }

  void set_paths(const advertised& adv) {
    tail.clear();
    for (size_t k = 0; k < size_classes; ++k) {
      advertised_hops[k] = 0;
      tail_at[k] = 0;
      if (adv.metrics[k] == infinite_metric)
        continue;
      advertised_hops[k] = adv.hops[k];
      size_t j = 0;
      while (j < k
             && (adv.metrics[j] == infinite_metric || adv.path[j] != adv.path[k]))
        ++j;
      if (j < k) {
        tail_at[k] = tail_at[j];
      } else {
        tail_at[k] = static_cast<uint8_t>(tail.size());
        tail.insert(tail.end(), adv.path[k].begin(), adv.path[k].end());
      }
    }
  }
};

/// Preferred route in class k: lower metric, then fewer hops, then lower
/// next hop (deterministic).
bool preferred(const route& x, const route& y, size_t k) {
  auto xh = x.hops(k);
  auto yh = y.hops(k);
  return std::tie(x.metrics[k], xh, x.via) < std::tie(y.metrics[k], yh, y.via);
}

struct destination {
  std::vector<route> routes;
  std::array<std::optional<next_hop>, size_classes> selected;
  /// What we advertise for it now (kept by recompute).
  advertised adv;
  /// Set while the destination has no route left: it is advertised as
  /// retracted until then.
  std::optional<time_point> tombstone;

  route* find(next_hop nh) {
    for (auto& r : routes)
      if (r.via == nh)
        return &r;
    return nullptr;
  }

  const route* find(next_hop nh) const {
    return const_cast<destination*>(this)->find(nh);
  }
};

struct source {
  std::array<fd_slot, size_classes> fd;
  /// No destination entry for the origin any more.
  bool idle = false;
  std::optional<time_point> idle_since;
};

struct neighbour {
  metric_vector cost = infinite_metrics;
  link_code kind = link_code::unknown;
  std::set<module_id> destinations;
};

/// Sources of an origin with no route are forgotten after
/// max(3 * the longest hold seen, this).
constexpr duration min_source_hold = std::chrono::minutes{5};

} // namespace

struct route_table::impl {
  module_id self;
  route_limits limits;
  size_t route_count = 0;
  uint64_t sources_evicted = 0;
  seqno_t own_seqno = 0;
  std::map<next_hop, neighbour> neighbours;
  std::map<module_id, destination> dests;
  std::map<module_id, source> sources;
  std::set<std::tuple<time_point, module_id, next_hop>> expiries;
  std::set<std::pair<time_point, module_id>> tombstones;
  std::set<std::pair<time_point, module_id>> idle_sources; // by idle_since
  std::vector<module_id> newly_idle; // idle, not yet stamped by expire()
  duration longest_hold{};
  size_t reachable = 0;

  impl(module_id id, route_limits lim) : self(id), limits(lim) {
  }

  duration source_hold() const {
    return std::max<duration>(3 * longest_hold, min_source_hold);
  }

  const fd_slot* fds(module_id origin) const {
    auto i = sources.find(origin);
    return i == sources.end() ? nullptr : i->second.fd.data();
  }

  // -- sources ---------------------------------------------------------------------

  void mark_busy(module_id origin) {
    auto i = sources.find(origin);
    if (i == sources.end() || !i->second.idle)
      return;
    i->second.idle = false;
    if (i->second.idle_since)
      idle_sources.erase({*i->second.idle_since, origin});
    i->second.idle_since.reset();
  }

  void mark_idle(module_id origin) {
    auto i = sources.find(origin);
    if (i == sources.end() || i->second.idle)
      return;
    i->second.idle = true;
    i->second.idle_since.reset();
    newly_idle.push_back(origin);
  }

  void forget_source(module_id origin) {
    auto i = sources.find(origin);
    if (i == sources.end())
      return;
    if (i->second.idle_since)
      idle_sources.erase({*i->second.idle_since, origin});
    sources.erase(i);
  }

  // -- destinations ----------------------------------------------------------------

  destination& make_destination(module_id origin) {
    auto [i, added] = dests.try_emplace(origin);
    if (added) {
      i->second.adv.origin = origin;
      mark_busy(origin);
    }
    return i->second;
  }

  void clear_tombstone(module_id dest, destination& d) {
    if (d.tombstone) {
      tombstones.erase({*d.tombstone, dest});
      d.tombstone.reset();
    }
  }

  void set_tombstone(module_id dest, destination& d, time_point until) {
    clear_tombstone(dest, d);
    d.tombstone = until;
    tombstones.emplace(until, dest);
  }

  /// Removes route `r` of `d` (without recomputing the selection). A
  /// destination left without routes stays advertised as retracted until
  /// `tombstone`.
  void drop_route(module_id dest, destination& d, route* r,
                  time_point tombstone) {
    if (auto nb = neighbours.find(r->via); nb != neighbours.end())
      nb->second.destinations.erase(dest);
    erase_route(dest, d, r, tombstone);
  }

  /// The part of drop_route that leaves the neighbour's index alone.
  void erase_route(module_id dest, destination& d, route* r,
                   time_point tombstone) {
    expiries.erase({r->expires, dest, r->via});
    --route_count;
    if (r != &d.routes.back())
      *r = std::move(d.routes.back());
    d.routes.pop_back();
    if (d.routes.empty())
      set_tombstone(dest, d, tombstone);
  }

  /// Reselects every class of `dest`, records feasibility distances and
  /// reports a change of what we advertise or of a next hop.
  void recompute(module_id dest, destination& d, table_change& out) {
    auto& fd = sources[dest].fd;
    auto was_reachable = d.selected[0].has_value();
    auto old_selected = d.selected;
    std::array<const route*, size_classes> best{};
    for (size_t k = 0; k < size_classes; ++k) {
      for (auto& r : d.routes) {
        if (r.metrics[k] == infinite_metric
            || !update_feasible(fd[k], r.seqno, r.refmetrics[k]))
          continue;
        if (!best[k] || preferred(r, *best[k], k))
          best[k] = &r;
      }
      d.selected[k].reset();
      if (best[k]) {
        d.selected[k] = best[k]->via;
        if (beats(best[k]->seqno, best[k]->metrics[k], fd[k]))
          fd[k] = distance{best[k]->seqno, best[k]->metrics[k]};
      }
    }
    // Advertise the oldest seqno among the selected classes (normally they
    // are all equal). A seqno newer than a class's own route would let a
    // neighbour accept that class's metric as feasible too early (a loop);
    // an older one only makes neighbours stricter.
    advertised adv;
    adv.origin = dest;
    std::optional<seqno_t> seqno;
    for (size_t k = 0; k < size_classes; ++k) {
      auto r = best[k];
      if (!r)
        continue;
      adv.metrics[k] = r->metrics[k];
      adv.hops[k] = r->hops(k);
      adv.path[k] = r->path(k);
      if (!seqno || seqno_newer(*seqno, r->seqno))
        seqno = r->seqno;
    }
    // Nothing selected: a retraction. It carries the class-0 FD's seqno, so
    // a seqno request for a starving destination asks for that plus one.
    if (!seqno && fd[0])
      seqno = fd[0]->seqno;
    if (!seqno && !d.routes.empty())
      seqno = d.routes.front().seqno;
    adv.seqno = seqno ? *seqno : d.adv.seqno;
    if (std::none_of(fd.begin(), fd.end(),
                     [](const fd_slot& x) { return x.has_value(); }))
      sources.erase(dest); // nothing ever selected: no source yet
    if (old_selected != d.selected || !same_advertisement(adv, d.adv))
      out.changed.push_back(dest);
    d.adv = std::move(adv);
    // Starving in any class: only a new seqno from the origin helps, and it
    // helps every class at once.
    auto starving = false;
    for (size_t k = 0; k < size_classes && !starving; ++k)
      if (!d.selected[k])
        for (auto& r : d.routes)
          starving = starving || r.metrics[k] != infinite_metric;
    if (starving)
      out.starving.push_back(dest);
    auto is_reachable = d.selected[0].has_value();
    if (is_reachable != was_reachable)
      is_reachable ? ++reachable : --reachable;
  }

  void recompute_all(std::vector<module_id>& touched, table_change& out) {
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    for (auto dest : touched)
      if (auto i = dests.find(dest); i != dests.end())
        recompute(dest, i->second, out);
  }

  /// Removes the neighbours in [first, last) and their routes.
  table_change drop_neighbours(std::map<next_hop, neighbour>::iterator first,
                               std::map<next_hop, neighbour>::iterator last) {
    std::vector<module_id> touched;
    for (auto nb = first; nb != last; ++nb) {
      for (auto dest : nb->second.destinations) {
        auto& d = dests.at(dest);
        auto r = d.find(nb->first);
        erase_route(dest, d, r, r->expires);
        touched.push_back(dest);
      }
    }
    neighbours.erase(first, last);
    table_change out;
    recompute_all(touched, out);
    return out;
  }
};

// -- construction -------------------------------------------------------------------

route_table::route_table(module_id self, route_limits limits)
  : impl_(std::make_unique<impl>(self, limits)) {
}

route_table::~route_table() = default;

route_table::route_table(route_table&&) noexcept = default;

route_table& route_table::operator=(route_table&&) noexcept = default;

module_id route_table::self() const noexcept {
  return impl_->self;
}

void route_table::set_self(module_id id) {
  auto& s = *impl_;
  if (id == s.self)
    return;
  auto old = s.self;
  s.self = id;
  if (auto i = s.dests.find(id); i != s.dests.end()) {
    auto& d = i->second;
    while (!d.routes.empty())
      s.drop_route(id, d, &d.routes.back(), time_point{});
    s.clear_tombstone(id, d);
    if (d.selected[0])
      --s.reachable;
    s.dests.erase(i);
  }
  s.forget_source(id);
  // Neighbours still advertise our old id back to us for a while: record the
  // FD we had as its origin, (own seqno, 0), so those echoes are unfeasible
  // and cannot form a loop. A newer seqno (a new holder) passes.
  if (is_unicast(old)) {
    auto& src = s.sources[old];
    for (auto& fd : src.fd)
      fd = distance{s.own_seqno, 0};
    if (s.dests.count(old) == 0)
      s.mark_idle(old);
  }
}

// -- neighbours ---------------------------------------------------------------------

table_change route_table::set_neighbour(next_hop nh, metric_vector cost,
                                        link_code kind) {
  auto& s = *impl_;
  cost = clamp_cost(cost);
  auto [i, added] = s.neighbours.try_emplace(nh);
  auto& nb = i->second;
  table_change out;
  if (!added && nb.cost == cost && nb.kind == kind)
    return out;
  nb.cost = cost;
  nb.kind = kind;
  for (auto dest : nb.destinations) {
    auto& d = s.dests.at(dest);
    auto r = d.find(nh);
    r->kind = kind;
    for (size_t k = 0; k < size_classes; ++k)
      r->metrics[k] = route_metric(r->refmetrics[k], r->advertised_hops[k],
                                   cost[k]);
    s.recompute(dest, d, out);
  }
  return out;
}

table_change route_table::remove_neighbour(next_hop nh) {
  auto& s = *impl_;
  auto i = s.neighbours.find(nh);
  if (i == s.neighbours.end())
    return {};
  return s.drop_neighbours(i, std::next(i));
}

table_change route_table::remove_channel(channel_id channel) {
  auto& s = *impl_;
  auto first = s.neighbours.lower_bound(next_hop{channel, 0});
  auto last = first;
  while (last != s.neighbours.end() && last->first.channel == channel)
    ++last;
  return s.drop_neighbours(first, last);
}

// -- updates ------------------------------------------------------------------------

update_result route_table::update(next_hop from, const advertised& adv,
                                  time_point now, duration hold,
                                  table_change& out) {
  auto& s = *impl_;
  if (!well_formed(adv, s.self))
    return update_result::malformed;
  auto nb = s.neighbours.find(from);
  if (nb == s.neighbours.end())
    return update_result::unknown_neighbour;
  auto retraction = is_retraction(adv);
  auto di = s.dests.find(adv.origin);
  if (di == s.dests.end() && retraction)
    return update_result::accepted; // retraction of a route we never had
  auto r = di != s.dests.end() ? di->second.find(from) : nullptr;
  if (!r && retraction)
    return update_result::accepted;
  // A retraction of a route already retracted is no news and must not keep
  // it alive: two neighbours that both hold retracted routes from each
  // other advertise the retraction to each other in every periodic update,
  // and refreshing would keep the destination (and its room in the table)
  // for ever. It expires at the end of the hold the first retraction set.
  if (r && retraction && r->refmetrics == infinite_metrics)
    return update_result::accepted;
  // Bounds apply to what is new only: a route held is refreshed whatever
  // the table's size, so that a full table keeps serving what it has.
  if (!r) {
    if (di == s.dests.end() && s.dests.size() >= s.limits.destinations)
      return update_result::over_limit;
    if (nb->second.destinations.size() >= s.limits.per_neighbour)
      return update_result::over_share;
    if (s.route_count >= s.limits.routes)
      return update_result::over_limit;
  }
  hold = std::max(hold, duration::zero());
  s.longest_hold = std::max(s.longest_hold, hold);
  auto& d = di != s.dests.end() ? di->second : s.make_destination(adv.origin);
  if (!r) {
    d.routes.emplace_back();
    ++s.route_count;
    r = &d.routes.back();
    r->via = from;
    nb->second.destinations.insert(adv.origin);
  } else {
    s.expiries.erase({r->expires, adv.origin, from});
  }
  r->kind = nb->second.kind;
  r->seqno = adv.seqno;
  r->refmetrics = adv.metrics;
  r->set_paths(adv);
  for (size_t k = 0; k < size_classes; ++k)
    r->metrics[k] = route_metric(adv.metrics[k], r->advertised_hops[k],
                                 nb->second.cost[k]);
  r->hold = hold;
  r->expires = now + hold;
  s.expiries.emplace(r->expires, adv.origin, from);
  s.clear_tombstone(adv.origin, d);
  s.recompute(adv.origin, d, out);
  return update_result::accepted;
}

std::optional<route_table::time_point> route_table::next_expiry() const {
  auto& s = *impl_;
  std::optional<time_point> first;
  auto consider = [&first](time_point t) {
    if (!first || t < *first)
      first = t;
  };
  if (!s.expiries.empty())
    consider(std::get<0>(*s.expiries.begin()));
  if (!s.tombstones.empty())
    consider(s.tombstones.begin()->first);
  if (!s.idle_sources.empty())
    consider(s.idle_sources.begin()->first + s.source_hold());
  return first;
}

table_change route_table::expire(time_point now) {
  auto& s = *impl_;
  table_change out;
  std::vector<module_id> touched;
  while (!s.expiries.empty() && std::get<0>(*s.expiries.begin()) <= now) {
    auto dest = std::get<1>(*s.expiries.begin());
    auto via = std::get<2>(*s.expiries.begin());
    auto& d = s.dests.at(dest);
    auto r = d.find(via);
    s.drop_route(dest, d, r, now + r->hold);
    touched.push_back(dest);
  }
  s.recompute_all(touched, out);
  while (!s.tombstones.empty() && s.tombstones.begin()->first <= now) {
    auto dest = s.tombstones.begin()->second;
    s.tombstones.erase(s.tombstones.begin());
    auto i = s.dests.find(dest);
    i->second.tombstone.reset();
    s.dests.erase(i); // no routes, hence nothing selected
    s.mark_idle(dest);
  }
  for (auto origin : s.newly_idle) {
    auto i = s.sources.find(origin);
    if (i != s.sources.end() && i->second.idle && !i->second.idle_since) {
      i->second.idle_since = now;
      s.idle_sources.emplace(now, origin);
    }
  }
  s.newly_idle.clear();
  auto hold = s.source_hold();
  while (!s.idle_sources.empty() && s.idle_sources.begin()->first + hold <= now)
    s.forget_source(s.idle_sources.begin()->second);
  // Destinations come and go as fast as neighbours advertise and retract
  // them, and each leaves an idle source behind for minutes: keep at most
  // as many idle ones as the table holds destinations, forgetting the
  // oldest first (their FD only matters if they come back before the hold).
  while (s.idle_sources.size() > s.limits.destinations) {
    s.forget_source(s.idle_sources.begin()->second);
    ++s.sources_evicted;
  }
  return out;
}

// -- what to advertise ----------------------------------------------------------------

std::optional<advertised> route_table::advertisement(module_id dest) const {
  auto& s = *impl_;
  if (dest == s.self) {
    advertised adv;
    adv.origin = s.self;
    adv.seqno = s.own_seqno;
    adv.metrics.fill(0);
    return adv;
  }
  auto i = s.dests.find(dest);
  if (i == s.dests.end())
    return std::nullopt;
  return i->second.adv;
}

std::vector<module_id> route_table::destinations() const {
  auto& s = *impl_;
  std::vector<module_id> result;
  result.reserve(s.dests.size() + 1);
  for (auto& entry : s.dests)
    result.push_back(entry.first);
  auto pos = std::lower_bound(result.begin(), result.end(), s.self);
  if (pos == result.end() || *pos != s.self)
    result.insert(pos, s.self);
  return result;
}

void route_table::bump_own_seqno() {
  ++impl_->own_seqno;
}

void route_table::set_own_seqno(seqno_t x) {
  if (seqno_newer(x, impl_->own_seqno))
    impl_->own_seqno = x;
}

seqno_t route_table::own_seqno() const noexcept {
  return impl_->own_seqno;
}

// -- forwarding -------------------------------------------------------------------------

std::optional<next_hop> route_table::lookup(module_id dest, uint8_t k) const {
  auto& s = *impl_;
  if (k >= size_classes)
    return std::nullopt;
  auto i = s.dests.find(dest);
  if (i == s.dests.end())
    return std::nullopt;
  return i->second.selected[k];
}

std::vector<route_row> route_table::rows() const {
  auto& s = *impl_;
  std::vector<route_row> result;
  for (auto& [dest, d] : s.dests) {
    auto fd = s.fds(dest);
    for (auto& r : d.routes) {
      for (uint8_t k = 0; k < size_classes; ++k) {
        route_row row;
        row.destination = dest;
        row.size_class = k;
        row.via = r.via;
        row.cost = r.metrics[k];
        row.hops = r.hops(k);
        row.path = r.path(k);
        row.seqno = r.seqno;
        row.selected = d.selected[k] == r.via;
        row.feasible = update_feasible(fd ? fd[k] : fd_slot{}, r.seqno,
                                       r.refmetrics[k]);
        result.push_back(std::move(row));
      }
    }
  }
  std::sort(result.begin(), result.end(),
            [](const route_row& x, const route_row& y) {
              return std::tie(x.destination, x.size_class, x.cost, x.hops,
                              x.via)
                     < std::tie(y.destination, y.size_class, y.cost, y.hops,
                                y.via);
            });
  return result;
}

size_t route_table::reachable() const {
  return impl_->reachable;
}

const route_limits& route_table::limits() const noexcept {
  return impl_->limits;
}

size_t route_table::size() const {
  return impl_->dests.size();
}

size_t route_table::routes() const {
  return impl_->route_count;
}

size_t route_table::routes_from(next_hop nh) const {
  auto i = impl_->neighbours.find(nh);
  return i == impl_->neighbours.end() ? 0 : i->second.destinations.size();
}

uint64_t route_table::sources_evicted() const {
  return impl_->sources_evicted;
}

} // namespace herm
