#include "apps/bench/peers/actor_client.hpp"

#include <future>
#include <memory>

#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/atoms.hpp"
#include "actors/runtime/error.hpp"
#include "apps/bench/peers/bench_types.hpp"

namespace herm::bench {

namespace {

struct rtt_client_state {
  static inline const char* name = "herm.bench.rtt_client";
  caf::actor target;
  endpoint_params params;
  bool retry_no_route = false;
  std::vector<uint8_t> payload;
  uint32_t next = 0; // index of the request in flight
  bool answered = false; // a reply came: the route is there
  int64_t t0 = 0;
  client_result result;
  std::shared_ptr<std::promise<client_result>> done;
};

using rtt_client_actor = caf::stateful_actor<rtt_client_state>;

void finish(rtt_client_actor* self) {
  self->state.done->set_value(std::move(self->state.result));
  self->quit();
}

void send_next(rtt_client_actor* self) {
  auto& st = self->state;
  fill_payload(st.payload, st.next);
  st.t0 = now_ns();
  self->request(st.target, st.params.timeout, st.payload)
    .then(
      [self](std::vector<uint8_t>& reply) {
        auto t1 = now_ns();
        auto& s = self->state;
        if (reply.size() != s.payload.size()
            || payload_seq(reply.data(), reply.size()) != s.next) {
          s.result.error = "reply " + std::to_string(s.next) + " of "
                           + std::to_string(reply.size()) + " bytes does not match";
          finish(self);
          return;
        }
        s.answered = true;
        if (s.next >= s.params.warmup)
          s.result.rtt_ns.push_back(t1 - s.t0);
        if (++s.next == s.params.warmup + s.params.count) {
          finish(self);
          return;
        }
        if (s.params.gap.count() > 0)
          self->delayed_send(self, s.params.gap, atom::tick_v);
        else
          send_next(self);
      },
      [self](caf::error& err) {
        auto& s = self->state;
        if (s.retry_no_route && !s.answered && is(err, ec::no_route)) {
          self->delayed_send(self, std::chrono::milliseconds(50), atom::tick_v);
          return;
        }
        s.result.error = "request " + std::to_string(s.next) + ": " + render(err);
        finish(self);
      });
}

caf::behavior rtt_client(rtt_client_actor* self, caf::actor target,
                         endpoint_params p, bool retry_no_route,
                         std::shared_ptr<std::promise<client_result>> done) {
  auto& st = self->state;
  st.target = std::move(target);
  st.payload.resize(p.size);
  st.result.rtt_ns.reserve(p.count);
  st.params = std::move(p);
  st.retry_no_route = retry_no_route;
  st.done = std::move(done);
  send_next(self);
  return {
    [self](atom::tick) { send_next(self); },
  };
}

} // namespace

client_result run_actor_client(caf::actor_system& sys, const caf::actor& target,
                               const endpoint_params& p, bool retry_no_route) {
  auto done = std::make_shared<std::promise<client_result>>();
  auto fut = done->get_future();
  sys.spawn(rtt_client, target, p, retry_no_route, done);
  return fut.get();
}

caf::behavior echo_actor(caf::event_based_actor*) {
  return {
    [](std::vector<uint8_t>& bytes) { return std::move(bytes); },
  };
}

} // namespace herm::bench
