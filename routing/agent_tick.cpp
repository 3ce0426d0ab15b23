#include "routing/agent_state.hpp"

// The routing agent's housekeeping tick: liveness of neighbours, expiry of
// routes and seqno requests, the address allocator's deadlines, and at each
// hello the hellos, periodic updates and announcements.
//
// The housekeeping tick runs on a grid of quarter hello intervals that ends
// at the next hello: at every hello (hellos, periodic updates and
// announcements), and between hellos only at the first grid point at or
// after something expires (a neighbour, a route, a seqno request) or the
// address allocator must act. So an idle module ticks once or twice per
// hello interval instead of four times, and a silently failed link is still
// noticed within a quarter interval of its neighbour's expiry.
//
// Nothing that happens between ticks makes something due before the tick
// on its way: a new neighbour expires hello_loss (at least 1) intervals
// after its hello, a route its hold (at least an interval) after its
// update, a seqno request an interval after it was sent, and the address
// allocator acts a claim interval (the hello interval) after it claimed;
// the tick on its way is due at the next hello at the latest, less than an
// interval away.

#include <algorithm>
#include <optional>
#include <vector>

#include "channels/lax_timer.hpp"

namespace herm::agent_detail {

namespace {

using agent_time = caf::actor_clock::time_point;

caf::timespan quarter_of(const agent_state& st) {
  // At least 1 ms: hello intervals below 4 ms reach here through the API.
  return std::max(caf::timespan{st.cfg.hello_interval} / 4,
                  caf::timespan{std::chrono::milliseconds{1}});
}

/// The first point of the tick grid at or after `t`; the next hello when
/// `t` is after it.
agent_time grid_point_from(const agent_state& st, agent_time t) {
  if (t >= st.next_hello)
    return st.next_hello;
  return st.next_hello - ((st.next_hello - t) / quarter_of(st)) * quarter_of(st);
}

/// The earliest time something the tick handles falls due, if anything.
std::optional<agent_time> next_deadline(const agent_state& st) {
  std::optional<agent_time> first;
  for (auto t : {st.neighbours.next_expiry(), st.requested.next_expiry(),
                 st.table.next_expiry(), st.alloc->next_deadline()})
    if (t && (!first || *t < *first))
      first = t;
  return first;
}

/// Sends the next tick, due at `due`; one already on its way no longer
/// counts.
void schedule_tick(agent_impl self, agent_time due) {
  auto& st = self->state;
  st.next_tick = due;
  // Lax: on a busy loop the tick rides on a wake the traffic makes.
  send_lax_at(self, due, lax_slack(quarter_of(st)), atom::tick_v,
              ++st.tick_generation);
}

} // namespace

void tick(agent_impl self) {
  auto& st = self->state;
  auto now = self->clock().now();
  bool first = st.tick_generation == 1;
  // When this tick was due: its grid point (the first tick: now).
  auto due = first ? now : st.next_tick;
  // A check between hellos that fired after the next hello says it too.
  bool hello_due = first || now >= st.next_hello;
  if (hello_due) {
    // An interval after the last one was due; late by a whole interval
    // (or the first), the grid starts afresh.
    st.next_hello += st.cfg.hello_interval;
    if (first || st.next_hello <= now)
      st.next_hello = now + st.cfg.hello_interval;
  }
  if (hello_due && !st.leaving)
    send_hellos(self);
  // Neighbours silent for too long are gone.
  table_change change;
  std::vector<neighbour_table::neighbour> was;
  auto lost = st.neighbours.expire(now, st.cfg.on_neighbour ? &was : nullptr);
  for (size_t i = 0; i < lost.size(); ++i) {
    auto& nh = lost[i];
    if (i < was.size())
      report_neighbour(self, nh, was[i].id, was[i].instance, false,
                       "hellos lost");
    auto c = st.table.remove_neighbour(nh);
    change.changed.insert(change.changed.end(), c.changed.begin(),
                          c.changed.end());
  }
  // Seqno requests older than an interval no longer hold back new ones.
  st.requested.expire(now);
  auto expired = st.table.expire(now);
  change.changed.insert(change.changed.end(), expired.changed.begin(),
                        expired.changed.end());
  change.starving.insert(change.starving.end(), expired.starving.begin(),
                         expired.starving.end());
  std::sort(change.changed.begin(), change.changed.end());
  change.changed.erase(std::unique(change.changed.begin(), change.changed.end()),
                       change.changed.end());
  apply_change(self, change);
  // The allocator acts as at its deadline or this tick's grid point, so
  // that its next deadline, a claim interval later, falls on the grid too
  // (ticks fire a little late on the loop scheduler).
  if (auto deadline = st.alloc->next_deadline(); deadline && *deadline <= now)
    act(self, st.alloc->tick(std::max(*deadline, std::min(due, now))));
  if (hello_due) {
    if (++st.ticks % st.cfg.update_every == 0)
      send_update(self, st.table.destinations());
    if (st.alloc->assigned() && st.ticks % st.cfg.announce_every == 0) {
      // An announcement is a claim whose nonce is the claimant's instance
      // (a fresh claim's nonce is random): receivers treat it as "this id
      // is in use by that instance" and apply the merge rule (a static
      // id's holder names itself holder: address_allocator.hpp).
      claim announce{st.alloc->id(), st.alloc->instance(),
                     st.alloc->instance(), default_hop_limit};
      send_all(self, encoded(self, announce));
      ++st.stats.tx_claims;
    }
  }
  auto deadline = next_deadline(st);
  schedule_tick(self, deadline ? grid_point_from(st, std::max(*deadline,
                                                              due + caf::timespan{1}))
                               : st.next_hello);
}

} // namespace herm::agent_detail
