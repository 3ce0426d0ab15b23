#include "routing/agent_state.hpp"

#include <iterator>

// The routing agent's side of the fast path for established routes
// (routing/fast_routes.hpp): which destinations the snapshot covers and
// when it is published or withdrawn.

namespace herm::agent_detail {

namespace {

/// Gives back the places of destinations the table no longer holds (not
/// even retracted); the next packet sent or forwarded to one of them
/// through the agent takes a place again.
void forget_unknown(agent_state& st, std::set<module_id>& dests) {
  for (auto d = dests.begin(); d != dests.end();)
    d = st.table.advertisement(*d) ? std::next(d) : dests.erase(d);
}

} // namespace

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
  for (auto* dests : {&st.fast_dests, &st.fast_transit}) {
    forget_unknown(st, *dests);
    for (auto dst : *dests) {
      auto& hops = snap->routes[dst];
      for (uint8_t k = 0; k < size_classes; ++k)
        if (auto nh = st.table.lookup(dst, k))
          if (auto i = st.channels.find(nh->channel); i != st.channels.end())
            hops[k] = fast_hop{i->second.handle, nh->neighbour};
    }
  }
  cell->publish(std::move(snap));
}

void note_fast_destination(agent_impl self, module_id dst, bool forwarded) {
  auto& st = self->state;
  if (!st.cfg.fast_routes || st.fast_dests.count(dst) > 0
      || (forwarded && st.fast_transit.count(dst) > 0))
    return;
  // Originated or forwarded, each with a budget of its own: traffic
  // through the module never takes the places of its own destinations.
  auto& dests = forwarded ? st.fast_transit : st.fast_dests;
  auto bound = st.cfg.fast_routes->max_destinations();
  if (dests.size() >= bound)
    forget_unknown(st, dests);
  if (dests.size() >= bound) {
    ++st.stats.fast_routes_refused;
    return;
  }
  dests.insert(dst);
  if (!forwarded)
    st.fast_transit.erase(dst);
  publish_fast_routes(self);
}

} // namespace herm::agent_detail
