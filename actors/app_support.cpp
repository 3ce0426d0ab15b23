#include "actors/app_support.hpp"

// The Application Support Layer's actor: adapts messages and timers to the
// pure cores (APO registry, bindings, outgoing requests, reliable mode,
// request server, discoveries, topics, reachability: asl_state.hpp) and
// sends what they decide. Local publications are in asl_topics.cpp,
// bindings and discoveries in asl_bindings.cpp.

#include <algorithm>
#include <random>
#include <variant>

#include "caf/actor_system.hpp"
#include "caf/mailbox_element.hpp"

#include "actors/asl_errors.hpp"
#include "actors/asl_state.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/loop_scheduler.hpp"
#include "actors/runtime/type_ids.hpp"
#include "actors/unexpected.hpp"
#include "channels/lax_timer.hpp"
#include "channels/thread_cache.hpp"

namespace herm {

namespace asl_detail {

namespace {

// -- small helpers -----------------------------------------------------------------

template <class T, class = void>
constexpr bool has_payload = false;

template <class T>
constexpr bool has_payload<T, std::void_t<decltype(std::declval<T&>().payload)>>
  = true;

/// Puts the encoded message `body` for `dst` straight on the next hop's
/// channel when the routing agent published one (routing/fast_routes.hpp):
/// header and body in one buffer from the thread's cache. False: it must
/// go through the agent.
bool send_fast(asl_impl self, module_id dst, const byte_buffer& body,
               bool sign) {
  auto& cell = self->state.cfg.fast_routes;
  if (!cell || sign || !is_unicast(dst))
    return false;
  auto snap = cell->get();
  if (!snap || dst == snap->self)
    return false;
  data_header h;
  h.src = snap->self;
  h.dst = dst;
  h.priority = prio_normal;
  h.protocol = asl_protocol;
  h.size_class = size_class_of(body.size());
  auto* hop = snap->lookup(dst, h.size_class);
  if (hop == nullptr || !hop->channel)
    return false;
  // Given back by the channel once written.
  auto bytes = take_buffer(header_size(h) + body.size());
  encode(h, bytes);
  bytes.insert(bytes.end(), body.begin(), body.end());
  cell->count_sent();
  hop->channel->enqueue(make_pooled_element(self->ctrl(), caf::make_message_id(),
                                            write_packet{hop->neighbour,
                                                         h.priority,
                                                         std::move(bytes)}),
                        self->context());
  return true;
}

/// Whether anything waits on the housekeeping tick's fine granularity:
/// a request's deadline or retransmission, a request being served.
bool needs_fast_tick(const asl_state& st) {
  return st.pending->size() > 0 || st.server->serving() > 0;
}

/// The next housekeeping tick, `period` from now; any tick already on its
/// way is superseded (its generation no longer counts).
void schedule_tick(asl_impl self, std::chrono::milliseconds period) {
  auto& st = self->state;
  st.tick_fast = period <= st.cfg.tick;
  // Lax: on a busy loop the tick rides on a wake the traffic makes. Nothing
  // fine-grained waits on the slow tick (needs_fast_tick), so it may come
  // up to half its period late, at most 250 ms (what subscription renewals
  // and unreachable_grace can spare): on an idle module it then runs on a
  // wake the routing agent's tick or a neighbour's hello makes instead of
  // waking the loop itself.
  auto slack = st.tick_fast
                 ? lax_slack(period)
                 : std::min(caf::timespan{period} / 2,
                            caf::timespan{std::chrono::milliseconds{250}});
  auto t = self->clock().now() + period;
  // The latest time it comes: what slow_tick_too_late must assume.
  st.tick_at = t + slack;
  send_lax_at(self, t, slack, atom::tick_v, ++st.tick_generation);
}

/// Whether the slow tick comes too late for what sending `msg` starts.
/// A plain request needs the fine tick only from one tick before its
/// deadline; the slow tick usually comes sooner and brings the fine one
/// itself if the request still waits. Bringing it forward for every
/// request would leave a superseded slow tick behind each time, which
/// wakes the loop for nothing. Anything else (a reliable request's next
/// copy after its RTO, an ack, a response) brings it forward.
bool slow_tick_too_late(asl_impl self, const asl_message& msg) {
  auto& st = self->state;
  if (!std::holds_alternative<asl_request>(msg))
    return true;
  return st.tick_at + st.cfg.tick
         > self->clock().now() + st.cfg.request_timeout;
}

/// Encodes `msg` once, into the scratch buffer, and sends it by the
/// published next hop or through the agent.
void send_now(asl_impl self, module_id dst, const asl_message& msg,
              bool sign) {
  auto& st = self->state;
  if (!st.tick_fast && needs_fast_tick(st) && slow_tick_too_late(self, msg))
    schedule_tick(self, st.cfg.tick);
  st.buf.clear();
  encode(msg, st.buf);
  if (send_fast(self, dst, st.buf, sign))
    return;
  self->send(st.agent,
             send_packet{dst, asl_protocol, prio_normal, st.buf, sign});
}

/// Gives the payload buffer of `msg`, if its kind has one, back to the
/// thread's cache (channels/thread_cache.hpp): `msg` was encoded or
/// decoded, and the next payload marshalled or received can use it.
void recycle_payload(asl_message& msg) {
  std::visit(
    [](auto& x) {
      if constexpr (has_payload<std::decay_t<decltype(x)>>)
        recycle_buffer(std::move(x.payload));
    },
    msg);
}

} // namespace

void flush(asl_impl self) {
  auto& st = self->state;
  // Swapped with a vector kept for the purpose, so that neither allocates
  // once both have grown.
  st.flushing.swap(st.out.items);
  for (auto& x : st.flushing) {
    send_now(self, x.dst, x.msg, x.sign);
    recycle_payload(x.msg);
  }
  st.flushing.clear();
}

namespace {

/// Sends an ASL message over the network (after what the outbox holds);
/// with `sign`, signed in a keyed network whatever its `auth.data`
/// (apo_access::signed_only traffic).
void transmit(asl_impl self, module_id dst, asl_message msg,
              bool sign = false) {
  flush(self);
  send_now(self, dst, msg, sign);
  recycle_payload(msg);
}

} // namespace

caf::error agent_gone(asl_impl self) {
  auto& st = self->state;
  if (!st.agent_down)
    return caf::none;
  return asl_error::agent_stopped(st.self_id, st.agent_down);
}


void post(asl_impl self, const caf::strong_actor_ptr& dst,
          caf::strong_actor_ptr from, caf::message_id mid, caf::message msg) {
  if (!dst)
    return;
  if (mid.is_response())
    request_answered(self->system(), dst->get(), mid);
  dst->enqueue(make_pooled_message_element(std::move(from), mid, std::move(msg)),
               self->context());
}

void fail(asl_impl self, const outgoing& out, const caf::error& err) {
  post(self, out.sender, nullptr, out.mid.response_id(),
       caf::make_message(err));
}

namespace {

/// Answers a request with an error (one-way messages have nobody to tell).
void refuse(asl_impl self, const caf::strong_actor_ptr& sender,
            caf::message_id mid, caf::error err) {
  if (mid.is_request())
    post(self, sender, nullptr, mid.response_id(),
         caf::make_message(std::move(err)));
}

bool reachable(asl_impl self, module_id m) {
  return m == self->state.self_id || self->state.reach.reachable(m);
}

} // namespace

caf::expected<caf::message> unmarshal_counted(asl_impl self,
                                              const byte_buffer& payload) {
  auto& st = self->state;
  auto msg = unmarshal(self->system(), payload.data(), payload.size(),
                       st.cfg.limits);
  if (!msg) {
    if (is(msg.error(), app_ec::unknown_type))
      ++st.stats.rx_unknown_type;
    else
      ++st.stats.rx_malformed;
  }
  return msg;
}

namespace {

/// `msg` as a local APO takes it: a raw_payload (sent through a proxy
/// whose target turned out local) unmarshalled here; the APO answers with
/// its own types.
caf::expected<caf::message> for_local_apo(asl_impl self, caf::message msg) {
  if (!msg.match_elements<raw_payload>())
    return msg;
  return unmarshal_counted(self, msg.get_as<raw_payload>(0).bytes);
}

// -- requests: the sender ------------------------------------------------------------

/// Sends reliable request `rid` (again) if its binding has a reachable
/// target, and sets when to look at it next. Returns true when it was
/// handed to a local APO instead (a rebinding proxy's new target is here):
/// the caller forgets it.
bool send_reliable(asl_impl self, uint64_t rid, outgoing& out, time_point now) {
  auto& st = self->state;
  auto b = st.bindings.find(out.binding);
  if (b == nullptr || !b->bound) {
    st.reliable->wait(out.tx, now); // parked: waits for a target
    return false;
  }
  auto& target = b->target;
  if (target.module == st.self_id) {
    auto a = st.apos->find(target.apo);
    if (a == nullptr) {
      st.reliable->defer(out.tx, now);
      return false;
    }
    if (auto msg = for_local_apo(self, std::move(out.msg)))
      post(self, caf::actor_cast<caf::strong_actor_ptr>(*a),
           std::move(out.sender), out.mid, std::move(*msg));
    else
      refuse(self, out.sender, out.mid, std::move(msg.error()));
    return true;
  }
  if (!reachable(self, target.module))
    st.reliable->wait(out.tx, now);
  else if (st.reliable->send(out.tx, target.module, now))
    transmit(self, target.module,
             asl_reliable_request{rid, target.apo, out.oneway, out.payload},
             b->sign);
  return false;
}

/// Sends every reliable request whose time has come, and those of the
/// bindings in `forced` (a binding just bound, or bound to a module that
/// just became reachable: then only those not acked).
void send_due(asl_impl self, const std::vector<uint32_t>& forced = {},
              bool unacked_only = false) {
  auto& st = self->state;
  auto now = self->clock().now();
  for (auto rid : st.pending->due(now, forced, unacked_only))
    if (send_reliable(self, rid, *st.pending->find(rid), now))
      st.pending->erase(rid);
}

/// Sends `msg` through binding `id` to its remote target (or, reliable,
/// parks it until there is one): marshals it, refuses it if it cannot go
/// (counted), and waits for its response unless it is a plain one-way
/// message.
void send_remote(asl_impl self, uint32_t id, binding& b,
                 caf::strong_actor_ptr& sender, caf::message_id mid,
                 caf::message& msg) {
  auto& st = self->state;
  // A raw_payload request goes as it is (marshalled elsewhere).
  bool raw = msg.match_elements<raw_payload>();
  auto payload = [&]() -> caf::expected<byte_buffer> {
    if (!raw)
      return marshal(self->system(), msg);
    auto& bytes = msg.get_as<raw_payload>(0).bytes;
    if (auto bad = check_raw(bytes))
      return bad;
    return bytes;
  }();
  caf::error err;
  if (!payload)
    err = std::move(payload.error());
  else if (payload->size() > st.cfg.max_message)
    err = asl_error::too_large(payload->size(), st.cfg.max_message);
  else if ((b.reliable || mid.is_request()) && st.pending->full())
    err = asl_error::outstanding(st.pending->size());
  if (err) {
    ++st.stats.tx_refused;
    refuse(self, sender, mid, std::move(err));
    return;
  }
  bool oneway = !mid.is_request();
  ++(oneway ? st.stats.oneway_sent : st.stats.requests_sent);
  if (!b.reliable && oneway) {
    transmit(self, b.target.module,
             asl_request{0, b.target.apo, std::move(*payload)}, b.sign);
    return;
  }
  auto now = self->clock().now();
  outgoing out;
  out.sender = std::move(sender);
  out.mid = mid;
  out.binding = id;
  out.raw = raw;
  out.deadline = now + st.cfg.request_timeout;
  if (!b.reliable) {
    out.tx.dst = b.target.module;
    auto rid = st.pending->add(std::move(out)).first;
    transmit(self, b.target.module,
             asl_request{rid, b.target.apo, std::move(*payload)}, b.sign);
    return;
  }
  out.reliable = true;
  out.oneway = oneway;
  out.msg = std::move(msg);
  out.payload = std::move(*payload);
  ++st.stats.reliable_sent;
  auto [rid, added] = st.pending->add(std::move(out));
  if (send_reliable(self, rid, added, now))
    st.pending->erase(rid);
}

void on_forward(asl_impl self, uint32_t id, caf::strong_actor_ptr& sender,
                caf::message_id mid, caf::message& msg) {
  auto& st = self->state;
  auto b = st.bindings.find(id);
  if (b == nullptr) {
    refuse(self, sender, mid, asl_error::apo_gone("binding ended"));
  } else if (auto err = agent_gone(self)) {
    refuse(self, sender, mid, std::move(err));
  } else if (b->reliable
             && (b->bound ? b->target.module != st.self_id : b->rebind)) {
    send_remote(self, id, *b, sender, mid, msg);
  } else if (!b->bound) {
    refuse(self, sender, mid,
           asl_error::apo_gone("no APO named '" + b->pattern
                          + "' is bound yet (looking for one)"));
  } else if (b->target.module == st.self_id) {
    // A rebinding proxy whose match is here: hand it over unchanged.
    auto a = st.apos->find(b->target.apo);
    auto local = for_local_apo(self, std::move(msg));
    if (a == nullptr)
      refuse(self, sender, mid, asl_error::apo_gone(describe(b->target)));
    else if (!local)
      refuse(self, sender, mid, std::move(local.error()));
    else
      post(self, caf::actor_cast<caf::strong_actor_ptr>(*a),
           std::move(sender), mid, std::move(*local));
  } else if (!reachable(self, b->target.module)) {
    ++st.stats.dropped_no_route;
    refuse(self, sender, mid, asl_error::no_route_to(b->target.module));
  } else {
    send_remote(self, id, *b, sender, mid, msg);
  }
}

void on_response(asl_impl self, module_id src, asl_response& r) {
  auto& st = self->state;
  auto step = st.pending->on_response(src, r, self->clock().now(), st.bindings);
  if (step.kind == outgoing_requests::response_step::rebind)
    lose_target(self, step.binding, step.error, step.error);
  if (step.kind != outgoing_requests::response_step::reply)
    return;
  auto& out = step.out;
  caf::strong_actor_ptr from;
  if (auto b = st.bindings.find(out.binding))
    from = b->proxy.lock();
  auto reply = [&](caf::message x) {
    post(self, out.sender, from, out.mid.response_id(), std::move(x));
  };
  if (!r.ok) {
    auto err = from_wire(r.error);
    reply(caf::make_message(err));
    if (is(err, app_ec::apo_gone))
      lose_target(self, out.binding, err, err);
  } else if (out.raw) {
    reply(caf::make_message(raw_payload{std::move(r.payload)}));
  } else if (auto msg = unmarshal_counted(self, r.payload)) {
    reply(std::move(*msg));
  } else {
    reply(caf::make_message(msg.error()));
  }
}

// -- requests: the receiver ----------------------------------------------------------

/// A request (`rid` 0: a plain one-way message) for local APO `apo` from
/// module `src`, plain or reliable.
void on_request(asl_impl self, module_id src, uint64_t rid, uint32_t apo,
                bool oneway, const byte_buffer& payload, bool authenticated,
                bool reliable) {
  auto& st = self->state;
  auto& server = *st.server;
  if (server.admit(src, rid, apo, reliable, authenticated, st.self_id,
                   st.out)) {
    if (auto msg = unmarshal_counted(self, payload); !msg) {
      server.malformed(src, rid, apo, msg.error(), st.self_id, st.out);
    } else if (auto local = server.accept(src, rid, apo, oneway, reliable,
                                          self->clock().now(), st.self_id,
                                          st.out)) {
      auto dst = caf::actor_cast<caf::strong_actor_ptr>(*st.apos->find(apo));
      post(self, dst, *local != 0 ? st.sink : nullptr,
           caf::make_message_id(*local), std::move(*msg));
    }
  }
  flush(self);
}

/// The local APO answered request `local` of a remote requester.
void on_reply(asl_impl self, uint64_t local, caf::message& msg) {
  auto& st = self->state;
  std::variant<byte_buffer, caf::error> answer;
  if (msg.match_elements<caf::error>())
    answer = asl_error::from_apo(msg.get_as<caf::error>(0));
  else if (auto payload = marshal(self->system(), msg))
    answer = std::move(*payload);
  else
    answer = make_error(ec::invalid_parameter,
                        "the response cannot be marshalled: "
                          + context_of(payload.error()));
  st.server->reply(local, std::move(answer), st.out);
  flush(self);
}

// -- watching ------------------------------------------------------------------------

void on_down_remote(asl_impl self, module_id src, uint32_t apo,
                    const caf::error& reason) {
  auto& st = self->state;
  st.apos->table().forget(src, apo);
  for (auto id : st.bindings.bound_to(src, apo)) {
    auto err = asl_error::apo_gone(describe(st.bindings.find(id)->target)
                              + " exited");
    lose_target(self, id, reason, err);
  }
}

/// Local APO `apo` left the table (exited or unregistered).
void withdraw(asl_impl self, uint32_t apo, const caf::error& reason) {
  auto& st = self->state;
  auto name = st.apos->remove(apo, reason, st.out);
  flush(self);
  // Rebinding proxies of this module bound to it.
  if (name)
    for (auto id : st.bindings.bound_to(st.self_id, apo))
      lose_target(self, id, reason,
                  asl_error::apo_gone("APO '" + *name + "' exited"));
}

// -- the network ---------------------------------------------------------------------

void on_packet(asl_impl self, packet_delivered& pkt) {
  auto& st = self->state;
  auto msg = decode_asl(std::move(pkt.payload));
  auto src = pkt.src;
  if (!msg || !is_unicast(src)) {
    ++st.stats.rx_malformed;
    return;
  }
  auto now = self->clock().now();
  std::visit(
    [&](auto& x) {
      using T = std::decay_t<decltype(x)>;
      if constexpr (std::is_same_v<T, asl_query>) {
        st.discoveries->on_query(src, x, st.out);
      } else if constexpr (std::is_same_v<T, asl_answer>) {
        if (st.discoveries->on_answer(src, x, now))
          finish_discovery(self, x.query_id);
      } else if constexpr (std::is_same_v<T, asl_request>) {
        on_request(self, src, x.request_id, x.apo, x.request_id == 0,
                   x.payload, pkt.authenticated, false);
      } else if constexpr (std::is_same_v<T, asl_response>) {
        on_response(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_reliable_request>) {
        on_request(self, src, x.request_id, x.apo, x.oneway, x.payload,
                   pkt.authenticated, true);
      } else if constexpr (std::is_same_v<T, asl_ack>) {
        st.pending->on_ack(src, x, now);
      } else if constexpr (std::is_same_v<T, asl_watch>) {
        st.apos->on_watch(src, x, st.self_id, st.out);
      } else if constexpr (std::is_same_v<T, asl_unwatch>) {
        st.apos->on_unwatch(src, x);
      } else if constexpr (std::is_same_v<T, asl_down>) {
        on_down_remote(self, src, x.apo, from_wire(x.reason));
      } else if constexpr (std::is_same_v<T, asl_withdraw>) {
        on_down_remote(self, src, x.apo, asl_error::apo_gone("withdrawn"));
      } else if constexpr (std::is_same_v<T, asl_subscribe>) {
        st.topics->on_subscribe(src, x, now, st.out);
      } else if constexpr (std::is_same_v<T, asl_unsubscribe>) {
        st.topics->on_unsubscribe(src, x);
      } else if constexpr (std::is_same_v<T, asl_advertise>) {
        st.topics->on_advertise(src, x, now, st.out);
      } else if constexpr (std::is_same_v<T, asl_publish>) {
        if (auto t = st.topics->on_publish(src, x)) {
          caf::expected<caf::message> value{caf::message{}};
          if (!t->local_subs.empty())
            value = unmarshal_counted(self, x.payload);
          deliver_topic(self, x.topic, *t, src, x.seq,
                  value && !t->local_subs.empty() ? &*value : nullptr,
                  x.payload);
        }
      }
    },
    *msg);
  recycle_payload(*msg);
  flush(self);
}

// -- housekeeping ----------------------------------------------------------------------

/// Module `m` stayed unreachable past the grace period.
void module_lost(asl_impl self, module_id m) {
  auto& st = self->state;
  auto err = asl_error::unreachable(m);
  // Reliable bindings ride it out: their requests wait for the module or
  // their deadline.
  for (auto id : st.bindings.bound_to(m, 0))
    if (!st.bindings.find(id)->reliable)
      lose_target(self, id, err, err);
  fail_pending(self, 0, m, err, true);
  st.apos->table().drop_watcher(m);
  st.apos->table().forget_module(m);
  st.topics->module_lost(m);
}

/// Asks the routing agent for this module's id (kept if it does not
/// answer), then calls `then`.
template <class F>
void refresh_self_id(asl_impl self, F then) {
  self->request(self->state.agent, caf::infinite, atom::get_v, atom::stats_v)
    .then(
      [self, then](routing_stats& rs) mutable {
        self->state.self_id = rs.self;
        then();
      },
      [then](caf::error&) mutable { then(); });
}

void tick(asl_impl self) {
  auto& st = self->state;
  auto now = self->clock().now();
  if (!st.self_id_asked || now - *st.self_id_asked >= std::chrono::seconds(1)) {
    st.self_id_asked = now;
    refresh_self_id(self, [] {});
  }
  for (auto m : st.reach.lost(now, st.cfg.unreachable_grace))
    module_lost(self, m);
  // Deadlines.
  for (auto& out : st.pending->take_expired(now)) {
    ++st.stats.request_timeouts;
    auto b = st.bindings.find(out.binding);
    auto target = b != nullptr && b->bound ? b->target.module : no_module;
    fail(self, out,
         asl_error::deadline(out.reliable, target, reachable(self, target),
                             out.tx.dst, st.cfg.request_timeout));
  }
  st.server->expire(now);
  // Reliable mode: copies due, expired cache entries.
  send_due(self);
  st.reliable->expire(now);
  // Bindings: renew watches, look for new targets.
  for (auto& s : st.bindings.housekeep(now, st.cfg.watch_refresh,
                                      st.cfg.rebind_interval, st.self_id,
                                      st.out)) {
    discover(self, s.query, [self, id = s.id](std::vector<apo_ref> found) {
      auto& state = self->state;
      if (state.bindings.found(id, found, state.self_id, self->clock().now(),
                               state.cfg.rebind_interval, state.out)
          && state.bindings.find(id)->reliable)
        send_due(self, {id});
      flush(self);
    });
  }
  // Topics: renew subscriptions, expire subscribers.
  st.topics->housekeep(now, st.out);
  flush(self);
  st.apos->table().expire(now, st.cfg.remote_entry_ttl);
  auto searching = std::any_of(st.bindings.all().begin(), st.bindings.all().end(),
                               [](auto& kv) { return !kv.second.bound; });
  schedule_tick(self, needs_fast_tick(st) || searching
                        ? st.cfg.tick
                        : std::max(st.cfg.tick, st.cfg.idle_tick));
}

/// The routing agent ended: nothing can be sent any more. Every request
/// waiting for the network fails with app_ec::unavailable, proxies end with
/// it, and so does anything asked later (the layer stays up to say why).
void agent_stopped(asl_impl self, const caf::error& reason) {
  auto& st = self->state;
  st.agent_down = reason;
  auto err = agent_gone(self);
  for (auto& out : st.pending->take_all())
    fail(self, out, err);
  for (auto& p : st.bindings.take_proxies())
    if (detail::kill_apo_proxy(p, err, self->context()))
      ++st.stats.proxies_ended;
  for (auto qid : st.discoveries->running())
    finish_discovery(self, qid);
}

/// Registers local APO `apo` (the handlers of atom::add).
caf::result<apo_ref> register_apo(asl_impl self, std::string name,
                                  std::string type, caf::actor& apo,
                                  apo_access access) {
  auto& st = self->state;
  auto added = st.apos->add(name, type, apo, access);
  if (!added)
    return std::move(added.error());
  auto id = *added;
  self->monitor(apo);
  if (st.self_id != no_module)
    return apo_ref{st.self_id, id, std::move(name), std::move(type)};
  // Right after start-up the module's id is not known here yet (the
  // periodic refresh has not run): ask the agent before answering.
  auto rp = self->make_response_promise<apo_ref>();
  refresh_self_id(self, [self, rp, id, name, type]() mutable {
    rp.deliver(apo_ref{self->state.self_id, id, std::move(name),
                       std::move(type)});
  });
  return rp;
}

/// The handlers of atom::bind with an apo_ref.
caf::result<caf::actor> bind_ref(asl_impl self, const apo_ref& ref,
                                 bool reliable, bool sign) {
  if (ref.module == self->state.self_id) {
    if (auto a = self->state.apos->find(ref.apo))
      return *a;
    return asl_error::apo_gone(describe(ref));
  }
  if (auto err = agent_gone(self))
    return err;
  if (!reachable(self, ref.module))
    return asl_error::no_route_to(ref.module);
  return make_binding(self, ref, reliable, sign);
}

/// The handler of atom::bind with a bind_request.
caf::result<caf::actor> bind_query(asl_impl self, const bind_request& req) {
  if (auto err = cannot_discover(self, req.by, req.pattern))
    return err;
  auto rp = self->make_response_promise<caf::actor>();
  apo_query q{req.by, req.pattern, req.timeout_ms, true};
  discover(self, q, [self, rp, req](std::vector<apo_ref> found) mutable {
    if (found.empty()) {
      rp.deliver(asl_error::not_found(req.by, req.pattern, req.timeout_ms));
    } else if (found.front().module == self->state.self_id && !req.rebind) {
      if (auto a = self->state.apos->find(found.front().apo))
        rp.deliver(*a);
      else
        rp.deliver(asl_error::apo_gone(describe(found.front())));
    } else {
      rp.deliver(make_binding(self, found.front(), req.reliable, false, &req));
    }
  });
  return rp;
}

// -- the actor -------------------------------------------------------------------------

app_support_actor::behavior_type asl_fun(asl_impl self, routing_agent_actor agent,
                                         app_support_config cfg) {
  auto& init = self->state;
  init.cfg = cfg;
  init.agent = agent;
  std::random_device rd;
  auto random_key = [&rd] { return (uint64_t{rd()} << 32) | rd(); };
  init.apos = std::make_unique<apo_registry>(random_key(), cfg.max_watches,
                                             init.stats);
  init.discoveries = std::make_unique<discovery_table>(
    random_key(), cfg.max_remote_apos, init.apos->table(), init.stats);
  init.reliable = std::make_unique<reliable_requests>(
    reliable_requests::config{cfg.tick, cfg.retransmit_initial,
                              cfg.retransmit_min, cfg.retransmit_max,
                              cfg.max_transmissions, cfg.reliable_cache,
                              cfg.reliable_cache_ttl},
    init.stats);
  init.pending = std::make_unique<outgoing_requests>(
    random_key(), cfg.max_pending, *init.reliable, init.stats);
  init.topics = std::make_unique<topic_table>(
    cfg.max_topic_peers, cfg.subscription_lease, init.stats);
  init.server = std::make_unique<request_server>(
    request_server::config{cfg.max_pending, cfg.request_timeout,
                           cfg.allow_unsigned_remote},
    *init.apos, *init.reliable, init.stats);
  init.sink = detail::make_reply_sink(self->system(),
                                      caf::actor_cast<caf::actor>(self));
  self->send(agent, atom::subscribe_v, asl_protocol,
             caf::actor_cast<network_receiver_actor>(self));
  self->send(agent, atom::subscribe_v, atom::routes_v,
             caf::actor_cast<route_listener_actor>(self));
  self->monitor(agent);
  self->set_default_handler(log_unexpected);
  self->set_down_handler([self](caf::down_msg& msg) {
    auto& st = self->state;
    if (msg.source == st.agent.address()) {
      agent_stopped(self, msg.reason ? msg.reason
                                     : make_error(app_ec::unavailable, "exited"));
      return;
    }
    if (auto apo = st.apos->number_of(msg.source))
      withdraw(self, apo, msg.reason);
    st.topics->unsubscribe(msg.source, nullptr, st.out);
    flush(self);
  });
  self->send(self, atom::tick_v, ++self->state.tick_generation);
  return {
    [self](atom::add, std::string& name, std::string& type,
           caf::actor& apo) -> caf::result<apo_ref> {
      return register_apo(self, std::move(name), std::move(type), apo,
                          apo_access::open);
    },
    [self](atom::add, std::string& name, std::string& type, caf::actor& apo,
           apo_access access) -> caf::result<apo_ref> {
      return register_apo(self, std::move(name), std::move(type), apo, access);
    },
    [self](atom::unregister, caf::actor& apo) {
      auto& st = self->state;
      if (auto number = st.apos->number_of(apo.address())) {
        self->demonitor(apo);
        withdraw(self, number, asl_error::apo_gone("unregistered"));
      }
    },
    [self](atom::get, atom::apps) -> std::vector<apo_info> {
      return self->state.apos->list(self->state.self_id, self->clock().now());
    },
    [self](atom::find, apo_query& q) -> caf::result<std::vector<apo_ref>> {
      if (auto err = cannot_discover(self, q.by, q.pattern))
        return err;
      if (q.by == query_by::any)
        q.pattern.clear();
      auto rp = self->make_response_promise<std::vector<apo_ref>>();
      discover(self, q, [rp](std::vector<apo_ref> found) mutable {
        rp.deliver(std::move(found));
      });
      return rp;
    },
    [self](atom::bind, apo_ref& ref) -> caf::result<caf::actor> {
      return bind_ref(self, ref, false, false);
    },
    [self](atom::bind, apo_ref& ref, bool reliable) -> caf::result<caf::actor> {
      return bind_ref(self, ref, reliable, false);
    },
    [self](atom::bind, apo_ref& ref,
           apo_access access) -> caf::result<caf::actor> {
      return bind_ref(self, ref, false, access == apo_access::signed_only);
    },
    [self](atom::bind, bind_request& req) -> caf::result<caf::actor> {
      return bind_query(self, req);
    },
    [self](atom::publish, std::string& topic, caf::message& msg) {
      on_publish_local(self, topic, msg);
    },
    [self](atom::subscribe, std::string& topic,
           caf::actor& sub) -> caf::result<void> {
      auto& st = self->state;
      if (auto err = asl_error::check_label("a topic", topic))
        return err;
      if (!sub)
        return make_error(ec::invalid_parameter, "invalid actor handle");
      auto t = st.topics->subscribe(topic, sub, self->clock().now(), st.out);
      if (t == nullptr)
        return caf::unit;
      self->monitor(sub);
      flush(self);
      if (t->has_last && !t->last.empty())
        post(self, caf::actor_cast<caf::strong_actor_ptr>(sub), nullptr,
             caf::make_message_id(), t->last);
      return caf::unit;
    },
    [self](atom::subscribe, std::string& topic, caf::actor& sub,
           atom::sample) -> caf::result<void> {
      auto& st = self->state;
      if (auto err = asl_error::check_label("a topic", topic))
        return err;
      if (!sub)
        return make_error(ec::invalid_parameter, "invalid actor handle");
      auto t = st.topics->subscribe(topic, sub, self->clock().now(), st.out,
                                    true);
      if (t == nullptr)
        return caf::unit;
      self->monitor(sub);
      flush(self);
      if (t->has_last && t->publishing)
        post(self, caf::actor_cast<caf::strong_actor_ptr>(sub), nullptr,
             caf::make_message_id(),
             caf::make_message(topic_sample{topic, st.self_id, t->seq,
                                            caf::make_timestamp(),
                                            t->last_payload}));
      return caf::unit;
    },
    [self](atom::publish, std::string& topic,
           raw_payload& payload) -> caf::result<void> {
      if (auto err = on_publish_raw(self, topic, payload.bytes))
        return err;
      return caf::unit;
    },
    [self](atom::get, atom::topics) -> std::vector<topic_info> {
      return self->state.topics->list();
    },
    [self](atom::unsubscribe, std::string& topic, caf::actor& sub) {
      self->state.topics->unsubscribe(sub.address(), &topic, self->state.out);
      flush(self);
    },
    [self](atom::get, atom::stats) -> app_support_stats {
      auto& st = self->state;
      auto result = st.stats;
      result.self = st.self_id;
      result.live_bindings = static_cast<uint32_t>(st.bindings.all().size());
      result.pending_requests = static_cast<uint32_t>(st.pending->size());
      result.cached_responses = static_cast<uint32_t>(st.reliable->cached());
      auto& table = st.apos->table();
      result.local_apos = static_cast<uint32_t>(table.locals().size());
      result.known_remote_apos = static_cast<uint32_t>(table.remotes().size());
      result.watches = static_cast<uint32_t>(table.watches());
      result.unexpected_messages = unexpected_messages();
      return result;
    },
    [self](packet_delivered& pkt) { on_packet(self, pkt); },
    [self](reachability& r) {
      auto& st = self->state;
      if (r.reachable) {
        st.reach.up(r.id);
        // Reliable requests waiting for this module go now.
        send_due(self, st.bindings.bound_to(r.id, 0), true);
      } else {
        st.reach.down(r.id, self->clock().now());
        // Requests waiting for it learn at the fine tick once its grace
        // is over.
        if (!st.tick_fast && needs_fast_tick(st))
          schedule_tick(self, st.cfg.tick);
      }
    },
    [self](atom::forward, uint32_t id, caf::strong_actor_ptr& sender,
           uint64_t mid, caf::message& msg) {
      on_forward(self, id, sender, caf::message_id{mid}, msg);
    },
    [self](atom::reply, uint64_t local, caf::message& msg) {
      on_reply(self, local, msg);
    },
    [self](atom::close, uint32_t id) {
      self->state.bindings.close(id, self->state.self_id, self->state.out);
      flush(self);
    },
    [self](atom::done, uint32_t qid) { finish_discovery(self, qid); },
    [self](atom::tick, uint64_t generation) {
      if (generation == self->state.tick_generation)
        tick(self);
    },
  };
}

} // namespace

} // namespace asl_detail

app_support_actor spawn_app_support(caf::actor_system& sys,
                                    routing_agent_actor agent,
                                    app_support_config cfg) {
  return sys.spawn(asl_detail::asl_fun, std::move(agent), std::move(cfg));
}

} // namespace herm
