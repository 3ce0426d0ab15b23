#include "routing/agent_state.hpp"

// What the routing agent reports: route events to listeners, packet
// traces, and the rows and counters it answers queries with.

namespace herm::agent_detail {

namespace {

/// "Ethernet-CAN2.0": link kinds along a path.
std::string path_string(const std::vector<link_code>& path) {
  std::string out;
  for (auto code : path) {
    if (!out.empty())
      out += '-';
    out += to_string(code);
  }
  return out;
}

/// The selected class-0 route to `d` as a route event (was_* fields
/// empty). O(log N).
reachability route_event(agent_impl self, module_id d) {
  auto& st = self->state;
  reachability now;
  now.id = d;
  auto nh = st.table.lookup(d, 0);
  if (!nh)
    return now;
  now.reachable = true;
  now.channel = nh->channel;
  now.neighbour = nh->neighbour;
  if (auto n = st.neighbours.find(*nh))
    now.next = n->id;
  if (auto ci = st.channels.find(nh->channel); ci != st.channels.end())
    now.device = ci->second.info.device;
  now.link_address = link_address_text(self, *nh);
  if (auto adv = st.table.advertisement(d)) {
    now.hops = adv->hops[0];
    now.cost = adv->metrics[0];
    now.path = path_string(adv->path[0]);
  }
  return now;
}

} // namespace

/// Tells route listeners what changed for `dests` since they were told:
/// one event per destination whose selected class-0 route differs in any
/// way (appeared, withdrawn, other cost, hops, next hop or path).
/// O(|dests| log N).
void tell_route_changes(agent_impl self, const std::vector<module_id>& dests) {
  auto& st = self->state;
  if (st.route_listeners.empty())
    return;
  for (auto d : dests) {
    auto now = route_event(self, d);
    auto i = st.told.find(d);
    if (i != st.told.end()) {
      now.was_reachable = true;
      now.old_cost = i->second.cost;
      now.old_next = i->second.next;
      now.old_device = i->second.device;
      auto& was = i->second;
      if (now.reachable && now.cost == was.cost && now.hops == was.hops
          && now.next == was.next && now.channel == was.channel
          && now.neighbour == was.neighbour && now.path == was.path)
        continue;
    } else if (!now.reachable) {
      continue;
    }
    if (now.reachable)
      st.told[d] = now;
    else
      st.told.erase(i);
    for (auto& l : st.route_listeners)
      self->send(l, now);
  }
}

/// Fills the outgoing half of a trace and hands it to the tracer.
void trace_out(agent_impl self, packet_trace& t, const data_header& h,
               const next_hop& nh) {
  auto& st = self->state;
  if (auto i = st.channels.find(nh.channel); i != st.channels.end()) {
    t.out_link = i->second.info.profile.name;
    t.out_mtu = i->second.info.profile.mtu;
  }
  if (auto n = st.neighbours.find(nh))
    t.next = n->id;
  if (auto adv = st.table.advertisement(h.dst)) {
    t.cost = adv->metrics[h.size_class];
    t.forwarding = path_string(adv->path[h.size_class]);
  }
  st.cfg.tracer(t);
}

packet_trace make_trace(agent_impl self, packet_trace::what_t what,
                        const data_header& h, size_t bytes, channel_id in) {
  auto& st = self->state;
  packet_trace t;
  t.what = what;
  t.self = st.table.self();
  t.src = h.src;
  t.dst = h.dst;
  t.protocol = h.protocol;
  t.size_class = h.size_class;
  t.bytes = static_cast<uint32_t>(bytes);
  if (auto i = st.channels.find(in); in != 0 && i != st.channels.end()) {
    t.in_link = i->second.info.profile.name;
    t.in_mtu = i->second.info.profile.mtu;
  }
  return t;
}

void subscribe_routes(agent_impl self, route_listener_actor& l) {
  auto& st = self->state;
  if (st.route_listeners.empty()) {
    // Nobody listened: what was told is stale; tell the whole table.
    st.told.clear();
    st.pending_told.clear();
    st.route_listeners.push_back(l);
    tell_route_changes(self, st.table.destinations());
  } else {
    for (auto& kv : st.told)
      self->send(l, kv.second);
    st.route_listeners.push_back(l);
  }
  self->monitor(l);
}

std::vector<route_info> route_rows(agent_impl self) {
  auto& st = self->state;
  std::vector<route_info> result;
  for (auto& r : st.table.rows()) {
    route_info ri;
    ri.destination = r.destination;
    ri.size_class = r.size_class;
    ri.channel = r.via.channel;
    ri.neighbour = st.channels.count(r.via.channel) > 0
                     ? link_address_text(self, r.via)
                     : "?";
    ri.cost = r.cost;
    ri.hops = r.hops;
    ri.forwarding = path_string(r.path);
    ri.selected = r.selected;
    ri.feasible = r.feasible;
    result.push_back(std::move(ri));
  }
  return result;
}

std::vector<neighbour_info> neighbour_rows(agent_impl self) {
  auto& st = self->state;
  auto now = self->clock().now();
  std::vector<neighbour_info> result;
  for (auto& [nh, n] : st.neighbours.entries()) {
    neighbour_info ni;
    ni.channel = nh.channel;
    ni.link_address = link_address_text(self, nh);
    ni.id = n.id;
    ni.instance = n.instance;
    auto ci = st.channels.find(nh.channel);
    if (ci != st.channels.end()) {
      ni.link_kind = to_string(ci->second.code);
      ni.cost.assign(ci->second.cost.begin(), ci->second.cost.end());
    }
    ni.duplicate_id = n.id == st.table.self() && is_unicast(n.id)
                      && n.instance != st.alloc->instance();
    ni.last_heard_ms = static_cast<uint32_t>(
      std::chrono::duration_cast<std::chrono::milliseconds>(now - n.last_hello)
        .count());
    result.push_back(std::move(ni));
  }
  return result;
}

/// The counters, with the gauges and the pure cores' counters filled in.
routing_stats stats_now(agent_impl self) {
  auto& st = self->state;
  auto result = st.stats;
  result.reachable = static_cast<uint32_t>(st.table.reachable());
  result.destinations = static_cast<uint32_t>(st.table.size());
  result.routes = static_cast<uint32_t>(st.table.routes());
  result.neighbours = static_cast<uint32_t>(st.neighbours.size());
  result.rx_neighbours_over_limit = st.neighbours.refused();
  result.seqno_requests_over_limit = st.requested.over_limit();
  auto evicted = [&](packet_type t) {
    return st.floods.evicted(static_cast<uint8_t>(t));
  };
  result.floods_evicted = evicted(packet_type::claim)
                          + evicted(packet_type::conflict)
                          + evicted(packet_type::seqno_request);
  result.flood_ids_evicted = evicted(packet_type::data);
  if (auto& cell = st.cfg.fast_routes) {
    result.fast_sent = cell->sent();
    result.originated += result.fast_sent;
    result.fast_delivered = cell->delivered();
    result.delivered += result.fast_delivered;
    result.fast_forwarded = cell->forwarded();
    result.forwarded += result.fast_forwarded;
  }
  result.sources_evicted = st.table.sources_evicted();
  if (auto other = st.alloc->live_holder(self->clock().now())) {
    result.id_conflict_instance = *other;
    result.id_conflict_heard = st.conflict_heard;
  }
  return result;
}

} // namespace herm::agent_detail
