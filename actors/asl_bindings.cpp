#include "actors/asl_state.hpp"

// Bindings and discoveries in the Application Support Layer's actor: a
// proxy made for a found APO, what happens to its requests when the target
// goes, and the broadcast queries that find targets (the binding table and
// the discovery table, actors/binding_table.hpp and discovery_table.hpp,
// decide; this file acts).

#include "actors/apo_proxy.hpp"
#include "actors/asl_errors.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm::asl_detail {

// -- bindings ------------------------------------------------------------------------

void fail_pending(asl_impl self, uint32_t id, module_id dst,
                  const caf::error& err, bool keep_reliable) {
  for (auto& out : self->state.pending->take_waiting_on(id, dst, keep_reliable))
    fail(self, out, err);
}

void lose_target(asl_impl self, uint32_t id, const caf::error& reason,
                 const caf::error& request_error) {
  auto& st = self->state;
  auto b = st.bindings.find(id);
  if (b == nullptr)
    return;
  // Reliable requests of a rebinding proxy wait for its next target (or
  // their deadline).
  fail_pending(self, id, no_module, request_error, b->rebind);
  if (auto proxy = st.bindings.lose(id, self->clock().now()))
    if (detail::kill_apo_proxy(proxy, reason, self->context()))
      ++st.stats.proxies_ended;
}

namespace {

/// Points binding `b` at `ref`.
void bind_to(asl_impl self, binding& b, const apo_ref& ref) {
  binding_table::bind(b, ref, self->state.self_id, self->clock().now(),
                      self->state.out);
  flush(self);
}

} // namespace

caf::actor make_binding(asl_impl self, const apo_ref& ref, bool reliable,
                        bool sign, const bind_request* req) {
  auto& st = self->state;
  auto [id, b] = st.bindings.add(self->clock().now());
  auto proxy = detail::make_apo_proxy(self->system(),
                                      caf::actor_cast<caf::actor>(self), id);
  b.proxy = caf::actor_cast<caf::weak_actor_ptr>(proxy);
  b.reliable = reliable;
  b.sign = sign;
  if (req != nullptr) {
    b.rebind = req->rebind;
    b.by = req->by;
    b.pattern = req->pattern;
  }
  bind_to(self, b, ref);
  return proxy;
}

// -- discovery ---------------------------------------------------------------------

void finish_discovery(asl_impl self, uint32_t qid) {
  auto& st = self->state;
  if (auto d = st.discoveries->finish(qid, st.self_id))
    d->finish(std::move(d->found));
}

caf::error cannot_discover(asl_impl self, query_by by,
                           const std::string& pattern) {
  if (auto err = agent_gone(self))
    return err;
  if (by != query_by::any)
    return asl_error::check_label("a pattern", pattern);
  return caf::none;
}

void discover(asl_impl self, apo_query q, discovery_table::callback finish) {
  auto& st = self->state;
  auto timeout = std::chrono::milliseconds(q.timeout_ms);
  auto qid = st.discoveries->start(std::move(q), st.self_id,
                                   std::move(finish), st.out);
  if (st.discoveries->satisfied(qid)) {
    finish_discovery(self, qid);
    return;
  }
  flush(self);
  self->delayed_send(self, timeout, atom::done_v, qid);
}

} // namespace herm::asl_detail
