#include "routing/agent_state.hpp"

#include <iterator>

// The routing agent's side of the fast path for established routes
// (routing/fast_routes.hpp): which destinations the snapshot covers and
// when it is published or withdrawn.

namespace herm::agent_detail {

void publish_fast_routes(agent_impl self) {
  auto& st = self->state;
  auto& cell = st.cfg.fast_routes;
  if (!cell)
    return;
  bool allowed = st.alloc->assigned() && !st.auth && !st.cfg.tracer
                 && !st.cfg.observer && !st.leaving;
  if (!allowed
      || (st.fast_dests.empty() && st.fast_transit.empty()
          && st.receivers.empty())) {
    cell->publish(nullptr);
    return;
  }
  auto snap = std::make_shared<route_snapshot>();
  snap->self = st.table.self();
  for (auto& [protocol, receiver] : st.receivers)
    snap->receivers.emplace(protocol, receiver);
  // A destination the table no longer holds (not even retracted) gives
  // its place back; the next packet sent or forwarded to it through the
  // agent takes one again.
  auto add = [&](std::set<module_id>& dests) {
    for (auto d = dests.begin(); d != dests.end();) {
      if (!st.table.advertisement(*d)) {
        d = dests.erase(d);
        continue;
      }
      auto& hops = snap->routes[*d];
      for (uint8_t k = 0; k < size_classes; ++k)
        if (auto nh = st.table.lookup(*d, k))
          if (auto i = st.channels.find(nh->channel); i != st.channels.end())
            hops[k] = fast_hop{i->second.handle, nh->neighbour};
      ++d;
    }
  };
  add(st.fast_dests);
  add(st.fast_transit);
  cell->publish(std::move(snap));
}

void note_fast_destination(agent_impl self, module_id dst, bool forwarded) {
  auto& st = self->state;
  if (!st.cfg.fast_routes || st.fast_dests.count(dst) > 0)
    return;
  // Originated or forwarded, each with a budget of its own: traffic
  // through the module never takes the places of its own destinations.
  auto& dests = forwarded ? st.fast_transit : st.fast_dests;
  if (forwarded && dests.count(dst) > 0)
    return;
  if (dests.size() >= st.cfg.fast_routes->max_destinations()) {
    // Full: the places of destinations the table forgot are free.
    for (auto d = dests.begin(); d != dests.end();)
      d = st.table.advertisement(*d) ? std::next(d) : dests.erase(d);
  }
  if (dests.size() >= st.cfg.fast_routes->max_destinations()) {
    ++st.stats.fast_routes_refused;
    return;
  }
  dests.insert(dst);
  if (!forwarded)
    st.fast_transit.erase(dst);
  publish_fast_routes(self);
}

} // namespace herm::agent_detail
