#include "routing/agent_state.hpp"

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
  if (!allowed || (st.fast_dests.empty() && st.receivers.empty())) {
    cell->publish(nullptr);
    return;
  }
  auto snap = std::make_shared<route_snapshot>();
  snap->self = st.table.self();
  for (auto& [protocol, receiver] : st.receivers)
    snap->receivers.emplace(protocol, receiver);
  for (auto dst : st.fast_dests) {
    auto& hops = snap->routes[dst];
    for (uint8_t k = 0; k < size_classes; ++k)
      if (auto nh = st.table.lookup(dst, k))
        if (auto i = st.channels.find(nh->channel); i != st.channels.end())
          hops[k] = fast_hop{i->second.handle, nh->neighbour};
  }
  cell->publish(std::move(snap));
}

void note_fast_destination(agent_impl self, module_id dst) {
  auto& st = self->state;
  if (!st.cfg.fast_routes || st.fast_dests.count(dst) > 0)
    return;
  if (st.fast_dests.size() >= st.cfg.fast_routes->max_destinations()) {
    ++st.stats.fast_routes_refused;
    return;
  }
  st.fast_dests.insert(dst);
  publish_fast_routes(self);
}

} // namespace herm::agent_detail
