#include "actors/app_support.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <functional>
#include <map>
#include <random>
#include <set>

#include "caf/actor_system.hpp"
#include "caf/mailbox_element.hpp"
#include "caf/make_message.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/apo_proxy.hpp"
#include "actors/app_table.hpp"
#include "actors/runtime/error.hpp"
#include "actors/unexpected.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm {

namespace {

using time_point = std::chrono::steady_clock::time_point;

/// A proxy and what it is bound to.
struct binding {
  caf::weak_actor_ptr proxy;
  bool bound = false;
  apo_ref target;
  /// Rebinding proxies: what to look for while unbound.
  bool rebind = false;
  query_by by = query_by::name;
  std::string pattern;
  time_point next_search;
  bool searching = false;
  time_point last_watch;
  /// Requests through this proxy travel in reliable mode.
  bool reliable = false;
  /// ... and signed (apo_access::signed_only).
  bool sign = false;
};

/// A request sent to a remote APO, waiting for its response.
struct outgoing {
  caf::strong_actor_ptr sender;
  caf::message_id mid;
  uint32_t binding = 0;
  module_id dst = no_module;
  time_point deadline;
  // -- reliable mode: what to send again, and when --
  bool reliable = false;
  bool oneway = false;
  /// The message (handed over unchanged if a rebinding proxy's new target
  /// is local) and its marshalled form.
  caf::message msg;
  byte_buffer payload;
  /// Copies sent so far (0: waiting for a reachable target).
  uint32_t sends = 0;
  time_point first_sent;
  time_point next_send;
  std::chrono::milliseconds rto{0};
  /// The receiver said it is serving the request: only probe now and then.
  bool acked = false;
  /// Counted in reliable_waited already.
  bool waited = false;
};

/// Round-trip estimate to one module (RFC 6298), in ms.
struct rtt_estimate {
  double srtt = 0;
  double rttvar = 0;
};

/// What the receiving module remembers of one reliable request.
struct cached_reply {
  /// False while the APO works on it.
  bool done = false;
  bool oneway = false;
  /// When done and not one-way: sent again for every copy that arrives.
  asl_response response;
  /// For a signed_only APO: the response travels signed.
  bool sign = false;
};

using request_key = std::pair<module_id, uint64_t>;

/// A request a remote module made of one of our APOs.
struct served {
  module_id origin = no_module;
  uint64_t origin_id = 0;
  time_point deadline;
  /// The response goes into the duplicate-suppression cache too.
  bool reliable = false;
  /// For a signed_only APO: the response travels signed.
  bool sign = false;
};

/// A discovery in progress.
struct discovery {
  apo_query query;
  std::set<apo_ref> found;
  std::function<void(std::vector<apo_ref>)> finish;
};

struct topic_state {
  // -- subscriber side --
  std::vector<caf::actor> local_subs;
  time_point next_refresh;
  /// Last sequence number per publishing module.
  std::map<module_id, uint32_t> last_seq;
  // -- publisher side --
  bool publishing = false;
  uint32_t seq = 0;
  bool has_last = false;
  caf::message last;
  byte_buffer last_payload;
  /// Subscribed modules and when their lease ends.
  std::map<module_id, time_point> remote_subs;
};

struct asl_state {
  static inline const char* name = "herm.asl";

  ~asl_state() {
    // Proxies end with the layer; requests still waiting fail.
    auto reason = make_error(routing_ec::no_route, "the application support layer of "
                                           "this module stopped");
    for (auto& kv : bindings)
      if (auto p = kv.second.proxy.lock())
        detail::kill_apo_proxy(p, reason, nullptr);
    for (auto& kv : pending)
      if (kv.second.sender)
        kv.second.sender->enqueue(nullptr, kv.second.mid.response_id(),
                                  caf::make_message(reason), nullptr);
  }

  app_support_config cfg;
  routing_agent_actor agent;
  module_id self_id = no_module;
  std::unique_ptr<app_table> table;
  /// Local APOs: by number and by address.
  std::map<uint32_t, caf::actor> apos;
  std::map<caf::actor_addr, uint32_t> apo_of;
  /// Local APOs registered apo_access::signed_only.
  std::set<uint32_t> signed_only;
  std::map<uint32_t, binding> bindings;
  uint32_t next_binding = 1;
  std::map<uint64_t, outgoing> pending;
  /// Request and query ids go on the wire: not sequential, so that a
  /// forged response or answer needs more than one packet sniffed.
  std::unique_ptr<scrambled_sequence<uint64_t>> request_ids;
  std::map<uint64_t, served> serving;
  uint64_t next_served = 1;
  std::map<uint32_t, discovery> discoveries;
  std::unique_ptr<scrambled_sequence<uint32_t>> query_ids;
  /// Why the routing agent stopped (then nothing can be sent: requests
  /// fail at once with app_ec::unavailable).
  caf::error agent_down;
  std::map<std::string, topic_state> topics;
  /// Modules with a route now, and since when others lost theirs.
  std::set<module_id> reachable;
  std::map<module_id, time_point> unreachable_since;
  caf::strong_actor_ptr sink;
  // -- reliable mode --
  /// Receiver: (sending module, request id) -> what was done, with the
  /// entries in arrival order and when each expires (ttl is constant, so
  /// the front expires first). Both hold the same keys.
  std::map<request_key, cached_reply> cache;
  std::deque<std::pair<request_key, time_point>> cache_order;
  /// Sender: reliable requests answered lately (late copies are counted as
  /// such), bounded like the cache.
  std::set<uint64_t> completed;
  std::deque<uint64_t> completed_order;
  std::map<module_id, rtt_estimate> rtt;
  uint32_t ticks = 0;
  app_support_stats stats;
  byte_buffer buf;
};

using asl_impl = app_support_actor::stateful_pointer<asl_state>;

// -- small helpers -----------------------------------------------------------------

std::string context_of(const caf::error& err) {
  auto& ctx = err.context();
  if (ctx.match_elements<std::string>())
    return ctx.get_as<std::string>(0);
  return ctx.empty() ? std::string{} : caf::to_string(ctx);
}

wire_error to_wire(const caf::error& err) {
  wire_error result;
  if (!err)
    return result;
  result.category = static_cast<uint64_t>(err.category());
  result.code = err.code();
  result.context = context_of(err);
  if (result.context.size() > max_asl_string)
    result.context.resize(max_asl_string);
  return result;
}

caf::error from_wire(const wire_error& w) {
  if (w.code == 0)
    return caf::error{};
  return caf::error{w.code, static_cast<caf::atom_value>(w.category),
                    w.context.empty() ? caf::message{}
                                      : caf::make_message(w.context)};
}

std::string describe(const apo_ref& ref) {
  return "APO '" + ref.name + "' (" + std::to_string(ref.apo) + ") on module "
         + to_hex(ref.module);
}

/// Sends an ASL message over the network.
void transmit(asl_impl self, module_id dst, const asl_message& msg,
              uint8_t priority = prio_normal) {
  auto& st = self->state;
  st.buf.clear();
  encode(msg, st.buf);
  self->send(st.agent, send_packet{dst, asl_protocol, priority, st.buf});
}

/// The same, signed in a keyed network whatever its `auth.data`
/// (apo_access::signed_only traffic).
void transmit_signed(asl_impl self, module_id dst, const asl_message& msg,
                     bool sign = true) {
  auto& st = self->state;
  st.buf.clear();
  encode(msg, st.buf);
  self->send(st.agent,
             send_packet{dst, asl_protocol, prio_normal, st.buf, sign});
}

/// app_ec::unavailable once the routing agent stopped, else none.
caf::error agent_gone(asl_impl self) {
  auto& st = self->state;
  if (!st.agent_down)
    return caf::none;
  return make_error(app_ec::unavailable,
                    "the routing agent of module " + to_hex(st.self_id)
                      + " stopped (" + render(st.agent_down) + ")");
}

/// Delivers `msg` to `dst` as if `from` sent it with message id `mid`.
void post(asl_impl self, const caf::strong_actor_ptr& dst,
          caf::strong_actor_ptr from, caf::message_id mid, caf::message msg) {
  if (dst)
    dst->enqueue(std::move(from), mid, std::move(msg), self->context());
}

/// Answers a request with an error (one-way messages have nobody to tell).
void refuse(asl_impl self, const caf::strong_actor_ptr& sender,
            caf::message_id mid, caf::error err) {
  if (mid.is_request())
    post(self, sender, nullptr, mid.response_id(),
         caf::make_message(std::move(err)));
}

bool reachable(asl_impl self, module_id m) {
  return m == self->state.self_id || self->state.reachable.count(m) != 0;
}

// -- bindings ------------------------------------------------------------------------

/// Fails every request waiting on binding `id` (or, with id 0, on module
/// `dst`).
void fail_pending(asl_impl self, uint32_t id, module_id dst,
                  const caf::error& err, bool keep_reliable = false) {
  auto& st = self->state;
  for (auto i = st.pending.begin(); i != st.pending.end();) {
    if (((id != 0 && i->second.binding == id)
         || (id == 0 && i->second.dst == dst))
        && !(keep_reliable && i->second.reliable)) {
      post(self, i->second.sender, nullptr, i->second.mid.response_id(),
           caf::make_message(err));
      i = st.pending.erase(i);
    } else {
      ++i;
    }
  }
}

/// The target of binding `id` is gone for `reason` (the remote exit reason,
/// or why it is unreachable). A rebinding proxy waits for a new target; any
/// other ends, and its monitors learn `reason`.
void lose_target(asl_impl self, uint32_t id, const caf::error& reason,
                 const caf::error& request_error) {
  auto& st = self->state;
  auto i = st.bindings.find(id);
  if (i == st.bindings.end())
    return;
  auto& b = i->second;
  // Reliable requests of a rebinding proxy wait for its next target (or
  // their deadline).
  fail_pending(self, id, no_module, request_error, b.rebind);
  if (b.rebind) {
    b.bound = false;
    b.next_search = self->clock().now();
    return;
  }
  if (auto p = b.proxy.lock())
    if (detail::kill_apo_proxy(p, reason, self->context()))
      ++st.stats.proxies_ended;
  st.bindings.erase(i);
}

/// Every binding to APO `apo` on module `m` (apo 0: any APO there).
std::vector<uint32_t> bindings_to(asl_impl self, module_id m, uint32_t apo) {
  std::vector<uint32_t> result;
  for (auto& [id, b] : self->state.bindings)
    if (b.bound && b.target.module == m && (apo == 0 || b.target.apo == apo))
      result.push_back(id);
  return result;
}

void watch(asl_impl self, binding& b) {
  b.last_watch = self->clock().now();
  if (b.target.module != self->state.self_id)
    transmit(self, b.target.module, asl_watch{b.target.apo});
}

/// Points binding `b` at `ref`.
void bind_to(asl_impl self, binding& b, const apo_ref& ref) {
  b.bound = true;
  b.target = ref;
  watch(self, b);
}

/// A new proxy bound to `ref` (or, unbound, looking for `req`).
caf::actor make_binding(asl_impl self, const apo_ref* ref,
                        const bind_request* req, bool reliable = false,
                        bool sign = false) {
  auto& st = self->state;
  auto id = st.next_binding++;
  auto proxy = detail::make_apo_proxy(self->system(),
                                      caf::actor_cast<caf::actor>(self), id);
  auto& b = st.bindings[id];
  b.proxy = caf::actor_cast<caf::weak_actor_ptr>(proxy);
  b.reliable = reliable;
  b.sign = sign;
  if (req != nullptr) {
    b.rebind = req->rebind;
    b.by = req->by;
    b.pattern = req->pattern;
    b.reliable = req->reliable;
  }
  if (ref != nullptr)
    bind_to(self, b, *ref);
  else
    b.next_search = self->clock().now();
  return proxy;
}

// -- discovery ---------------------------------------------------------------------

void finish_discovery(asl_impl self, uint32_t qid) {
  auto& st = self->state;
  auto i = st.discoveries.find(qid);
  if (i == st.discoveries.end())
    return;
  auto d = std::move(i->second);
  st.discoveries.erase(i);
  std::vector<apo_ref> result(d.found.begin(), d.found.end());
  // Local matches first, then by module and number.
  std::stable_partition(result.begin(), result.end(), [&](const apo_ref& r) {
    return r.module == st.self_id;
  });
  d.finish(std::move(result));
}

void discover(asl_impl self, apo_query q,
              std::function<void(std::vector<apo_ref>)> finish) {
  auto& st = self->state;
  auto qid = st.query_ids->next();
  while (st.discoveries.count(qid) != 0)
    qid = st.query_ids->next();
  auto& d = st.discoveries[qid];
  d.query = q;
  d.finish = std::move(finish);
  for (auto& e : st.table->match(q.by, q.pattern))
    d.found.insert(apo_ref{st.self_id, e.apo, e.name, e.type});
  if (q.first && !d.found.empty()) {
    finish_discovery(self, qid);
    return;
  }
  transmit(self, broadcast_module, asl_query{qid, q.by, q.pattern});
  ++st.stats.queries_sent;
  self->delayed_send(self, std::chrono::milliseconds(q.timeout_ms),
                     atom::done_v, qid);
}

void on_answer(asl_impl self, module_id src, asl_answer& a) {
  auto& st = self->state;
  ++st.stats.answers_received;
  auto now = self->clock().now();
  for (auto& e : a.entries)
    if (!st.table->learn(src, e, now, st.cfg.max_remote_apos))
      ++st.stats.remote_apos_refused;
  auto i = st.discoveries.find(a.query_id);
  if (i == st.discoveries.end())
    return;
  auto& d = i->second;
  for (auto& e : a.entries)
    if (app_table::matches(d.query.by, d.query.pattern, e.name, e.type)) {
      apo_ref ref{src, e.apo, e.name, e.type};
      if (d.found.size() >= st.cfg.max_remote_apos && d.found.count(ref) == 0)
        ++st.stats.discovery_entries_refused;
      else
        d.found.insert(std::move(ref));
    }
  if (d.query.first && !d.found.empty())
    finish_discovery(self, a.query_id);
}

void on_query(asl_impl self, module_id src, const asl_query& q) {
  auto& st = self->state;
  auto matches = st.table->match(q.by, q.pattern);
  if (matches.empty())
    return;
  ++st.stats.queries_answered;
  asl_answer a{q.query_id, {}};
  for (auto& e : matches) {
    a.entries.push_back(std::move(e));
    if (a.entries.size() == max_answer_entries) {
      transmit(self, src, a);
      a.entries.clear();
    }
  }
  if (!a.entries.empty())
    transmit(self, src, a);
}

// -- reliable mode: the sender ----------------------------------------------------

std::chrono::milliseconds base_rto(asl_impl self, module_id dst) {
  auto& cfg = self->state.cfg;
  auto i = self->state.rtt.find(dst);
  if (i == self->state.rtt.end())
    return cfg.retransmit_initial;
  auto ms = std::chrono::milliseconds(
    static_cast<int64_t>(i->second.srtt + 4 * i->second.rttvar + 0.5));
  return std::clamp(ms, cfg.retransmit_min, cfg.retransmit_max);
}

/// A round trip to `dst` of a request answered on its first copy (Karn).
void sample_rtt(asl_impl self, module_id dst, time_point sent) {
  auto r = std::chrono::duration<double, std::milli>(self->clock().now() - sent)
             .count();
  auto [i, fresh] = self->state.rtt.try_emplace(dst);
  auto& e = i->second;
  if (fresh) {
    e.srtt = r;
    e.rttvar = r / 2;
  } else {
    e.rttvar = 0.75 * e.rttvar + 0.25 * std::abs(e.srtt - r);
    e.srtt = 0.875 * e.srtt + 0.125 * r;
  }
}

/// Reliable request `rid` got its response or ack: late copies of either
/// are recognized for a while.
void note_completed(asl_impl self, uint64_t rid) {
  auto& st = self->state;
  if (!st.completed.insert(rid).second)
    return;
  st.completed_order.push_back(rid);
  while (st.completed_order.size() > st.cfg.reliable_cache) {
    st.completed.erase(st.completed_order.front());
    st.completed_order.pop_front();
  }
}

/// Sends reliable request `rid` (again) if its binding has a reachable
/// target, and sets when to look at it next. Returns true when it was
/// handed to a local APO instead (a rebinding proxy's new target is here):
/// the caller forgets it.
bool send_reliable(asl_impl self, uint64_t rid, outgoing& out, time_point now) {
  auto& st = self->state;
  auto wait = [&] {
    if (!out.waited) {
      out.waited = true;
      ++st.stats.reliable_waited;
    }
    out.next_send = now + st.cfg.tick;
    return false;
  };
  auto b = st.bindings.find(out.binding);
  if (b == st.bindings.end() || !b->second.bound)
    return wait(); // parked: waits for a target
  auto& target = b->second.target;
  if (target.module == st.self_id) {
    auto a = st.apos.find(target.apo);
    if (a == st.apos.end()) {
      out.next_send = now + st.cfg.tick;
      return false;
    }
    post(self, caf::actor_cast<caf::strong_actor_ptr>(a->second),
         std::move(out.sender), out.mid, std::move(out.msg));
    return true;
  }
  if (!reachable(self, target.module))
    return wait();
  if (out.sends >= st.cfg.max_transmissions) {
    out.next_send = now + st.cfg.tick;
    return false;
  }
  if (out.sends == 0 || out.dst != target.module) {
    out.sends = 0;
    out.acked = false;
    out.first_sent = now;
    out.rto = base_rto(self, target.module);
  } else {
    ++st.stats.retransmissions;
    out.rto = std::min(out.acked ? st.cfg.retransmit_max : out.rto * 2,
                       st.cfg.retransmit_max);
  }
  ++out.sends;
  out.dst = target.module;
  transmit_signed(self, out.dst,
                  asl_reliable_request{rid, target.apo, out.oneway, out.payload},
                  b->second.sign);
  out.next_send = now + out.rto;
  return false;
}

/// Sends every reliable request whose time has come (all of them towards
/// `only`, when given: it just became reachable or was bound).
void send_due(asl_impl self, uint32_t only_binding = 0,
              module_id only_module = no_module) {
  auto& st = self->state;
  auto now = self->clock().now();
  for (auto i = st.pending.begin(); i != st.pending.end();) {
    auto& out = i->second;
    bool forced = false;
    if (out.reliable && (only_binding != 0 || only_module != no_module)) {
      auto b = st.bindings.find(out.binding);
      forced = (only_binding != 0 && out.binding == only_binding)
               || (only_module != no_module && b != st.bindings.end()
                   && b->second.bound && b->second.target.module == only_module
                   && !out.acked);
    }
    if (out.reliable && (forced || out.next_send <= now)
        && send_reliable(self, i->first, out, now))
      i = st.pending.erase(i);
    else
      ++i;
  }
}

// -- requests ------------------------------------------------------------------------

/// `msg` marshalled for the wire; or nothing, after refusing the sender
/// (not marshallable, or above max_message) and counting it.
std::optional<byte_buffer> marshal_outgoing(asl_impl self,
                                            caf::strong_actor_ptr& sender,
                                            caf::message_id mid,
                                            const caf::message& msg) {
  auto& st = self->state;
  auto payload = marshal(self->system(), msg);
  if (!payload) {
    ++st.stats.tx_refused;
    refuse(self, sender, mid, std::move(payload.error()));
    return std::nullopt;
  }
  if (payload->size() > st.cfg.max_message) {
    ++st.stats.tx_refused;
    refuse(self, sender, mid,
           make_error(ec::packet_too_large,
                      "message of " + std::to_string(payload->size())
                        + " bytes marshalled; the limit is "
                        + std::to_string(st.cfg.max_message)));
    return std::nullopt;
  }
  return std::move(*payload);
}

/// A request or one-way message through a reliable binding (the target is
/// remote, or the proxy is still looking for one).
void forward_reliable(asl_impl self, uint32_t id, caf::strong_actor_ptr& sender,
                      caf::message_id mid, caf::message& msg) {
  auto& st = self->state;
  auto payload = marshal_outgoing(self, sender, mid, msg);
  if (!payload)
    return;
  if (st.pending.size() >= st.cfg.max_pending) {
    ++st.stats.tx_refused;
    refuse(self, sender, mid,
           make_error(ec::queue_full, std::to_string(st.pending.size())
                                        + " remote requests outstanding"));
    return;
  }
  auto now = self->clock().now();
  auto rid = st.request_ids->next();
  outgoing out;
  out.sender = std::move(sender);
  out.mid = mid;
  out.binding = id;
  out.deadline = now + st.cfg.request_timeout;
  out.reliable = true;
  out.oneway = !mid.is_request();
  out.msg = std::move(msg);
  out.payload = std::move(*payload);
  if (out.oneway)
    ++st.stats.oneway_sent;
  else
    ++st.stats.requests_sent;
  ++st.stats.reliable_sent;
  auto i = st.pending.emplace(rid, std::move(out)).first;
  if (send_reliable(self, rid, i->second, now))
    st.pending.erase(i);
}

void on_forward(asl_impl self, uint32_t id, caf::strong_actor_ptr& sender,
                caf::message_id mid, caf::message& msg) {
  auto& st = self->state;
  auto i = st.bindings.find(id);
  if (i == st.bindings.end()) {
    refuse(self, sender, mid, make_error(app_ec::apo_gone, "binding ended"));
    return;
  }
  if (auto err = agent_gone(self)) {
    refuse(self, sender, mid, std::move(err));
    return;
  }
  auto& b = i->second;
  if (b.reliable
      && (b.bound ? b.target.module != st.self_id : b.rebind)) {
    forward_reliable(self, id, sender, mid, msg);
    return;
  }
  if (!b.bound) {
    refuse(self, sender, mid,
           make_error(app_ec::apo_gone, "no APO named '" + b.pattern
                                      + "' is bound yet (looking for one)"));
    return;
  }
  if (b.target.module == st.self_id) {
    // A rebinding proxy whose match is here: hand it over unchanged.
    auto a = st.apos.find(b.target.apo);
    if (a == st.apos.end()) {
      refuse(self, sender, mid, make_error(app_ec::apo_gone, describe(b.target)));
      return;
    }
    post(self, caf::actor_cast<caf::strong_actor_ptr>(a->second),
         std::move(sender), mid, std::move(msg));
    return;
  }
  if (!reachable(self, b.target.module)) {
    ++st.stats.dropped_no_route;
    refuse(self, sender, mid,
           make_error(routing_ec::no_route, "no route to module "
                                      + to_hex(b.target.module)));
    return;
  }
  auto payload = marshal_outgoing(self, sender, mid, msg);
  if (!payload)
    return;
  if (!mid.is_request()) {
    ++st.stats.oneway_sent;
    transmit_signed(self, b.target.module,
                    asl_request{0, b.target.apo, std::move(*payload)}, b.sign);
    return;
  }
  if (st.pending.size() >= st.cfg.max_pending) {
    ++st.stats.tx_refused;
    refuse(self, sender, mid,
           make_error(ec::queue_full, std::to_string(st.pending.size())
                                        + " remote requests outstanding"));
    return;
  }
  auto rid = st.request_ids->next();
  outgoing out;
  out.sender = std::move(sender);
  out.mid = mid;
  out.binding = id;
  out.dst = b.target.module;
  out.deadline = self->clock().now() + st.cfg.request_timeout;
  st.pending.emplace(rid, std::move(out));
  ++st.stats.requests_sent;
  transmit_signed(self, b.target.module,
                  asl_request{rid, b.target.apo, std::move(*payload)}, b.sign);
}

asl_response error_response(uint64_t rid, const caf::error& err) {
  asl_response r;
  r.request_id = rid;
  r.ok = false;
  r.error = to_wire(err);
  return r;
}

void respond_error(asl_impl self, module_id dst, uint64_t rid,
                   const caf::error& err, bool sign = false) {
  if (rid == 0)
    return;
  transmit_signed(self, dst, error_response(rid, err), sign);
}

/// Whether a request for local APO `apo` that arrived from `src` (signed
/// and verified: `authenticated`) may reach it; if not, it is counted and
/// the requester gets app_ec::unauthorized.
bool authorized(asl_impl self, module_id src, uint64_t rid, uint32_t apo,
                bool authenticated) {
  auto& st = self->state;
  if (st.signed_only.count(apo) == 0 || authenticated
      || st.cfg.allow_unsigned_remote)
    return true;
  ++st.stats.rx_unauthorized;
  auto entry = st.table->local(apo);
  respond_error(self, src, rid,
                make_error(app_ec::unauthorized,
                           "APO '" + (entry ? entry->name : std::string{"?"})
                             + "' of module " + to_hex(st.self_id)
                             + " takes requests from other modules only signed "
                               "with the network's key (on a module without "
                               "a key: only with control.allow_unsigned_remote)"),
                true);
  return false;
}

// -- reliable mode: the receiver --------------------------------------------------

/// Remembers reliable request `key`; the oldest entry goes when full.
cached_reply& remember(asl_impl self, const request_key& key, bool done,
                       bool oneway) {
  auto& st = self->state;
  while (!st.cache_order.empty() && st.cache.size() >= st.cfg.reliable_cache) {
    st.cache.erase(st.cache_order.front().first);
    st.cache_order.pop_front();
  }
  st.cache_order.emplace_back(key, self->clock().now()
                                     + st.cfg.reliable_cache_ttl);
  auto& c = st.cache[key];
  c.done = done;
  c.oneway = oneway;
  return c;
}

void send_ack(asl_impl self, module_id dst, uint64_t rid) {
  ++self->state.stats.acks_sent;
  transmit(self, dst, asl_ack{rid});
}

/// The APO a request from `src` is for, and its payload unmarshalled; or
/// nothing, after answering the requester with the error and counting it.
std::optional<std::pair<caf::strong_actor_ptr, caf::message>>
open_request(asl_impl self, module_id src, uint64_t rid, uint32_t apo,
             const byte_buffer& payload) {
  auto& st = self->state;
  auto a = st.apos.find(apo);
  if (a == st.apos.end()) {
    ++st.stats.rx_unknown_apo;
    respond_error(self, src, rid,
                  make_error(app_ec::apo_gone, "no APO " + std::to_string(apo)
                                             + " on module "
                                             + to_hex(st.self_id)));
    return std::nullopt;
  }
  bool sign = st.signed_only.count(apo) != 0;
  auto msg = unmarshal(self->system(), payload.data(), payload.size(),
                       st.cfg.limits);
  if (!msg) {
    if (is(msg.error(), app_ec::unknown_type))
      ++st.stats.rx_unknown_type;
    else
      ++st.stats.rx_malformed;
    respond_error(self, src, rid,
                  make_herm_error(msg.error().code(),
                             "module " + to_hex(st.self_id) + ": "
                               + context_of(msg.error())),
                  sign);
    return std::nullopt;
  }
  return std::pair{caf::actor_cast<caf::strong_actor_ptr>(a->second),
                   std::move(*msg)};
}

void on_reliable_request(asl_impl self, module_id src,
                         asl_reliable_request& req, bool authenticated) {
  auto& st = self->state;
  if (!authorized(self, src, req.request_id, req.apo, authenticated))
    return;
  request_key key{src, req.request_id};
  if (auto c = st.cache.find(key); c != st.cache.end()) {
    // A copy of one that arrived before: never delivered again.
    ++st.stats.duplicates_suppressed;
    if (c->second.done && !c->second.oneway)
      transmit_signed(self, src, c->second.response, c->second.sign);
    else
      send_ack(self, src, req.request_id);
    return;
  }
  auto target = open_request(self, src, req.request_id, req.apo, req.payload);
  if (!target)
    return;
  auto& [dst, msg] = *target;
  if (req.oneway) {
    remember(self, key, true, true);
    ++st.stats.oneway_delivered;
    post(self, dst, nullptr, caf::make_message_id(), std::move(msg));
    send_ack(self, src, req.request_id);
    return;
  }
  bool sign = st.signed_only.count(req.apo) != 0;
  if (st.serving.size() >= st.cfg.max_pending) {
    // Not remembered: a later copy may find room.
    ++st.stats.serving_refused;
    respond_error(self, src, req.request_id,
                  make_error(ec::queue_full, "module " + to_hex(st.self_id)
                                               + " is serving too many requests"),
                  sign);
    return;
  }
  remember(self, key, false, false).sign = sign;
  auto local = st.next_served++;
  st.serving.emplace(local, served{src, req.request_id,
                                   self->clock().now() + st.cfg.request_timeout,
                                   true, sign});
  ++st.stats.requests_served;
  post(self, dst, st.sink, caf::make_message_id(local), std::move(msg));
}

void on_request(asl_impl self, module_id src, asl_request& req,
                bool authenticated) {
  auto& st = self->state;
  if (!authorized(self, src, req.request_id, req.apo, authenticated))
    return;
  auto target = open_request(self, src, req.request_id, req.apo, req.payload);
  if (!target)
    return;
  auto& [dst, msg] = *target;
  if (req.request_id == 0) {
    ++st.stats.oneway_delivered;
    post(self, dst, nullptr, caf::make_message_id(), std::move(msg));
    return;
  }
  bool sign = st.signed_only.count(req.apo) != 0;
  if (st.serving.size() >= st.cfg.max_pending) {
    ++st.stats.serving_refused;
    respond_error(self, src, req.request_id,
                  make_error(ec::queue_full, "module " + to_hex(st.self_id)
                                               + " is serving too many requests"),
                  sign);
    return;
  }
  auto local = st.next_served++;
  st.serving.emplace(local, served{src, req.request_id,
                                   self->clock().now() + st.cfg.request_timeout,
                                   false, sign});
  ++st.stats.requests_served;
  post(self, dst, st.sink, caf::make_message_id(local), std::move(msg));
}

/// The local APO answered request `local` of a remote requester.
void on_reply(asl_impl self, uint64_t local, caf::message& msg) {
  auto& st = self->state;
  auto i = st.serving.find(local);
  if (i == st.serving.end())
    return; // timed out meanwhile
  auto s = i->second;
  st.serving.erase(i);
  asl_response r;
  if (msg.match_elements<caf::error>()) {
    auto err = msg.get_as<caf::error>(0);
    // CAF's own codes never reach a user: the APO exited before it could
    // answer, or did not understand the request.
    if (err == caf::sec::request_receiver_down)
      err = make_error(app_ec::apo_gone, "the APO exited before it answered");
    else if (err == caf::sec::unexpected_message)
      err = make_error(ec::invalid_parameter,
                       "the APO does not handle a message of this type");
    r = error_response(s.origin_id, err);
  } else if (auto payload = marshal(self->system(), msg); !payload) {
    r = error_response(s.origin_id,
                       make_error(ec::invalid_parameter,
                                  "the response cannot be marshalled: "
                                    + context_of(payload.error())));
  } else {
    r.request_id = s.origin_id;
    r.ok = true;
    r.payload = std::move(*payload);
  }
  if (s.reliable)
    if (auto c = st.cache.find(request_key{s.origin, s.origin_id});
        c != st.cache.end()) {
      c->second.done = true;
      c->second.response = r;
    }
  transmit_signed(self, s.origin, r, s.sign);
}

void on_response(asl_impl self, module_id src, asl_response& r) {
  auto& st = self->state;
  auto i = st.pending.find(r.request_id);
  if (i == st.pending.end() || i->second.dst != src
      || (i->second.reliable && i->second.sends == 0)) {
    if (st.completed.count(r.request_id) != 0)
      ++st.stats.late_duplicates;
    else
      ++st.stats.rx_unexpected_response;
    return;
  }
  if (i->second.reliable) {
    auto& out = i->second;
    if (out.sends == 1)
      sample_rtt(self, src, out.first_sent);
    if (!r.ok && !out.oneway) {
      // The APO is not there (any more): a rebinding proxy's request waits
      // for the next target instead of failing.
      auto err = from_wire(r.error);
      auto b = st.bindings.find(out.binding);
      if (is(err, app_ec::apo_gone) && b != st.bindings.end() && b->second.rebind) {
        out.sends = 0;
        lose_target(self, out.binding, err, err);
        return;
      }
    }
    note_completed(self, r.request_id);
    if (out.oneway) {
      // An error for a one-way message: nobody to tell.
      st.pending.erase(i);
      return;
    }
  }
  auto out = std::move(i->second);
  st.pending.erase(i);
  ++st.stats.responses_received;
  caf::strong_actor_ptr from;
  if (auto b = st.bindings.find(out.binding); b != st.bindings.end())
    from = b->second.proxy.lock();
  if (!r.ok) {
    auto err = from_wire(r.error);
    post(self, out.sender, from, out.mid.response_id(), caf::make_message(err));
    if (is(err, app_ec::apo_gone))
      lose_target(self, out.binding, err, err);
    return;
  }
  auto msg = unmarshal(self->system(), r.payload.data(), r.payload.size(),
                       st.cfg.limits);
  if (!msg) {
    if (is(msg.error(), app_ec::unknown_type))
      ++st.stats.rx_unknown_type;
    else
      ++st.stats.rx_malformed;
    post(self, out.sender, from, out.mid.response_id(),
         caf::make_message(msg.error()));
    return;
  }
  post(self, out.sender, from, out.mid.response_id(), std::move(*msg));
}

void on_ack(asl_impl self, module_id src, const asl_ack& a) {
  auto& st = self->state;
  auto i = st.pending.find(a.request_id);
  if (i == st.pending.end() || !i->second.reliable || i->second.dst != src
      || i->second.sends == 0) {
    if (st.completed.count(a.request_id) != 0)
      ++st.stats.late_duplicates;
    else
      ++st.stats.rx_unexpected_response;
    return;
  }
  ++st.stats.acks_received;
  auto& out = i->second;
  if (out.oneway) {
    if (out.sends == 1)
      sample_rtt(self, src, out.first_sent);
    note_completed(self, a.request_id);
    st.pending.erase(i);
    return;
  }
  // Being served: probe at the slowest pace until the response comes.
  out.acked = true;
  out.next_send = self->clock().now() + st.cfg.retransmit_max;
}

// -- watching ------------------------------------------------------------------------

void on_down_remote(asl_impl self, module_id src, const asl_down& d) {
  auto& st = self->state;
  st.table->forget(src, d.apo);
  auto reason = from_wire(d.reason);
  for (auto id : bindings_to(self, src, d.apo)) {
    auto& b = st.bindings[id];
    auto err = make_error(app_ec::apo_gone, describe(b.target) + " exited");
    lose_target(self, id, reason ? reason : caf::error{}, err);
  }
}

/// Local APO `apo` left the table (exited or unregistered).
void withdraw(asl_impl self, uint32_t apo, const caf::error& reason) {
  auto& st = self->state;
  auto entry = st.table->local(apo);
  if (entry == nullptr)
    return;
  auto name = entry->name;
  auto watchers = st.table->remove_local(apo);
  st.signed_only.erase(apo);
  if (auto a = st.apos.find(apo); a != st.apos.end()) {
    st.apo_of.erase(a->second.address());
    st.apos.erase(a);
  }
  ++st.stats.withdrawn;
  for (auto m : watchers)
    transmit(self, m, asl_down{apo, to_wire(reason)});
  transmit(self, broadcast_module, asl_withdraw{apo, name});
  // Rebinding proxies of this module bound to it.
  for (auto id : bindings_to(self, st.self_id, apo))
    lose_target(self, id, reason,
                make_error(app_ec::apo_gone, "APO '" + name + "' exited"));
}

// -- topics --------------------------------------------------------------------------

void deliver_local(asl_impl self, topic_state& ts, const caf::message& msg) {
  for (auto& sub : ts.local_subs) {
    post(self, caf::actor_cast<caf::strong_actor_ptr>(sub), nullptr,
         caf::make_message_id(), msg);
    ++self->state.stats.publications_delivered;
  }
}

void send_publication(asl_impl self, const std::string& topic,
                      topic_state& ts, module_id dst) {
  transmit(self, dst, asl_publish{topic, ts.seq, ts.last_payload});
  ++self->state.stats.publications_sent;
}

void on_publish_local(asl_impl self, const std::string& topic,
                      caf::message& msg) {
  auto& st = self->state;
  if (topic.empty() || topic.size() > max_asl_string) {
    ++st.stats.tx_refused;
    return;
  }
  auto payload = marshal(self->system(), msg);
  if (!payload || payload->size() > st.cfg.max_message) {
    ++st.stats.tx_refused;
    return;
  }
  auto& ts = st.topics[topic];
  if (!ts.publishing) {
    ts.publishing = true;
    // Subscribers that are already waiting answer with a subscription.
    transmit(self, broadcast_module, asl_advertise{topic});
  }
  ++st.stats.published;
  ++ts.seq;
  ts.has_last = true;
  ts.last = msg;
  ts.last_payload = std::move(*payload);
  deliver_local(self, ts, msg);
  auto now = self->clock().now();
  for (auto i = ts.remote_subs.begin(); i != ts.remote_subs.end();) {
    if (i->second < now) {
      i = ts.remote_subs.erase(i);
      continue;
    }
    send_publication(self, topic, ts, i->first);
    ++i;
  }
}

void announce_subscription(asl_impl self, const std::string& topic,
                           topic_state& ts, module_id dst) {
  auto& cfg = self->state.cfg;
  transmit(self, dst,
           asl_subscribe{topic, static_cast<uint32_t>(
                                  cfg.subscription_lease.count())});
  ts.next_refresh = self->clock().now() + cfg.subscription_lease / 3;
}

void drop_subscriber(asl_impl self, const caf::actor_addr& who,
                     const std::string* only) {
  auto& st = self->state;
  for (auto i = st.topics.begin(); i != st.topics.end();) {
    auto& ts = i->second;
    if (only == nullptr || i->first == *only) {
      auto before = ts.local_subs.size();
      ts.local_subs.erase(std::remove_if(ts.local_subs.begin(),
                                         ts.local_subs.end(),
                                         [&](const caf::actor& a) {
                                           return a.address() == who;
                                         }),
                          ts.local_subs.end());
      if (before > 0 && ts.local_subs.empty()) {
        transmit(self, broadcast_module, asl_unsubscribe{i->first});
        ts.last_seq.clear();
      }
    }
    if (ts.local_subs.empty() && !ts.publishing)
      i = st.topics.erase(i);
    else
      ++i;
  }
}

void on_remote_publication(asl_impl self, module_id src, asl_publish& p) {
  auto& st = self->state;
  ++st.stats.publications_received;
  auto i = st.topics.find(p.topic);
  if (i == st.topics.end() || i->second.local_subs.empty())
    return; // no longer interested; the lease runs out
  auto& ts = i->second;
  auto last = ts.last_seq.find(src);
  if (last != ts.last_seq.end()) {
    if (p.seq == last->second)
      return; // the same value again (a late joiner's copy)
    if (p.seq > last->second + 1)
      st.stats.publications_lost += p.seq - last->second - 1;
    last->second = p.seq;
  } else if (ts.last_seq.size() < st.cfg.max_topic_peers) {
    ts.last_seq.emplace(src, p.seq);
  } else {
    // Delivered, but its gaps and repeats go unnoticed.
    ++st.stats.publishers_refused;
  }
  auto msg = unmarshal(self->system(), p.payload.data(), p.payload.size(),
                       st.cfg.limits);
  if (!msg) {
    if (is(msg.error(), app_ec::unknown_type))
      ++st.stats.rx_unknown_type;
    else
      ++st.stats.rx_malformed;
    return;
  }
  deliver_local(self, ts, *msg);
}

void on_remote_subscribe(asl_impl self, module_id src, const asl_subscribe& s) {
  auto& st = self->state;
  auto i = st.topics.find(s.topic);
  if (i == st.topics.end() || !i->second.publishing)
    return;
  auto& ts = i->second;
  auto lease = std::chrono::milliseconds(
    std::min<uint32_t>(s.lease_ms, 24 * 3600 * 1000));
  bool fresh = ts.remote_subs.count(src) == 0;
  if (fresh && ts.remote_subs.size() >= st.cfg.max_topic_peers) {
    ++st.stats.subscribers_refused;
    return;
  }
  ts.remote_subs[src] = self->clock().now() + lease;
  if (fresh && ts.has_last)
    send_publication(self, s.topic, ts, src); // a late joiner
}

// -- the network ---------------------------------------------------------------------

void on_packet(asl_impl self, packet_delivered& pkt) {
  auto& st = self->state;
  auto msg = decode_asl(pkt.payload.data(), pkt.payload.size());
  if (!msg) {
    ++st.stats.rx_malformed;
    return;
  }
  auto src = pkt.src;
  if (!is_unicast(src)) {
    ++st.stats.rx_malformed;
    return;
  }
  std::visit(
    [&](auto& x) {
      using T = std::decay_t<decltype(x)>;
      if constexpr (std::is_same_v<T, asl_query>) {
        on_query(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_answer>) {
        on_answer(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_request>) {
        on_request(self, src, x, pkt.authenticated);
      } else if constexpr (std::is_same_v<T, asl_response>) {
        on_response(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_reliable_request>) {
        on_reliable_request(self, src, x, pkt.authenticated);
      } else if constexpr (std::is_same_v<T, asl_ack>) {
        on_ack(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_watch>) {
        bool refused = false;
        if (st.table->watch(x.apo, src, st.cfg.max_watches, &refused)) {
          if (refused)
            ++st.stats.watches_refused;
        } else
          transmit(self, src,
                   asl_down{x.apo, to_wire(make_error(
                                     app_ec::apo_gone,
                                     "no APO " + std::to_string(x.apo)
                                       + " on module " + to_hex(st.self_id)))});
      } else if constexpr (std::is_same_v<T, asl_unwatch>) {
        st.table->unwatch(x.apo, src);
      } else if constexpr (std::is_same_v<T, asl_down>) {
        on_down_remote(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_withdraw>) {
        asl_down d{x.apo, to_wire(make_error(app_ec::apo_gone, "withdrawn"))};
        on_down_remote(self, src, d);
      } else if constexpr (std::is_same_v<T, asl_subscribe>) {
        on_remote_subscribe(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_unsubscribe>) {
        if (auto i = st.topics.find(x.topic); i != st.topics.end())
          i->second.remote_subs.erase(src);
      } else if constexpr (std::is_same_v<T, asl_publish>) {
        on_remote_publication(self, src, x);
      } else if constexpr (std::is_same_v<T, asl_advertise>) {
        if (auto i = st.topics.find(x.topic);
            i != st.topics.end() && !i->second.local_subs.empty())
          announce_subscription(self, x.topic, i->second, src);
      }
    },
    *msg);
}

// -- housekeeping ----------------------------------------------------------------------

/// Module `m` stayed unreachable past the grace period.
void module_lost(asl_impl self, module_id m) {
  auto& st = self->state;
  auto err = make_error(routing_ec::no_route, "module " + to_hex(m) + " unreachable");
  // Reliable bindings ride it out: their requests wait for the module or
  // their deadline.
  for (auto id : bindings_to(self, m, 0))
    if (!st.bindings[id].reliable)
      lose_target(self, id, err, err);
  fail_pending(self, 0, m, err, true);
  st.table->drop_watcher(m);
  st.table->forget_module(m);
  for (auto& kv : st.topics) {
    kv.second.remote_subs.erase(m);
    kv.second.last_seq.erase(m);
  }
}

void rebind_found(asl_impl self, uint32_t id, std::vector<apo_ref>& found) {
  auto& st = self->state;
  auto i = st.bindings.find(id);
  if (i == st.bindings.end())
    return;
  auto& b = i->second;
  b.searching = false;
  b.next_search = self->clock().now() + st.cfg.rebind_interval;
  if (!found.empty() && !b.bound) {
    bind_to(self, b, found.front());
    if (b.reliable)
      send_due(self, id);
  }
}

void rebind_search(asl_impl self, uint32_t id) {
  auto& st = self->state;
  auto& b = st.bindings[id];
  b.searching = true;
  apo_query q{b.by, b.pattern,
              static_cast<uint32_t>(st.cfg.rebind_interval.count() / 2), true};
  discover(self, q, [self, id](std::vector<apo_ref> found) {
    rebind_found(self, id, found);
  });
}

void tick(asl_impl self) {
  auto& st = self->state;
  auto now = self->clock().now();
  if (++st.ticks % 10 == 1)
    self->request(st.agent, caf::infinite, atom::get_v, atom::stats_v)
      .then([self](routing_stats& rs) { self->state.self_id = rs.self; },
            [](caf::error&) {});
  // Modules gone for longer than the grace period.
  for (auto i = st.unreachable_since.begin(); i != st.unreachable_since.end();) {
    if (now - i->second >= st.cfg.unreachable_grace) {
      auto m = i->first;
      i = st.unreachable_since.erase(i);
      module_lost(self, m);
    } else {
      ++i;
    }
  }
  // Deadlines.
  auto within = " within " + std::to_string(st.cfg.request_timeout.count())
                + " ms";
  for (auto i = st.pending.begin(); i != st.pending.end();) {
    if (i->second.deadline <= now) {
      ++st.stats.request_timeouts;
      auto& out = i->second;
      auto err = make_error(ec::timeout, "no response from module "
                                           + to_hex(out.dst) + within);
      if (out.reliable) {
        auto b = st.bindings.find(out.binding);
        if (b == st.bindings.end() || !b->second.bound)
          err = make_error(app_ec::apo_gone, "no APO to send it to" + within);
        else if (!reachable(self, b->second.target.module))
          err = make_error(routing_ec::no_route, "module "
                                           + to_hex(b->second.target.module)
                                           + " stayed unreachable" + within);
      }
      post(self, out.sender, nullptr, out.mid.response_id(),
           caf::make_message(std::move(err)));
      i = st.pending.erase(i);
    } else {
      ++i;
    }
  }
  for (auto i = st.serving.begin(); i != st.serving.end();)
    i = i->second.deadline <= now ? st.serving.erase(i) : std::next(i);
  // Reliable mode: copies due, expired cache entries.
  send_due(self);
  while (!st.cache_order.empty() && st.cache_order.front().second <= now) {
    st.cache.erase(st.cache_order.front().first);
    st.cache_order.pop_front();
  }
  // Bindings: renew watches, look for new targets.
  std::vector<uint32_t> search;
  for (auto& [id, b] : st.bindings) {
    if (b.bound && now - b.last_watch >= st.cfg.watch_refresh)
      watch(self, b);
    if (!b.bound && b.rebind && !b.searching && b.next_search <= now)
      search.push_back(id);
  }
  for (auto id : search)
    rebind_search(self, id);
  // Topics: renew subscriptions, expire subscribers.
  for (auto& [topic, ts] : st.topics) {
    if (!ts.local_subs.empty() && ts.next_refresh <= now)
      announce_subscription(self, topic, ts, broadcast_module);
    for (auto i = ts.remote_subs.begin(); i != ts.remote_subs.end();)
      i = i->second < now ? ts.remote_subs.erase(i) : std::next(i);
  }
  st.table->expire(now, st.cfg.remote_entry_ttl);
  self->delayed_send(self, st.cfg.tick, atom::tick_v);
}

/// The routing agent ended: nothing can be sent any more. Every request
/// waiting for the network fails with app_ec::unavailable, proxies end with it,
/// and so does anything asked later (the layer stays up to say why).
void agent_stopped(asl_impl self, const caf::error& reason) {
  auto& st = self->state;
  st.agent_down = reason;
  auto err = agent_gone(self);
  for (auto& kv : st.pending)
    post(self, kv.second.sender, nullptr, kv.second.mid.response_id(),
         caf::make_message(err));
  st.pending.clear();
  for (auto& kv : st.bindings)
    if (auto p = kv.second.proxy.lock())
      if (detail::kill_apo_proxy(p, err, self->context()))
        ++st.stats.proxies_ended;
  st.bindings.clear();
  std::vector<uint32_t> running;
  for (auto& kv : st.discoveries)
    running.push_back(kv.first);
  for (auto qid : running)
    finish_discovery(self, qid);
}

caf::error check_label(const std::string& what, const std::string& x) {
  if (x.empty() || x.size() > max_asl_string)
    return make_error(ec::invalid_parameter,
                      what + " must be 1 to 255 bytes, got "
                        + std::to_string(x.size()));
  return caf::none;
}

/// Registers local APO `apo` (the handlers of atom::add).
caf::result<apo_ref> register_apo(asl_impl self, std::string name,
                                  std::string type, caf::actor& apo,
                                  apo_access access) {
  auto& st = self->state;
  if (auto err = check_label("an APO name", name))
    return err;
  if (auto err = check_label("an APO type", type))
    return err;
  if (!apo)
    return make_error(ec::invalid_parameter, "invalid actor handle");
  if (st.apo_of.count(apo.address()) != 0)
    return make_error(ec::already_exists,
                      "that actor is registered already (as '"
                        + st.table->local(st.apo_of[apo.address()])->name
                        + "')");
  auto id = st.table->add_local(name, type);
  st.apos.emplace(id, apo);
  st.apo_of.emplace(apo.address(), id);
  self->monitor(apo);
  ++st.stats.registered;
  if (access == apo_access::signed_only)
    st.signed_only.insert(id);
  if (st.self_id != no_module)
    return apo_ref{st.self_id, id, std::move(name), std::move(type)};
  // Right after start-up the module's id is not known here yet (the
  // periodic refresh has not run): ask the agent before answering.
  auto rp = self->make_response_promise<apo_ref>();
  self->request(st.agent, caf::infinite, atom::get_v, atom::stats_v)
    .then(
      [self, rp, id, name, type](routing_stats& rs) mutable {
        self->state.self_id = rs.self;
        rp.deliver(apo_ref{rs.self, id, std::move(name), std::move(type)});
      },
      [self, rp, id, name, type](caf::error&) mutable {
        rp.deliver(apo_ref{self->state.self_id, id, std::move(name),
                           std::move(type)});
      });
  return rp;
}

/// The handlers of atom::bind with an apo_ref.
caf::result<caf::actor> bind_ref(asl_impl self, const apo_ref& ref,
                                 bool reliable, bool sign) {
  auto& st = self->state;
  if (ref.module == st.self_id) {
    auto i = st.apos.find(ref.apo);
    if (i == st.apos.end())
      return make_error(app_ec::apo_gone, describe(ref));
    return i->second;
  }
  if (auto err = agent_gone(self))
    return err;
  if (!reachable(self, ref.module))
    return make_error(routing_ec::no_route, "no route to module " + to_hex(ref.module));
  return make_binding(self, &ref, nullptr, reliable, sign);
}

// -- the actor -------------------------------------------------------------------------

app_support_actor::behavior_type asl_fun(asl_impl self, routing_agent_actor agent,
                                         app_support_config cfg) {
  auto& init = self->state;
  init.cfg = cfg;
  init.agent = agent;
  std::random_device rd;
  auto random_key = [&rd] { return (uint64_t{rd()} << 32) | rd(); };
  init.table = std::make_unique<app_table>(random_key());
  init.query_ids
    = std::make_unique<scrambled_sequence<uint32_t>>(random_key());
  init.request_ids
    = std::make_unique<scrambled_sequence<uint64_t>>(random_key());
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
    if (auto i = st.apo_of.find(msg.source); i != st.apo_of.end())
      withdraw(self, i->second, msg.reason);
    drop_subscriber(self, msg.source, nullptr);
  });
  self->send(self, atom::tick_v);
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
      if (auto i = st.apo_of.find(apo.address()); i != st.apo_of.end()) {
        self->demonitor(apo);
        withdraw(self, i->second,
                 make_error(app_ec::apo_gone, "unregistered"));
      }
    },
    [self](atom::get, atom::apps) -> std::vector<apo_info> {
      auto& st = self->state;
      auto now = self->clock().now();
      std::vector<apo_info> result;
      for (auto& [apo, e] : st.table->locals())
        result.push_back(apo_info{apo_ref{st.self_id, apo, e.name, e.type}, true,
                                  static_cast<uint32_t>(e.watchers.size()), 0});
      for (auto& [key, e] : st.table->remotes())
        result.push_back(apo_info{
          apo_ref{key.first, key.second, e.name, e.type}, false, 0,
          static_cast<uint32_t>(
            std::chrono::duration_cast<std::chrono::milliseconds>(now - e.heard)
              .count())});
      return result;
    },
    [self](atom::find, apo_query& q) -> caf::result<std::vector<apo_ref>> {
      if (auto err = agent_gone(self))
        return err;
      if (q.by != query_by::any)
        if (auto err = check_label("a pattern", q.pattern))
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
      if (auto err = agent_gone(self))
        return err;
      if (req.by != query_by::any)
        if (auto err = check_label("a pattern", req.pattern))
          return err;
      auto rp = self->make_response_promise<caf::actor>();
      apo_query q{req.by, req.pattern, req.timeout_ms, true};
      discover(self, q, [self, rp, req](std::vector<apo_ref> found) mutable {
        auto& st = self->state;
        if (found.empty()) {
          rp.deliver(make_error(app_ec::not_found,
                                "no APO " + std::string{req.by == query_by::type
                                                          ? "of type '"
                                                          : "named '"}
                                  + req.pattern + "' answered within "
                                  + std::to_string(req.timeout_ms) + " ms"));
          return;
        }
        auto& ref = found.front();
        if (ref.module == st.self_id && !req.rebind) {
          if (auto i = st.apos.find(ref.apo); i != st.apos.end())
            rp.deliver(i->second);
          else
            rp.deliver(make_error(app_ec::apo_gone, describe(ref)));
          return;
        }
        rp.deliver(make_binding(self, &ref, &req));
      });
      return rp;
    },
    [self](atom::publish, std::string& topic, caf::message& msg) {
      on_publish_local(self, topic, msg);
    },
    [self](atom::subscribe, std::string& topic,
           caf::actor& sub) -> caf::result<void> {
      auto& st = self->state;
      if (auto err = check_label("a topic", topic))
        return err;
      if (!sub)
        return make_error(ec::invalid_parameter, "invalid actor handle");
      auto& ts = st.topics[topic];
      if (std::find(ts.local_subs.begin(), ts.local_subs.end(), sub)
          != ts.local_subs.end())
        return caf::unit;
      ts.local_subs.push_back(sub);
      self->monitor(sub);
      if (ts.local_subs.size() == 1)
        announce_subscription(self, topic, ts, broadcast_module);
      if (ts.has_last)
        post(self, caf::actor_cast<caf::strong_actor_ptr>(sub), nullptr,
             caf::make_message_id(), ts.last);
      return caf::unit;
    },
    [self](atom::unsubscribe, std::string& topic, caf::actor& sub) {
      drop_subscriber(self, sub.address(), &topic);
    },
    [self](atom::get, atom::stats) -> app_support_stats {
      auto& st = self->state;
      auto result = st.stats;
      result.self = st.self_id;
      result.local_apos = static_cast<uint32_t>(st.table->locals().size());
      result.known_remote_apos = static_cast<uint32_t>(st.table->remotes().size());
      result.live_bindings = static_cast<uint32_t>(st.bindings.size());
      result.pending_requests = static_cast<uint32_t>(st.pending.size());
      result.cached_responses = static_cast<uint32_t>(st.cache.size());
      result.watches = static_cast<uint32_t>(st.table->watches());
      result.unexpected_messages = unexpected_messages();
      return result;
    },
    [self](packet_delivered& pkt) { on_packet(self, pkt); },
    [self](reachability& r) {
      auto& st = self->state;
      if (r.reachable) {
        st.reachable.insert(r.id);
        st.unreachable_since.erase(r.id);
        // Reliable requests waiting for this module go now.
        send_due(self, 0, r.id);
      } else if (st.reachable.erase(r.id) > 0) {
        st.unreachable_since.emplace(r.id, self->clock().now());
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
      auto& st = self->state;
      auto i = st.bindings.find(id);
      if (i == st.bindings.end())
        return;
      auto target = i->second.target;
      bool bound = i->second.bound;
      st.bindings.erase(i);
      if (bound && target.module != st.self_id
          && bindings_to(self, target.module, target.apo).empty())
        transmit(self, target.module, asl_unwatch{target.apo});
    },
    [self](atom::done, uint32_t qid) { finish_discovery(self, qid); },
    [self](atom::tick) { tick(self); },
  };
}

} // namespace

app_support_actor spawn_app_support(caf::actor_system& sys,
                                    routing_agent_actor agent,
                                    app_support_config cfg) {
  return sys.spawn(asl_fun, std::move(agent), std::move(cfg));
}

} // namespace herm
