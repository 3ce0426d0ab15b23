#include "routing/routing_agent.hpp"

#include <algorithm>
#include <memory>
#include <deque>
#include <map>
#include <set>
#include <random>

#include "caf/actor_system.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "routing/error.hpp"
#include "routing/type_ids.hpp"
#include "routing/address_allocator.hpp"
#include "routing/wire.hpp"

namespace herm {

namespace {

using time_point = std::chrono::steady_clock::time_point;

struct neighbour_state {
  module_id id = no_module;
  uint64_t instance = 0;
  time_point last_hello;
  std::chrono::milliseconds interval{0};
};

struct channel_state {
  channel_actor handle;
  channel_info info;
  metric_vector cost = infinite_metrics;
  link_code code = link_code::unknown;
};

struct agent_state {
  static inline const char* name = "herm.routing";

  routing_config cfg;
  io_manager_actor io;
  route_table table{no_module};
  std::unique_ptr<address_allocator> alloc;
  std::map<channel_id, channel_state> channels;
  std::map<next_hop, neighbour_state> neighbours;
  std::map<uint8_t, network_receiver_actor> receivers;
  /// Floods seen recently (claims, conflicts, seqno requests), by key, with
  /// the time they were last relayed, and the same in arrival order for
  /// forgetting them; bounded by cfg.max_floods.
  using flood_key = std::tuple<uint8_t, uint64_t, uint64_t>;
  std::map<flood_key, time_point> floods;
  std::deque<std::pair<time_point, flood_key>> floods_order;
  /// Triggered updates not sent yet (see apply_change).
  std::set<module_id> pending_changed;
  std::set<module_id> pending_starving;
  bool flush_scheduled = false;
  /// When a seqno request for a destination was last sent, within the last
  /// hello interval (older ones are forgotten at the next tick); at most
  /// cfg.max_seqno_requests.
  std::map<module_id, time_point> requested;
  /// Flooded broadcasts seen, by (source, flood id), and the same keys in
  /// arrival order for forgetting the oldest; bounded by cfg.max_flood_ids.
  std::set<std::pair<module_id, uint32_t>> flood_ids;
  std::deque<std::pair<time_point, std::pair<module_id, uint32_t>>> flood_order;
  uint32_t next_flood_id = 1;
  /// Route listeners and what they were told last, per destination
  /// reachable (a subset of the table's destinations), and the
  /// destinations whose selected route may have changed since the last
  /// flush (a subset of the table's destinations too, and of the ones it
  /// dropped since): both bounded by the table's bound.
  std::vector<route_listener_actor> route_listeners;
  std::map<module_id, reachability> told;
  std::set<module_id> pending_told;
  routing_stats stats;
  uint16_t hello_seqno = 0;
  /// Hello intervals and quarter intervals since start.
  uint32_t ticks = 0;
  uint32_t quarters = 0;
  /// Said goodbye: sends no more hellos.
  bool leaving = false;
  /// Where the other holder of our static id was last reported heard.
  std::string conflict_heard;
  byte_buffer buf;
  /// Signs and verifies packets when the network has a key.
  std::unique_ptr<authenticator> auth;

  std::chrono::steady_clock::duration hold() const {
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      cfg.hello_interval * cfg.update_every * cfg.hold_factor);
  }
};

using agent_impl = routing_agent_actor::stateful_pointer<agent_state>;

// -- sending --------------------------------------------------------------------

/// `bytes` as they leave on channel `cs`: with a trailer for that link when
/// `sign` (a keyed network), else unchanged. Data packets get their
/// authenticated flag set first.
byte_buffer outgoing(agent_impl self, const channel_state& cs,
                     const byte_buffer& bytes, bool sign) {
  auto& st = self->state;
  if (!sign || !st.auth)
    return bytes;
  byte_buffer out;
  out.reserve(bytes.size() + st.auth->config().trailer_size());
  out = bytes;
  if (!out.empty() && (out[0] & 0x0F) == static_cast<uint8_t>(packet_type::data)
      && out.size() >= data_header_size)
    set_authenticated(out.data(), true);
  st.auth->sign(out, static_cast<uint8_t>(cs.code));
  ++st.stats.tx_signed;
  return out;
}

/// Control packets: signed whenever the network has a key.
void send_on(agent_impl self, channel_id ch, link_addr dst,
             const byte_buffer& bytes, uint8_t prio = prio_control) {
  auto i = self->state.channels.find(ch);
  if (i != self->state.channels.end())
    self->send(i->second.handle,
               write_packet{dst, prio, outgoing(self, i->second, bytes, true)});
}

void send_all(agent_impl self, const byte_buffer& bytes,
              channel_id except = 0) {
  for (auto& kv : self->state.channels)
    if (kv.first != except)
      self->send(kv.second.handle,
                 write_packet{broadcast_addr, prio_control,
                              outgoing(self, kv.second, bytes, true)});
}

/// Encodes this module's next hello into st.buf; a goodbye (interval 0)
/// when `leaving`.
void make_hello(agent_impl self, bool leaving) {
  auto& st = self->state;
  auto interval = std::clamp<int64_t>(st.cfg.hello_interval.count(), 1, 0xFFFF);
  hello h{st.table.self(), st.alloc->instance(), st.hello_seqno++,
          static_cast<uint16_t>(leaving ? 0 : interval)};
  st.buf.clear();
  encode(h, st.buf);
}

/// Hellos on every channel; a goodbye (interval 0) when `leaving`.
void send_hellos(agent_impl self, bool leaving = false) {
  auto& st = self->state;
  make_hello(self, leaving);
  send_all(self, st.buf);
  st.stats.tx_hellos += st.channels.size();
}

/// Advertises `dests` on every channel (or only `only` when not 0).
void send_update(agent_impl self, const std::vector<module_id>& dests,
                 channel_id only = 0) {
  auto& st = self->state;
  if (st.channels.empty())
    return;
  update u;
  u.sender = st.table.self();
  u.instance = st.alloc->instance();
  auto flush = [&] {
    if (u.entries.empty())
      return;
    st.buf.clear();
    encode(u, st.buf);
    if (only != 0)
      send_on(self, only, broadcast_addr, st.buf);
    else
      send_all(self, st.buf);
    st.stats.tx_updates += only != 0 ? 1 : st.channels.size();
    st.stats.tx_update_entries += u.entries.size();
    u.entries.clear();
  };
  for (auto d : dests) {
    if (!is_unicast(d))
      continue;
    if (auto adv = st.table.advertisement(d)) {
      u.entries.push_back(std::move(*adv));
      if (u.entries.size() == max_update_entries)
        flush();
    }
  }
  flush();
}

void send_seqno_requests(agent_impl self, const std::vector<module_id>& dests) {
  auto& st = self->state;
  auto now = self->clock().now();
  for (auto d : dests) {
    // At most one request per destination per hello interval.
    auto i = st.requested.find(d);
    if (i != st.requested.end() && now - i->second < st.cfg.hello_interval)
      continue;
    if (i == st.requested.end()) {
      if (st.requested.size() >= st.cfg.max_seqno_requests) {
        ++st.stats.seqno_requests_over_limit;
        continue;
      }
      i = st.requested.emplace(d, now).first;
    }
    i->second = now;
    auto adv = st.table.advertisement(d);
    seqno_request req{st.table.self(), d,
                      static_cast<seqno_t>((adv ? adv->seqno : 0) + 1),
                      max_route_hops};
    st.buf.clear();
    encode(req, st.buf);
    send_all(self, st.buf);
    ++st.stats.tx_seqno_requests;
  }
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
  if (auto n = st.neighbours.find(*nh); n != st.neighbours.end())
    now.next = n->second.id;
  if (auto adv = st.table.advertisement(d)) {
    now.hops = adv->hops[0];
    now.cost = adv->metrics[0];
    for (auto code : adv->path[0]) {
      if (!now.path.empty())
        now.path += '-';
      now.path += to_string(code);
    }
  }
  return now;
}

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

/// Collects what changed; a flush message queued behind the messages being
/// processed sends one triggered update for the whole burst (a cold start
/// or a failure changes many destinations through many updates at once),
/// and one route event per destination changed. O(|change| log N).
void apply_change(agent_impl self, const table_change& change) {
  auto& st = self->state;
  if (!st.route_listeners.empty())
    st.pending_told.insert(change.changed.begin(), change.changed.end());
  st.pending_changed.insert(change.changed.begin(), change.changed.end());
  st.pending_starving.insert(change.starving.begin(), change.starving.end());
  if (!st.flush_scheduled
      && (!st.pending_changed.empty() || !st.pending_starving.empty())) {
    st.flush_scheduled = true;
    self->send(self, atom::flush_v);
  }
}

void flush_changes(agent_impl self) {
  auto& st = self->state;
  st.flush_scheduled = false;
  std::vector<module_id> changed(st.pending_changed.begin(),
                                 st.pending_changed.end());
  std::vector<module_id> starving(st.pending_starving.begin(),
                                  st.pending_starving.end());
  st.pending_changed.clear();
  st.pending_starving.clear();
  if (!st.pending_told.empty()) {
    std::vector<module_id> told(st.pending_told.begin(), st.pending_told.end());
    st.pending_told.clear();
    tell_route_changes(self, told);
  }
  if (!changed.empty())
    send_update(self, changed);
  if (!starving.empty())
    send_seqno_requests(self, starving);
}

// -- addressing -----------------------------------------------------------------

/// "channel 1 (eth0) from link address 5, hello": where a packet came from,
/// for id conflict reports.
std::string heard_at(agent_impl self, channel_id ch, link_addr src,
                     const char* what) {
  auto& st = self->state;
  auto ci = st.channels.find(ch);
  return "channel " + std::to_string(ch) + " ("
         + (ci != st.channels.end() ? ci->second.info.device : "?")
         + ") from link address " + std::to_string(src) + ", " + what;
}

/// A dispute over our static id (address_allocator): counted, reported to
/// the configured callback; a newcomer says goodbye and ends.
void on_dispute(agent_impl self, const address_allocator::dispute& d,
                const std::string& where) {
  auto& st = self->state;
  st.stats.id_conflicts = st.alloc->disputes();
  st.conflict_heard = where;
  if (st.cfg.on_id_conflict)
    st.cfg.on_id_conflict(id_conflict{d.id, d.other, where, d.refused});
  if (!d.refused)
    return;
  // Routes through us are wrong from the start: neighbours drop them now.
  send_hellos(self, true);
  st.leaving = true;
  self->quit(make_error(ec::already_exists,
                        "module id " + to_hex(d.id)
                          + " is already held by instance "
                          + std::to_string(d.other) + " (heard on " + where
                          + "): not joining; a static id must be unique"));
}

void act(agent_impl self, address_allocator::actions acts,
         const std::string& where = "") {
  auto& st = self->state;
  if (acts.disputed)
    on_dispute(self, *acts.disputed, where);
  for (auto& c : acts.claims) {
    st.buf.clear();
    encode(c, st.buf);
    send_all(self, st.buf);
    ++st.stats.tx_claims;
  }
  for (auto& c : acts.conflicts) {
    st.buf.clear();
    encode(c, st.buf);
    send_all(self, st.buf);
    ++st.stats.tx_conflicts;
  }
  if (acts.renumbered_from) {
    // Withdraw the old id: advertise it unreachable with a newer seqno.
    advertised gone;
    gone.origin = *acts.renumbered_from;
    gone.seqno = static_cast<seqno_t>(st.table.own_seqno() + 1);
    update u{st.table.self(), st.alloc->instance(), {gone}};
    st.buf.clear();
    encode(u, st.buf);
    send_all(self, st.buf);
    ++st.stats.renumberings;
  }
  if (acts.renumbered_from) {
    st.stats.self = no_module;
    st.stats.assigned = false;
  }
  if (acts.assigned) {
    st.table.set_self(st.alloc->id());
    st.table.bump_own_seqno();
    st.stats.self = st.alloc->id();
    st.stats.assigned = st.alloc->assigned();
    send_update(self, {st.table.self()});
  }
}

/// True if this flood was not relayed recently; records it.
bool fresh_flood(agent_impl self, uint8_t type, uint64_t a, uint64_t b) {
  auto& st = self->state;
  auto now = self->clock().now();
  auto key = std::make_tuple(type, a, b);
  auto window = st.cfg.hello_interval / 2;
  // What is older than the window suppresses nothing: forget it, oldest
  // first. A key is recorded only when absent (or forgotten), so the map
  // and the order hold the same entries.
  auto forget_oldest = [&st] {
    st.floods.erase(st.floods_order.front().second);
    st.floods_order.pop_front();
  };
  while (!st.floods_order.empty()
         && now - st.floods_order.front().first >= window)
    forget_oldest();
  if (st.floods.count(key) > 0)
    return false;
  // Full of fresh ones (a flood of distinct floods): forget the oldest; a
  // duplicate of it may then be relayed once more, which hop limits bound.
  while (!st.floods_order.empty() && st.floods.size() >= st.cfg.max_floods) {
    forget_oldest();
    ++st.stats.floods_evicted;
  }
  st.floods.emplace(key, now);
  st.floods_order.emplace_back(now, key);
  return true;
}

// -- receiving ------------------------------------------------------------------

void deliver(agent_impl self, const data_header& h, const byte_buffer& bytes) {
  auto& st = self->state;
  auto i = st.receivers.find(h.protocol);
  if (i == st.receivers.end()) {
    ++st.stats.dropped_no_receiver;
    return;
  }
  ++st.stats.delivered;
  // The originator sends with default_hop_limit and every forwarding
  // module takes one off, so a packet from a neighbour arrives with the
  // default (1 hop); one from this module never left it (0 hops).
  uint8_t hops = h.src == st.table.self()
                   ? 0
                   : static_cast<uint8_t>(default_hop_limit - h.hop_limit + 1);
  // A keyed module keeps the authenticated flag of a data packet whose
  // trailer it verified (authenticate()); a keyless one never gets here
  // with it set (on_data).
  packet_delivered msg{h.src, h.protocol, h.priority, hops,
                       byte_buffer(bytes.begin() + header_size(h),
                                   bytes.end()),
                       h.authenticated};
  self->send(i->second, std::move(msg));
}

/// Fills the outgoing half of a trace and hands it to the tracer.
void trace_out(agent_impl self, packet_trace& t, const data_header& h,
               const next_hop& nh) {
  auto& st = self->state;
  if (auto i = st.channels.find(nh.channel); i != st.channels.end()) {
    t.out_link = i->second.info.profile.name;
    t.out_mtu = i->second.info.profile.mtu;
  }
  if (auto n = st.neighbours.find(nh); n != st.neighbours.end())
    t.next = n->second.id;
  if (auto adv = st.table.advertisement(h.dst)) {
    t.cost = adv->metrics[h.size_class];
    for (auto code : adv->path[h.size_class]) {
      if (!t.forwarding.empty())
        t.forwarding += '-';
      t.forwarding += to_string(code);
    }
  }
  st.cfg.tracer(t);
}

packet_trace make_trace(agent_impl self, packet_trace::what_t what,
                        const data_header& h, size_t bytes,
                        channel_id in = 0) {
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

/// Whether a data packet (header `h`, encoded in `bytes` without trailer)
/// is signed on its way out.
bool must_sign(agent_impl self, const data_header& h, const byte_buffer& bytes) {
  auto& st = self->state;
  if (!st.auth)
    return false;
  // A packet that arrived signed leaves signed: what its originator asked
  // for (send_packet::sign, remote control) holds on every hop.
  if (h.authenticated)
    return true;
  auto off = header_size(h);
  return data_needs_auth(st.auth->config(), h.dst, h.protocol, bytes.data() + off,
                         bytes.size() - off);
}

/// Puts an encoded data packet on the channel and neighbour of `nh`, signed
/// when `sign`.
void transmit(agent_impl self, const next_hop& nh, uint8_t priority,
              byte_buffer bytes, bool sign) {
  auto i = self->state.channels.find(nh.channel);
  if (i == self->state.channels.end())
    return;
  if (sign)
    bytes = outgoing(self, i->second, bytes, true);
  self->send(i->second.handle,
             write_packet{nh.neighbour, priority, std::move(bytes)});
}

/// Passes on a packet for another module, one hop limit less.
void forward(agent_impl self, const data_header& h, byte_buffer bytes,
             channel_id in) {
  auto& st = self->state;
  if (h.hop_limit <= 1) {
    ++st.stats.dropped_hop_limit;
    return;
  }
  auto nh = st.table.lookup(h.dst, h.size_class);
  if (!nh) {
    ++st.stats.dropped_no_route;
    return;
  }
  set_hop_limit(bytes.data(), static_cast<uint8_t>(h.hop_limit - 1));
  ++st.stats.forwarded;
  if (st.cfg.tracer) {
    auto t = make_trace(self, packet_trace::forwarded, h, bytes.size(), in);
    trace_out(self, t, h, *nh);
  }
  auto sign = must_sign(self, h, bytes);
  transmit(self, *nh, h.priority, std::move(bytes), sign);
}

/// True the first time flood (src, id) is seen within the flood memory;
/// records it.
bool fresh_broadcast(agent_impl self, module_id src, uint32_t id) {
  auto& st = self->state;
  auto now = self->clock().now();
  while (!st.flood_order.empty()
         && (now - st.flood_order.front().first >= st.cfg.flood_memory
             || st.flood_order.size() >= st.cfg.max_flood_ids)) {
    if (now - st.flood_order.front().first < st.cfg.flood_memory)
      ++st.stats.flood_ids_evicted;
    st.flood_ids.erase(st.flood_order.front().second);
    st.flood_order.pop_front();
  }
  auto key = std::make_pair(src, id);
  if (!st.flood_ids.insert(key).second)
    return false;
  st.flood_order.emplace_back(now, key);
  return true;
}

/// Sends a flooded broadcast on every channel but `except` (signed per
/// link in a keyed network: every hop signs with its own counter).
void relay_broadcast(agent_impl self, uint8_t priority, const byte_buffer& bytes,
                     channel_id except) {
  for (auto& kv : self->state.channels)
    if (kv.first != except)
      self->send(kv.second.handle,
                 write_packet{broadcast_addr, priority,
                              outgoing(self, kv.second, bytes, true)});
}

void on_data(agent_impl self, channel_id ch, byte_buffer bytes) {
  auto& st = self->state;
  auto h = decode_data_header(bytes.data(), bytes.size());
  if (!h) {
    ++st.stats.rx_malformed;
    return;
  }
  if (h->authenticated && !st.auth) {
    // Signed by a keyed network, and this module has no key (a keyed one
    // has checked and removed the trailer): where the payload ends is
    // unknown, so nothing of it can be delivered.
    ++st.stats.rx_auth_failed;
    return;
  }
  if (h->dst == broadcast_module) {
    if (h->flood_id != 0) {
      if (h->src == st.table.self() || !fresh_broadcast(self, h->src, h->flood_id)) {
        ++st.stats.dropped_duplicate;
        return;
      }
      if (st.cfg.observer)
        st.cfg.observer(st.table.self(), *h, bytes);
      deliver(self, *h, bytes);
      if (h->hop_limit > 1) {
        set_hop_limit(bytes.data(), static_cast<uint8_t>(h->hop_limit - 1));
        ++st.stats.broadcasts_relayed;
        relay_broadcast(self, h->priority, bytes, ch);
      }
      return;
    }
    // Link-local broadcast: for the neighbours that hear it only.
    deliver(self, *h, bytes);
    return;
  }
  if (st.cfg.observer)
    st.cfg.observer(st.table.self(), *h, bytes);
  if (h->dst == st.table.self()) {
    if (st.cfg.tracer)
      st.cfg.tracer(make_trace(self, packet_trace::delivered, *h, bytes.size(), ch));
    deliver(self, *h, bytes);
  } else {
    forward(self, *h, std::move(bytes), ch);
  }
}

/// True if one more neighbour on channel `ch` stays within the bounds
/// (routing_config::max_neighbours, max_neighbours_per_channel). O(log n +
/// the channel's neighbours).
bool room_for_neighbour(agent_impl self, channel_id ch) {
  auto& st = self->state;
  if (st.neighbours.size() >= st.cfg.max_neighbours)
    return false;
  auto first = st.neighbours.lower_bound(next_hop{ch, 0});
  size_t on_channel = 0;
  for (auto i = first; i != st.neighbours.end() && i->first.channel == ch; ++i)
    if (++on_channel >= st.cfg.max_neighbours_per_channel)
      return false;
  return true;
}

void on_hello(agent_impl self, channel_id ch, link_addr src,
              const byte_buffer& bytes) {
  auto& st = self->state;
  auto h = decode_hello(bytes.data(), bytes.size());
  if (!h) {
    ++st.stats.rx_malformed;
    return;
  }
  auto ci = st.channels.find(ch);
  if (ci == st.channels.end())
    return;
  auto now = self->clock().now();
  next_hop nh{ch, src};
  if (h->interval_ms == 0) {
    // A goodbye: the neighbour leaves now; its routes go at once.
    auto i = st.neighbours.find(nh);
    if (i != st.neighbours.end() && i->second.instance == h->instance) {
      st.neighbours.erase(i);
      ++st.stats.rx_goodbyes;
      apply_change(self, st.table.remove_neighbour(nh));
    }
    return;
  }
  if (st.neighbours.count(nh) == 0 && !room_for_neighbour(self, ch)) {
    ++st.stats.rx_neighbours_over_limit;
    return;
  }
  auto [i, added] = st.neighbours.try_emplace(nh);
  auto& n = i->second;
  bool restarted = !added && n.instance != h->instance;
  n.id = h->sender;
  n.instance = h->instance;
  n.last_hello = now;
  n.interval = std::chrono::milliseconds(h->interval_ms);
  if (added || restarted) {
    apply_change(self, st.table.set_neighbour(nh, ci->second.cost, ci->second.code));
    // Tell the new neighbour everything we know at once.
    send_update(self, st.table.destinations(), ch);
  }
  if (is_unicast(h->sender))
    act(self, st.alloc->on_heard(h->sender, h->instance, now),
        h->sender == st.table.self() ? heard_at(self, ch, src, "hello") : "");
}

void on_update(agent_impl self, channel_id ch, link_addr src,
               const byte_buffer& bytes) {
  auto& st = self->state;
  auto u = decode_update(bytes.data(), bytes.size());
  if (!u) {
    ++st.stats.rx_malformed;
    return;
  }
  next_hop nh{ch, src};
  if (st.neighbours.count(nh) == 0) {
    ++st.stats.rx_unknown_neighbour;
    return;
  }
  auto now = self->clock().now();
  if (is_unicast(u->sender))
    act(self, st.alloc->on_heard(u->sender, u->instance, now),
        u->sender == st.table.self() ? heard_at(self, ch, src, "update") : "");
  table_change change;
  for (auto& e : u->entries) {
    // Neighbours echo our own routes back to us: not an error.
    if (e.origin == st.table.self())
      continue;
    switch (st.table.update(nh, e, now, st.hold(), change)) {
      case update_result::accepted:
        break;
      case update_result::over_limit:
        ++st.stats.rx_routes_over_limit;
        break;
      case update_result::over_share:
        ++st.stats.rx_routes_over_limit;
        ++st.stats.rx_routes_over_share;
        break;
      default:
        ++st.stats.rx_refused_routes;
        break;
    }
  }
  apply_change(self, change);
}

void on_seqno_request(agent_impl self, channel_id ch, const byte_buffer& bytes) {
  auto& st = self->state;
  auto r = decode_seqno_request(bytes.data(), bytes.size());
  if (!r) {
    ++st.stats.rx_malformed;
    return;
  }
  if (!fresh_flood(self, 3, r->origin, r->seqno))
    return;
  if (r->origin == st.table.self()) {
    // Jump to the requested seqno (a module that restarted may be far
    // behind what its neighbours remember), then advertise.
    st.table.set_own_seqno(r->seqno);
    send_update(self, {st.table.self()});
    return;
  }
  if (r->hop_count <= 1)
    return;
  // Towards the origin along our selected route, if any.
  auto nh = st.table.lookup(r->origin, 0);
  if (!nh || nh->channel == ch)
    return;
  auto fwd = *r;
  fwd.hop_count = static_cast<uint8_t>(r->hop_count - 1);
  st.buf.clear();
  encode(fwd, st.buf);
  send_on(self, nh->channel, nh->neighbour, st.buf);
}

void on_claim(agent_impl self, channel_id ch, link_addr src,
              const byte_buffer& bytes) {
  auto& st = self->state;
  auto c = decode_claim(bytes.data(), bytes.size());
  if (!c) {
    ++st.stats.rx_malformed;
    return;
  }
  if (c->instance == st.alloc->instance() || !fresh_flood(self, 4, c->id, c->nonce))
    return;
  if (c->nonce == c->instance)
    act(self,
        st.alloc->on_heard(c->id, c->instance, self->clock().now(), false),
        c->id == st.table.self() ? heard_at(self, ch, src, "announcement")
                                 : "");
  else
    act(self, st.alloc->on_claim(*c, self->clock().now()));
  if (c->hop_limit > 1) {
    auto fwd = *c;
    fwd.hop_limit = static_cast<uint8_t>(c->hop_limit - 1);
    st.buf.clear();
    encode(fwd, st.buf);
    send_all(self, st.buf, ch);
  }
}

void on_conflict(agent_impl self, channel_id ch, link_addr src,
                 const byte_buffer& bytes) {
  auto& st = self->state;
  auto c = decode_conflict(bytes.data(), bytes.size());
  if (!c) {
    ++st.stats.rx_malformed;
    return;
  }
  if (!fresh_flood(self, 5, c->id ^ (c->claim_nonce << 16),
                   c->holder_instance ^ c->loser_instance))
    return;
  act(self, st.alloc->on_conflict(*c, self->clock().now()),
      c->id == st.table.self() ? heard_at(self, ch, src, "conflict") : "");
  if (c->hop_limit > 1) {
    auto fwd = *c;
    fwd.hop_limit = static_cast<uint8_t>(c->hop_limit - 1);
    st.buf.clear();
    encode(fwd, st.buf);
    send_all(self, st.buf, ch);
  }
}

// -- authentication -------------------------------------------------------------

/// Challenges sender `index`, heard at `src` on channel `ch` with a right
/// tag but not known: a fresh nonce it must echo, signed. At most one per
/// index per challenge_interval (the authenticator's rate limit).
void send_challenge(agent_impl self, channel_id ch, link_addr src,
                    uint32_t index) {
  auto& st = self->state;
  challenge_request req;
  if (!st.auth->challenge(index, self->clock().now(), req.nonce))
    return;
  st.buf.clear();
  encode(req, st.buf);
  send_on(self, ch, src, st.buf);
  ++st.stats.tx_challenges;
}

/// Answers the challenge request in `pkt` (its body: `t.body_size` bytes)
/// from sender `t.index`, whatever that index and its counter (RFC 8967
/// 4.3: the requester may not know us, and we may not know it), at most
/// once per requesting index per challenge_interval. The reply is followed
/// by our hello to the requester: the requester knows our index once the
/// reply is in, so the hello makes us its neighbour at once instead of at
/// our next hello.
void answer_challenge(agent_impl self, const packet_received& pkt,
                      const auth_trailer& t) {
  auto& st = self->state;
  auto req = decode_challenge_request(pkt.bytes.data(), t.body_size);
  if (!req) {
    ++st.stats.rx_malformed;
    return;
  }
  if (!st.auth->may_reply(t.index, self->clock().now()))
    return;
  st.buf.clear();
  encode(challenge_reply{req->nonce}, st.buf);
  send_on(self, pkt.channel, pkt.src, st.buf);
  ++st.stats.tx_challenge_replies;
  if (st.leaving)
    return;
  make_hello(self, false);
  send_on(self, pkt.channel, pkt.src, st.buf);
  ++st.stats.tx_hellos;
}

/// A challenge reply from sender `t.index`, not known yet: known from now
/// on if it echoes the live nonce of our challenge to that index.
void on_challenge_reply(agent_impl self, const packet_received& pkt,
                        const auth_trailer& t) {
  auto& st = self->state;
  auto rep = decode_challenge_reply(pkt.bytes.data(), t.body_size);
  if (!rep) {
    ++st.stats.rx_malformed;
    return;
  }
  switch (st.auth->accept_reply(t, rep->nonce, self->clock().now())) {
    case auth_result::ok:
      break;
    case auth_result::table_full:
      ++st.stats.rx_auth_table_full;
      break;
    default:
      ++st.stats.rx_challenge_failed;
      break;
  }
}

/// In a keyed network: checks the trailer of a received packet and strips
/// it. False (and counted) when the packet must be dropped. Challenge
/// requests and replies are handled here, and never go further.
bool authenticate(agent_impl self, packet_received& pkt, packet_type type) {
  auto& st = self->state;
  auto ci = st.channels.find(pkt.channel);
  if (ci == st.channels.end())
    return false;
  auto& b = pkt.bytes;
  size_t min_body = 1;
  if (type == packet_type::data) {
    auto h = decode_data_header(b.data(), b.size());
    if (!h) {
      ++st.stats.rx_malformed;
      return false;
    }
    if (!h->authenticated) {
      auto off = header_size(*h);
      if (data_needs_auth(st.auth->config(), h->dst, h->protocol, b.data() + off,
                          b.size() - off)) {
        ++st.stats.rx_unsigned;
        return false;
      }
      return true;
    }
    min_body = header_size(*h);
  }
  auth_trailer t;
  auto res = st.auth->verify(b.data(), b.size(),
                             static_cast<uint8_t>(ci->second.code),
                             self->clock().now(), t, min_body);
  bool right_tag = res == auth_result::ok || res == auth_result::replayed
                   || res == auth_result::table_full
                   || res == auth_result::unknown_index;
  if (res == auth_result::unknown_index
      && type != packet_type::challenge_reply) {
    // Not acted on until its sender has shown that it is alive.
    ++st.stats.rx_auth_challenged;
    // Our challenge goes out before our answer to theirs (below): the
    // sender answers it before it hears our hello, so the full update it
    // sends on meeting us finds its index known here.
    send_challenge(self, pkt.channel, pkt.src, t.index);
  }
  // A challenge request with a right tag is answered before the index and
  // counter checks (RFC 8967 4.3): the requester may be new to us.
  if (right_tag && type == packet_type::challenge_request)
    answer_challenge(self, pkt, t);
  switch (res) {
    case auth_result::ok:
      break;
    case auth_result::unknown_index:
      if (type == packet_type::challenge_reply)
        on_challenge_reply(self, pkt, t);
      return false;
    case auth_result::replayed:
      ++st.stats.rx_replayed;
      return false;
    case auth_result::table_full:
      ++st.stats.rx_auth_table_full;
      return false;
    default:
      ++st.stats.rx_auth_failed;
      return false;
  }
  if (type == packet_type::challenge_request
      || type == packet_type::challenge_reply)
    return false; // answered above; a reply from a known index: nothing to do
  // Data packets keep their authenticated flag: it tells the receiver that
  // the packet was verified (packet_delivered::authenticated) and a
  // forwarder that it must sign it again (must_sign).
  b.resize(t.body_size);
  return true;
}

// -- timer ----------------------------------------------------------------------

/// Runs every quarter hello interval: liveness, expiry and addressing; every
/// fourth time also hellos, periodic updates and announcements.
void tick(agent_impl self) {
  auto& st = self->state;
  auto now = self->clock().now();
  bool hello_due = st.quarters++ % 4 == 0;
  if (hello_due && !st.leaving)
    send_hellos(self);
  // Neighbours silent for too long are gone.
  table_change change;
  for (auto i = st.neighbours.begin(); i != st.neighbours.end();) {
    auto interval = std::max(i->second.interval, st.cfg.hello_interval);
    auto limit = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      interval * st.cfg.hello_loss);
    if (now - i->second.last_hello > limit) {
      auto c = st.table.remove_neighbour(i->first);
      change.changed.insert(change.changed.end(), c.changed.begin(),
                            c.changed.end());
      i = st.neighbours.erase(i);
    } else {
      ++i;
    }
  }
  // Seqno requests older than an interval no longer hold back new ones.
  for (auto i = st.requested.begin(); i != st.requested.end();)
    i = now - i->second >= st.cfg.hello_interval ? st.requested.erase(i)
                                                 : std::next(i);
  auto expired = st.table.expire(now);
  change.changed.insert(change.changed.end(), expired.changed.begin(),
                        expired.changed.end());
  change.starving.insert(change.starving.end(), expired.starving.begin(),
                         expired.starving.end());
  std::sort(change.changed.begin(), change.changed.end());
  change.changed.erase(std::unique(change.changed.begin(), change.changed.end()),
                       change.changed.end());
  apply_change(self, change);
  if (auto due = st.alloc->next_deadline(); due && *due <= now)
    act(self, st.alloc->tick(now));
  self->delayed_send(self, st.cfg.hello_interval / 4, atom::tick_v);
  if (!hello_due)
    return;
  if (++st.ticks % st.cfg.update_every == 0)
    send_update(self, st.table.destinations());
  if (st.alloc->assigned() && st.ticks % st.cfg.announce_every == 0) {
    // An announcement is a claim whose nonce is the claimant's instance (a
    // fresh claim's nonce is random): receivers treat it as "this id is in
    // use by that instance" and apply the merge rule (a static id's holder
    // names itself holder: address_allocator.hpp).
    claim announce{st.alloc->id(), st.alloc->instance(), st.alloc->instance(),
                   default_hop_limit};
    st.buf.clear();
    encode(announce, st.buf);
    send_all(self, st.buf);
    ++st.stats.tx_claims;
  }
}

caf::error originate(agent_impl self, send_packet& msg) {
  auto& st = self->state;
  auto self_id = st.table.self();
  if (!st.alloc->assigned())
    return make_error(routing_ec::no_route, "module has no address yet (claiming)");
  data_header h;
  h.src = self_id;
  h.dst = msg.dst;
  h.size_class = size_class_of(msg.payload.size());
  h.priority = static_cast<uint8_t>(std::min<uint8_t>(msg.priority, 3));
  h.protocol = msg.protocol;
  if (msg.dst == broadcast_module) {
    h.flood_id = st.next_flood_id++;
    if (st.next_flood_id == 0)
      st.next_flood_id = 1;
    fresh_broadcast(self, self_id, h.flood_id);
  }
  byte_buffer bytes;
  bytes.reserve(header_size(h) + msg.payload.size());
  encode(h, bytes);
  bytes.insert(bytes.end(), msg.payload.begin(), msg.payload.end());
  ++st.stats.originated;
  if (msg.dst == self_id) {
    deliver(self, h, bytes);
    return caf::none;
  }
  if (msg.dst == broadcast_module) {
    ++st.stats.broadcasts_originated;
    if (st.cfg.observer)
      st.cfg.observer(self_id, h, bytes);
    relay_broadcast(self, h.priority, bytes, 0);
    return caf::none;
  }
  if (!is_unicast(msg.dst))
    return make_error(routing_ec::no_route, "cannot send to " + to_hex(msg.dst));
  auto nh = st.table.lookup(msg.dst, h.size_class);
  if (!nh) {
    ++st.stats.dropped_no_route;
    return make_error(routing_ec::no_route, "no route to module " + to_hex(msg.dst));
  }
  if (st.cfg.observer)
    st.cfg.observer(self_id, h, bytes);
  if (st.cfg.tracer) {
    auto t = make_trace(self, packet_trace::originated, h, bytes.size());
    trace_out(self, t, h, *nh);
  }
  auto sign = msg.sign || must_sign(self, h, bytes);
  transmit(self, *nh, h.priority, std::move(bytes), sign);
  return caf::none;
}

routing_agent_actor::behavior_type agent_fun(agent_impl self,
                                             io_manager_actor io,
                                             routing_config cfg) {
  auto& init = self->state;
  init.cfg = std::move(cfg);
  init.io = io;
  init.table = route_table{no_module, init.cfg.limits};
  uint64_t instance = init.cfg.instance;
  uint64_t seed = init.cfg.seed;
  if (instance == 0 || seed == 0) {
    std::random_device rd;
    if (instance == 0)
      instance = (uint64_t{rd()} << 32) | rd() | 1;
    if (seed == 0)
      seed = (uint64_t{rd()} << 32) | rd();
  }
  address_allocator::config acfg;
  acfg.static_id = init.cfg.id;
  acfg.claim_interval = init.cfg.hello_interval;
  init.alloc = std::make_unique<address_allocator>(acfg, instance, seed);
  if (init.cfg.auth.enabled()) {
    // A fresh sender index per start (RFC 8967's index): receivers keep
    // one counter per index, so a restarted module, whose counter starts
    // at 1 again, is a new sender rather than a replay.
    std::random_device rd;
    init.auth = std::make_unique<authenticator>(init.cfg.auth,
                                                static_cast<uint32_t>(rd()));
    // The key lives on in the authenticator only.
    std::fill(init.cfg.auth.key.begin(), init.cfg.auth.key.end(), 0);
    init.cfg.auth.key.clear();
  }
  init.stats.instance = instance;
  // Flood ids start at a random point so that a restarted module's first
  // broadcasts are not taken for duplicates of its previous life's.
  init.next_flood_id = static_cast<uint32_t>(seed >> 32) | 1;
  self->send(io, atom::subscribe_v, caf::actor_cast<io_listener_actor>(self));
  // Channels tell their subscribers when they end; the IO manager's
  // channel_down carries the same news, and that is what we act on.
  self->set_down_handler([self](caf::down_msg& msg) {
    auto& ls = self->state.route_listeners;
    ls.erase(std::remove_if(ls.begin(), ls.end(),
                            [&](const route_listener_actor& l) {
                              return l.address() == msg.source;
                            }),
             ls.end());
  });
  act(self, init.alloc->start(self->clock().now()));
  self->send(self, atom::tick_v);
  return {
    [self](send_packet& msg) { originate(self, msg); },
    [self](atom::send, send_packet& msg) -> caf::result<void> {
      if (auto err = originate(self, msg))
        return err;
      return caf::unit;
    },
    [self](atom::subscribe, uint8_t protocol, network_receiver_actor& rcv) {
      self->state.receivers[protocol] = std::move(rcv);
    },
    [self](atom::subscribe, atom::routes, route_listener_actor& l) {
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
    },
    [self](atom::get, atom::routes) -> std::vector<route_info> {
      auto& st = self->state;
      std::vector<route_info> result;
      for (auto& r : st.table.rows()) {
        route_info ri;
        ri.destination = r.destination;
        ri.size_class = r.size_class;
        ri.channel = r.via.channel;
        auto ci = st.channels.find(r.via.channel);
        ri.neighbour = ci != st.channels.end() ? std::to_string(r.via.neighbour)
                                               : "?";
        ri.cost = r.cost;
        ri.hops = r.hops;
        for (auto code : r.path) {
          if (!ri.forwarding.empty())
            ri.forwarding += '-';
          ri.forwarding += to_string(code);
        }
        ri.selected = r.selected;
        ri.feasible = r.feasible;
        result.push_back(std::move(ri));
      }
      return result;
    },
    [self](atom::get, atom::neighbors) -> std::vector<neighbour_info> {
      auto& st = self->state;
      auto now = self->clock().now();
      std::vector<neighbour_info> result;
      for (auto& [nh, n] : st.neighbours) {
        neighbour_info ni;
        ni.channel = nh.channel;
        ni.link_address = std::to_string(nh.neighbour);
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
    },
    [self](atom::get, atom::stats) -> routing_stats {
      auto& st = self->state;
      auto result = st.stats;
      result.reachable = static_cast<uint32_t>(st.table.reachable());
      result.destinations = static_cast<uint32_t>(st.table.size());
      result.routes = static_cast<uint32_t>(st.table.routes());
      result.neighbours = static_cast<uint32_t>(st.neighbours.size());
      result.sources_evicted = st.table.sources_evicted();
      if (auto other = st.alloc->live_holder(self->clock().now())) {
        result.id_conflict_instance = *other;
        result.id_conflict_heard = st.conflict_heard;
      }
      return result;
    },
    [self](channel_up& up) {
      auto& st = self->state;
      channel_state cs;
      cs.handle = up.handle;
      cs.info = up.info;
      cs.cost = link_metrics(up.info.profile);
      cs.code = link_code_of(up.info.profile.name);
      st.channels[up.info.id] = std::move(cs);
      self->request(up.handle, caf::infinite, atom::subscribe_v,
                    caf::actor_cast<channel_reader_actor>(self))
        .then([](channel_info&) {}, [](caf::error&) {});
      send_hellos(self);
    },
    [self](channel_down& down) {
      auto& st = self->state;
      st.channels.erase(down.id);
      for (auto i = st.neighbours.begin(); i != st.neighbours.end();)
        i = i->first.channel == down.id ? st.neighbours.erase(i) : std::next(i);
      apply_change(self, st.table.remove_channel(down.id));
    },
    [self](packet_received& pkt) {
      auto& st = self->state;
      auto type = peek_type(pkt.bytes.data(), pkt.bytes.size());
      if (!type) {
        ++st.stats.rx_malformed;
        return;
      }
      if (st.auth && !authenticate(self, pkt, *type))
        return;
      switch (*type) {
        case packet_type::data:
          on_data(self, pkt.channel, std::move(pkt.bytes));
          break;
        case packet_type::hello:
          on_hello(self, pkt.channel, pkt.src, pkt.bytes);
          break;
        case packet_type::update:
          on_update(self, pkt.channel, pkt.src, pkt.bytes);
          break;
        case packet_type::seqno_request:
          on_seqno_request(self, pkt.channel, pkt.bytes);
          break;
        case packet_type::claim:
          on_claim(self, pkt.channel, pkt.src, pkt.bytes);
          break;
        case packet_type::conflict:
          on_conflict(self, pkt.channel, pkt.src, pkt.bytes);
          break;
        case packet_type::challenge_request:
        case packet_type::challenge_reply:
          // Keyed: handled by authenticate. Without a key: authentication
          // traffic this module cannot check.
          ++st.stats.rx_auth_failed;
          break;
      }
    },
    [](link_event&) {
      // Hellos, not link events, decide who is a neighbour.
    },
    [self](atom::close) -> caf::result<void> {
      // Goodbyes first, then one round trip per channel: a channel handles
      // its mailbox in order, so when it answers, the goodbye is with its
      // driver.
      auto& st = self->state;
      send_hellos(self, true);
      st.leaving = true;
      auto rp = self->make_response_promise<void>();
      auto deliver = [](caf::typed_response_promise<void>& p) {
        static_cast<caf::response_promise&>(p).deliver(caf::unit);
      };
      if (st.channels.empty()) {
        deliver(rp);
        return rp;
      }
      auto left = std::make_shared<size_t>(st.channels.size());
      for (auto& kv : st.channels)
        self->request(kv.second.handle, std::chrono::seconds(1), atom::get_v,
                      atom::info_v)
          .then(
            [rp, left, deliver](channel_info&) mutable {
              if (--*left == 0)
                deliver(rp);
            },
            [rp, left, deliver](caf::error&) mutable {
              if (--*left == 0)
                deliver(rp);
            });
      return rp;
    },
    [self](atom::tick) { tick(self); },
    [self](atom::flush) { flush_changes(self); },
  };
}

} // namespace

routing_agent_actor spawn_routing_agent(caf::actor_system& sys,
                                        io_manager_actor io,
                                        routing_config cfg) {
  return sys.spawn(agent_fun, std::move(io), std::move(cfg));
}

} // namespace herm
