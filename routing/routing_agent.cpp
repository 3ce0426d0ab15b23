#include "routing/routing_agent.hpp"

// The routing agent: adapts messages and timers to the pure cores (route
// table, neighbour table, flood cache, seqno requests, address allocator,
// authenticator: agent_state.hpp) and sends what they decide. Queries and
// route events are answered in agent_reports.cpp, authentication in
// agent_auth.cpp, the fast path's snapshot kept in agent_fast_routes.cpp,
// the housekeeping tick in agent_tick.cpp.

#include <algorithm>
#include <limits>
#include <memory>
#include <random>
#include <type_traits>

#include "caf/actor_system.hpp"

#include "routing/agent_state.hpp"
#include "routing/error.hpp"

namespace herm {

namespace {

/// How long a neighbour heard only through its update (no hello yet) is
/// held for its first hello: a hello interval can be up to 65.5 s, but a
/// module sends its hello right after such an update or within its
/// interval.
constexpr std::chrono::milliseconds first_hello_wait{10'000};

} // namespace

namespace agent_detail {

// -- sending --------------------------------------------------------------------

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

void send_on(agent_impl self, channel_id ch, link_addr dst,
             const byte_buffer& bytes, uint8_t prio) {
  auto i = self->state.channels.find(ch);
  if (i != self->state.channels.end())
    self->send(i->second.handle,
               write_packet{dst, prio, outgoing(self, i->second, bytes, true)});
}

void send_all(agent_impl self, const byte_buffer& bytes, channel_id except,
              uint8_t prio) {
  for (auto& kv : self->state.channels)
    if (kv.first != except)
      self->send(kv.second.handle,
                 write_packet{broadcast_addr, prio,
                              outgoing(self, kv.second, bytes, true)});
}

const byte_buffer& make_hello(agent_impl self, bool leaving) {
  auto& st = self->state;
  auto interval = std::clamp<int64_t>(st.cfg.hello_interval.count(), 1, 0xFFFF);
  hello h{st.table.self(), st.alloc->instance(), st.hello_seqno++,
          static_cast<uint16_t>(leaving ? 0 : interval)};
  return encoded(self, h);
}

void report_neighbour(agent_impl self, const next_hop& nh, module_id id,
                      uint64_t instance, bool up, const char* reason) {
  auto& st = self->state;
  if (!st.cfg.on_neighbour)
    return;
  neighbour_event ev;
  ev.up = up;
  ev.id = id;
  ev.instance = instance;
  ev.channel = nh.channel;
  if (auto ci = st.channels.find(nh.channel); ci != st.channels.end()) {
    ev.device = ci->second.info.device;
    ev.link_kind = to_string(ci->second.code);
  }
  ev.link_address = link_address_text(self, nh);
  ev.reason = reason;
  st.cfg.on_neighbour(ev);
}

void send_hellos(agent_impl self, bool leaving) {
  auto& st = self->state;
  send_all(self, make_hello(self, leaving));
  st.stats.tx_hellos += st.channels.size();
}

void send_update(agent_impl self, const std::vector<module_id>& dests,
                 channel_id only) {
  auto& st = self->state;
  // After our goodbye, silence: an update would make us a neighbour again
  // where it arrives (meet).
  if (st.channels.empty() || st.leaving)
    return;
  update u;
  u.sender = st.table.self();
  u.instance = st.alloc->instance();
  auto flush = [&] {
    if (u.entries.empty())
      return;
    if (only != 0)
      send_on(self, only, broadcast_addr, encoded(self, u));
    else
      send_all(self, encoded(self, u));
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

namespace {

/// Floods a seqno request for each of `dests` that seqno_requests lets
/// through (one per destination per hello interval, a bounded number).
void send_seqno_requests(agent_impl self, const std::vector<module_id>& dests) {
  auto& st = self->state;
  auto now = self->clock().now();
  for (auto d : dests) {
    if (st.requested.request(d, now) != seqno_requests::decision::send)
      continue;
    auto adv = st.table.advertisement(d);
    seqno_request req{st.table.self(), d,
                      static_cast<seqno_t>((adv ? adv->seqno : 0) + 1),
                      max_route_hops};
    send_all(self, encoded(self, req));
    ++st.stats.tx_seqno_requests;
  }
}

/// True if this flood was not seen within its lifetime (half a hello
/// interval for control packets, flood_memory for broadcasts, whose type
/// is `data`); records it.
bool fresh_flood(agent_impl self, packet_type type, uint64_t a, uint64_t b) {
  auto& st = self->state;
  auto lifetime = type == packet_type::data
                    ? st.cfg.flood_memory
                    : st.cfg.hello_interval / 2;
  return st.floods.admit({static_cast<uint8_t>(type), a, b},
                         self->clock().now(), lifetime);
}

/// The channel a flood that came on `in` is not relayed on: `in` itself on
/// a medium where every station hears every frame (a CAN bus, an emulated
/// medium, an in-process segment), none on a UDP channel, whose
/// "broadcast" is one datagram to each configured peer: the other peers of
/// the module it came from did not hear it (the sender drops its own copy
/// as a duplicate).
channel_id relay_except(agent_impl self, channel_id in) {
  auto i = self->state.channels.find(in);
  if (i != self->state.channels.end() && i->second.info.kind == "udp")
    return std::numeric_limits<channel_id>::max();
  return in;
}

/// Relays a flooded control packet (claim, conflict) on every channel but
/// the one it came on (relay_except), one hop less, while it has hops left.
template <class T>
void relay_flood(agent_impl self, T fwd, channel_id in) {
  if (fwd.hop_limit <= 1)
    return;
  fwd.hop_limit = static_cast<uint8_t>(fwd.hop_limit - 1);
  send_all(self, encoded(self, fwd), relay_except(self, in));
}

} // namespace

// -- route changes --------------------------------------------------------------

void apply_change(agent_impl self, const table_change& change) {
  auto& st = self->state;
  // The snapshot follows at once: a packet must not leave on a next hop
  // the table gave up one mailbox turn ago.
  auto published = [&](module_id d) {
    return st.fast_dests.count(d) > 0 || st.fast_transit.count(d) > 0;
  };
  if ((!st.fast_dests.empty() || !st.fast_transit.empty())
      && std::any_of(change.changed.begin(), change.changed.end(), published))
    publish_fast_routes(self);
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

namespace {

/// Takes the contents of a pending set, leaving it empty.
std::vector<module_id> take(std::set<module_id>& pending) {
  std::vector<module_id> out(pending.begin(), pending.end());
  pending.clear();
  return out;
}

void flush_changes(agent_impl self) {
  auto& st = self->state;
  st.flush_scheduled = false;
  auto changed = take(st.pending_changed);
  auto starving = take(st.pending_starving);
  if (!st.pending_told.empty())
    tell_route_changes(self, take(st.pending_told));
  if (!changed.empty())
    send_update(self, changed);
  if (!starving.empty())
    send_seqno_requests(self, starving);
}

// -- addressing -----------------------------------------------------------------

/// "channel 1 (eth0) from 127.0.0.1:47001, hello": where a packet came from,
/// for id conflict reports; empty unless `about` is this module's id.
std::string heard_at(agent_impl self, module_id about, channel_id ch,
                     link_addr src, const char* what) {
  auto& st = self->state;
  if (about != st.table.self())
    return "";
  auto ci = st.channels.find(ch);
  return "channel " + std::to_string(ch) + " ("
         + (ci != st.channels.end() ? ci->second.info.device : "?")
         + ") from " + link_address_text(self, next_hop{ch, src}) + ", " + what;
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

} // namespace

void act(agent_impl self, address_allocator::actions acts,
         const std::string& where) {
  auto& st = self->state;
  if (acts.disputed)
    on_dispute(self, *acts.disputed, where);
  for (auto& c : acts.claims) {
    send_all(self, encoded(self, c));
    ++st.stats.tx_claims;
  }
  for (auto& c : acts.conflicts) {
    send_all(self, encoded(self, c));
    ++st.stats.tx_conflicts;
  }
  if (acts.renumbered_from) {
    // Withdraw the old id: advertise it unreachable with a newer seqno.
    advertised gone;
    gone.origin = *acts.renumbered_from;
    gone.seqno = static_cast<seqno_t>(st.table.own_seqno() + 1);
    send_all(self, encoded(self, update{st.table.self(), st.alloc->instance(),
                                        {gone}}));
    ++st.stats.renumberings;
    st.stats.self = no_module;
    st.stats.assigned = false;
    publish_fast_routes(self);
  }
  if (acts.assigned) {
    st.table.set_self(st.alloc->id());
    st.table.bump_own_seqno();
    st.stats.self = st.alloc->id();
    st.stats.assigned = st.alloc->assigned();
    send_update(self, {st.table.self()});
    publish_fast_routes(self);
  }
}

namespace {

// -- data packets ---------------------------------------------------------------

/// Hands a data packet for this module (header `h`, `packet` the whole
/// packet) to the receiver of its protocol; the payload is moved out of
/// `packet` (no copy) when it is an rvalue.
template <class Packet>
void deliver(agent_impl self, const data_header& h, Packet&& packet) {
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
  packet_delivered msg{h.src, h.protocol, h.priority, hops, {},
                       h.authenticated};
  auto body = packet.begin() + static_cast<ptrdiff_t>(header_size(h));
  if constexpr (std::is_rvalue_reference_v<Packet&&>) {
    packet.erase(packet.begin(), body);
    msg.payload = std::move(packet);
  } else {
    msg.payload.assign(body, packet.end());
  }
  self->send(i->second, std::move(msg));
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

/// Traces (when a tracer is set) and puts an encoded unicast data packet
/// on the channel and neighbour of `nh`, signed when `sign` (or when it
/// must be). `what` is originated or forwarded; `in` the channel it came on.
void transmit(agent_impl self, packet_trace::what_t what, const data_header& h,
              const next_hop& nh, byte_buffer bytes, bool sign,
              channel_id in = 0) {
  auto& st = self->state;
  if (st.cfg.tracer) {
    auto t = make_trace(self, what, h, bytes.size(), in);
    trace_out(self, t, h, nh);
  }
  sign = sign || must_sign(self, h, bytes);
  auto i = st.channels.find(nh.channel);
  if (i == st.channels.end())
    return;
  if (sign)
    bytes = outgoing(self, i->second, bytes, true);
  self->send(i->second.handle,
             write_packet{nh.neighbour, h.priority, std::move(bytes)});
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
  transmit(self, packet_trace::forwarded, h, *nh, std::move(bytes), false, in);
  // The next packets for it take the fast path (fast_receiver).
  note_fast_destination(self, h.dst, true);
}

void on_data(agent_impl self, channel_id ch, byte_buffer bytes) {
  auto& st = self->state;
  auto h = decode_data_header(bytes.data(), bytes.size());
  if (!decoded(self, h))
    return;
  if (h->authenticated && !st.auth) {
    // Signed by a keyed network, and this module has no key (a keyed one
    // has checked and removed the trailer): where the payload ends is
    // unknown, so nothing of it can be delivered.
    ++st.stats.rx_auth_failed;
    return;
  }
  if (h->dst == broadcast_module) {
    if (h->flood_id != 0) {
      if (h->src == st.table.self()
          || !fresh_flood(self, packet_type::data, h->src, h->flood_id)) {
        ++st.stats.dropped_duplicate;
        return;
      }
      if (st.cfg.observer)
        st.cfg.observer(st.table.self(), *h, bytes);
      deliver(self, *h, bytes);
      if (h->hop_limit > 1) {
        set_hop_limit(bytes.data(), static_cast<uint8_t>(h->hop_limit - 1));
        ++st.stats.broadcasts_relayed;
        send_all(self, bytes, relay_except(self, ch), h->priority);
      }
      return;
    }
    // Link-local broadcast: for the neighbours that hear it only.
    deliver(self, *h, std::move(bytes));
    return;
  }
  if (st.cfg.observer)
    st.cfg.observer(st.table.self(), *h, bytes);
  if (h->dst == st.table.self()) {
    if (st.cfg.tracer)
      st.cfg.tracer(make_trace(self, packet_trace::delivered, *h, bytes.size(), ch));
    deliver(self, *h, std::move(bytes));
  } else {
    forward(self, *h, std::move(bytes), ch);
  }
}

// -- control packets ------------------------------------------------------------

/// Takes `nh` as a neighbour that says it is `id`, instance `instance`,
/// with hellos every `interval` (from a hello, or from an update heard
/// before any hello: `how`). A new or restarted neighbour gets its direct
/// route and our whole table at once. False when the neighbour table
/// refuses it (a bound, counted there).
bool meet(agent_impl self, const next_hop& nh, module_id id,
          uint64_t instance, std::chrono::milliseconds interval,
          const char* how) {
  auto& st = self->state;
  auto ci = st.channels.find(nh.channel);
  if (ci == st.channels.end())
    return false;
  using result = neighbour_table::hello_result;
  auto res = st.neighbours.heard(nh, id, instance, interval,
                                 self->clock().now());
  if (res == result::refused)
    return false;
  if (res == result::added || res == result::restarted) {
    report_neighbour(self, nh, id, instance, true,
                     res == result::added ? how : "restarted");
    apply_change(self, st.table.set_neighbour(nh, ci->second.cost,
                                              ci->second.code));
    // Tell the new neighbour everything we know at once.
    send_update(self, st.table.destinations(), nh.channel);
  }
  return true;
}

void on_hello(agent_impl self, channel_id ch, link_addr src,
              const byte_buffer& bytes) {
  auto& st = self->state;
  auto h = decode_hello(bytes.data(), bytes.size());
  if (!decoded(self, h))
    return;
  auto now = self->clock().now();
  next_hop nh{ch, src};
  if (h->interval_ms == 0) {
    // A goodbye: the neighbour leaves now; its routes go at once.
    if (st.neighbours.goodbye(nh, h->instance)) {
      report_neighbour(self, nh, h->sender, h->instance, false, "goodbye");
      ++st.stats.rx_goodbyes;
      apply_change(self, st.table.remove_neighbour(nh));
    }
    return;
  }
  if (!meet(self, nh, h->sender, h->instance,
            std::chrono::milliseconds(h->interval_ms), "hello"))
    return;
  if (is_unicast(h->sender))
    act(self, st.alloc->on_heard(h->sender, h->instance, now),
        heard_at(self, h->sender, ch, src, "hello"));
}

void on_update(agent_impl self, channel_id ch, link_addr src,
               const byte_buffer& bytes) {
  auto& st = self->state;
  auto u = decode_update(bytes.data(), bytes.size());
  if (!decoded(self, u))
    return;
  next_hop nh{ch, src};
  auto* from = st.neighbours.find(nh);
  if (!from) {
    // An update is as good a sign of the link as a hello: the sender heard
    // our hello first and told us everything at once. Dropping it would
    // leave us without a route back until its next hello (a hello
    // interval), while it already routes to us. Its interval is unknown
    // until that hello, and may be longer than ours: it is held for
    // first_hello_wait meanwhile (with ours, a neighbour with slower
    // hellos would be lost before its first one, and every binding
    // through it with it). An update that was overtaken by its sender's
    // goodbye (another priority lane) does not bring it back.
    if (st.neighbours.departed(nh, u->instance)
        || !meet(self, nh, u->sender, u->instance,
                 std::max(st.cfg.hello_interval, first_hello_wait),
                 "update")) {
      ++st.stats.rx_unknown_neighbour;
      return;
    }
    from = st.neighbours.find(nh);
  }
  auto hold = st.hold(from->interval);
  auto now = self->clock().now();
  if (is_unicast(u->sender))
    act(self, st.alloc->on_heard(u->sender, u->instance, now),
        heard_at(self, u->sender, ch, src, "update"));
  table_change change;
  for (auto& e : u->entries) {
    // Neighbours echo our own routes back to us: not an error.
    if (e.origin == st.table.self())
      continue;
    switch (st.table.update(nh, e, now, hold, change)) {
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
  if (!decoded(self, r)
      || !fresh_flood(self, packet_type::seqno_request, r->origin, r->seqno))
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
  send_on(self, nh->channel, nh->neighbour, encoded(self, fwd));
}

void on_claim(agent_impl self, channel_id ch, link_addr src,
              const byte_buffer& bytes) {
  auto& st = self->state;
  auto c = decode_claim(bytes.data(), bytes.size());
  if (!decoded(self, c) || c->instance == st.alloc->instance()
      || !fresh_flood(self, packet_type::claim, c->id, c->nonce))
    return;
  auto now = self->clock().now();
  if (c->nonce == c->instance)
    act(self, st.alloc->on_heard(c->id, c->instance, now, false),
        heard_at(self, c->id, ch, src, "announcement"));
  else
    act(self, st.alloc->on_claim(*c, now));
  relay_flood(self, *c, ch);
}

void on_conflict(agent_impl self, channel_id ch, link_addr src,
                 const byte_buffer& bytes) {
  auto& st = self->state;
  auto c = decode_conflict(bytes.data(), bytes.size());
  if (!decoded(self, c)
      || !fresh_flood(self, packet_type::conflict,
                      c->id ^ (c->claim_nonce << 16),
                      c->holder_instance ^ c->loser_instance))
    return;
  act(self, st.alloc->on_conflict(*c, self->clock().now()),
      heard_at(self, c->id, ch, src, "conflict"));
  relay_flood(self, *c, ch);
}

void on_packet(agent_impl self, packet_received& pkt) {
  auto& st = self->state;
  auto type = peek_type(pkt.bytes.data(), pkt.bytes.size());
  if (!decoded(self, type) || (st.auth && !authenticate(self, pkt, *type)))
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
}

// -- requests from above --------------------------------------------------------

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
    fresh_flood(self, packet_type::data, self_id, h.flood_id);
  }
  byte_buffer bytes;
  bytes.reserve(header_size(h) + msg.payload.size());
  encode(h, bytes);
  bytes.insert(bytes.end(), msg.payload.begin(), msg.payload.end());
  ++st.stats.originated;
  if (msg.dst == self_id) {
    deliver(self, h, std::move(bytes));
    return caf::none;
  }
  if (msg.dst == broadcast_module) {
    ++st.stats.broadcasts_originated;
    if (st.cfg.observer)
      st.cfg.observer(self_id, h, bytes);
    send_all(self, bytes, 0, h.priority);
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
  transmit(self, packet_trace::originated, h, *nh, std::move(bytes), msg.sign);
  note_fast_destination(self, msg.dst);
  return caf::none;
}

/// Leaves the network: goodbyes first, then one round trip per channel: a
/// channel handles its mailbox in order, so when it answers, the goodbye
/// is with its driver.
caf::result<void> leave(agent_impl self) {
  auto& st = self->state;
  send_hellos(self, true);
  st.leaving = true;
  publish_fast_routes(self);
  auto rp = self->make_response_promise<void>();
  auto deliver = [](caf::typed_response_promise<void>& p) {
    static_cast<caf::response_promise&>(p).deliver(caf::unit);
  };
  if (st.channels.empty()) {
    deliver(rp);
    return rp;
  }
  auto left = std::make_shared<size_t>(st.channels.size());
  auto one_done = [rp, left, deliver]() mutable {
    if (--*left == 0)
      deliver(rp);
  };
  for (auto& kv : st.channels)
    self->request(kv.second.handle, std::chrono::seconds(1), atom::get_v,
                  atom::info_v)
      .then([one_done](channel_info&) mutable { one_done(); },
            [one_done](caf::error&) mutable { one_done(); });
  return rp;
}

// -- set-up ---------------------------------------------------------------------

void init(agent_impl self, io_manager_actor io, routing_config cfg) {
  auto& st = self->state;
  st.cfg = std::move(cfg);
  st.io = io;
  st.table = route_table{no_module, st.cfg.limits};
  st.neighbours = neighbour_table{{st.cfg.max_neighbours,
                                   st.cfg.max_neighbours_per_channel,
                                   st.cfg.hello_interval, st.cfg.hello_loss}};
  st.floods = flood_cache{st.cfg.max_floods};
  st.requested = seqno_requests{{st.cfg.hello_interval,
                                 st.cfg.max_seqno_requests}};
  uint64_t instance = st.cfg.instance;
  uint64_t seed = st.cfg.seed;
  if (instance == 0 || seed == 0) {
    std::random_device rd;
    if (instance == 0)
      instance = (uint64_t{rd()} << 32) | rd() | 1;
    if (seed == 0)
      seed = (uint64_t{rd()} << 32) | rd();
  }
  address_allocator::config acfg;
  acfg.static_id = st.cfg.id;
  acfg.claim_interval = st.cfg.hello_interval;
  st.alloc = std::make_unique<address_allocator>(acfg, instance, seed);
  if (st.cfg.auth.enabled()) {
    // A fresh sender index per start (RFC 8967's index): receivers keep
    // one counter per index, so a restarted module, whose counter starts
    // at 1 again, is a new sender rather than a replay.
    std::random_device rd;
    st.auth = std::make_unique<authenticator>(st.cfg.auth,
                                              static_cast<uint32_t>(rd()));
    // The key lives on in the authenticator only.
    std::fill(st.cfg.auth.key.begin(), st.cfg.auth.key.end(), 0);
    st.cfg.auth.key.clear();
  }
  st.stats.instance = instance;
  // Flood ids start at a random point so that a restarted module's first
  // broadcasts are not taken for duplicates of its previous life's.
  st.next_flood_id = static_cast<uint32_t>(seed >> 32) | 1;
}

routing_agent_actor::behavior_type agent_fun(agent_impl self,
                                             io_manager_actor io,
                                             routing_config cfg) {
  init(self, io, std::move(cfg));
  // Nobody may send on a route of an agent that ended.
  if (auto cell = self->state.cfg.fast_routes)
    self->attach_functor([cell] { cell->publish(nullptr); });
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
  act(self, self->state.alloc->start(self->clock().now()));
  self->send(self, atom::tick_v, ++self->state.tick_generation);
  return {
    [self](send_packet& msg) { originate(self, msg); },
    [self](atom::send, send_packet& msg) -> caf::result<void> {
      if (auto err = originate(self, msg))
        return err;
      return caf::unit;
    },
    [self](atom::subscribe, uint8_t protocol, network_receiver_actor& rcv) {
      self->state.receivers[protocol] = std::move(rcv);
      publish_fast_routes(self);
    },
    [self](atom::subscribe, atom::routes, route_listener_actor& l) {
      subscribe_routes(self, l);
    },
    [self](atom::get, atom::routes) { return route_rows(self); },
    [self](atom::get, atom::neighbors) { return neighbour_rows(self); },
    [self](atom::get, atom::stats) { return stats_now(self); },
    [self](channel_up& up) {
      channel_state cs;
      cs.handle = up.handle;
      cs.info = up.info;
      cs.cost = link_metrics(up.info.profile);
      cs.code = link_code_of(up.info.profile.name);
      self->state.channels[up.info.id] = std::move(cs);
      self->request(up.handle, caf::infinite, atom::subscribe_v,
                    caf::actor_cast<channel_reader_actor>(self))
        .then([](channel_info&) {}, [](caf::error&) {});
      send_hellos(self);
    },
    [self](channel_down& down) {
      auto& st = self->state;
      if (st.cfg.on_neighbour) {
        auto& all = st.neighbours.entries();
        for (auto i = all.lower_bound(next_hop{down.id, 0});
             i != all.end() && i->first.channel == down.id; ++i)
          report_neighbour(self, i->first, i->second.id, i->second.instance,
                           false, "channel closed");
      }
      st.channels.erase(down.id);
      auto names = st.peer_names.lower_bound(next_hop{down.id, 0});
      while (names != st.peer_names.end() && names->first.channel == down.id)
        names = st.peer_names.erase(names);
      st.neighbours.remove_channel(down.id);
      apply_change(self, st.table.remove_channel(down.id));
    },
    [self](packet_received& pkt) { on_packet(self, pkt); },
    [self](link_event& ev) {
      // Hellos, not link events, decide who is a neighbour; a peer heard
      // for the first time tells how its link address is written.
      auto& st = self->state;
      if (ev.kind == static_cast<uint8_t>(link_event_kind::peer_heard)
          && !ev.detail.empty() && st.channels.count(ev.channel) > 0
          && st.peer_names.size() < st.max_peer_names())
        st.peer_names[next_hop{ev.channel, ev.peer}] = ev.detail;
    },
    [self](atom::close) { return leave(self); },
    [self](atom::tick, uint64_t generation) {
      if (generation == self->state.tick_generation)
        tick(self);
    },
    [self](atom::flush) { flush_changes(self); },
  };
}

} // namespace

} // namespace agent_detail

routing_agent_actor spawn_routing_agent(caf::actor_system& sys,
                                        io_manager_actor io,
                                        routing_config cfg) {
  return sys.spawn(agent_detail::agent_fun, std::move(io), std::move(cfg));
}

} // namespace herm
