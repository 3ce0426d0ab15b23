#include "apps/bench/peers/actor_client.hpp"

#include <future>
#include <memory>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/atoms.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/bench/peers/bench_types.hpp"

namespace herm::bench {

namespace {

/// What both client actors hold: the target, the parameters, the payload
/// buffer, and the result they hand to `done` when they finish.
struct client_state_base {
  caf::actor target;
  endpoint_params params;
  std::vector<uint8_t> payload;
  client_result result;
  std::shared_ptr<std::promise<client_result>> done;
};

/// Hands the result to the waiting thread and ends the actor; called once.
template <class State>
void finish(caf::stateful_actor<State>* self) {
  self->state.done->set_value(std::move(self->state.result));
  self->quit();
}

struct rtt_client_state : client_state_base {
  static inline const char* name = "herm.bench.rtt_client";
  bool retry_no_route = false;
  uint32_t next = 0; // index of the request in flight
  bool answered = false; // a reply came: the route is there
  int64_t t0 = 0;
};

using rtt_client_actor = caf::stateful_actor<rtt_client_state>;

void send_next(rtt_client_actor* self) {
  auto& st = self->state;
  if (st.next == st.params.warmup)
    timed_part_begins(); // probes.hpp: between two round trips
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
          timed_part_ends();
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
        if (s.retry_no_route && !s.answered && is(err, routing_ec::no_route)) {
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

void configure_actor_system(caf::actor_system_config& cfg, const std::string& policy) {
  auto [name, threads] = split_policy(policy);
  if (name == "loop")
    configure(cfg, name, 1, threads); // "loop:US": busy-poll US microseconds
  else
    configure(cfg, name, threads);
  cfg.add_message_types<caf::id_block::herm_bench>();
}

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

// -- oneway ---------------------------------------------------------------------------

namespace herm::bench {

namespace {

struct oneway_client_state : client_state_base {
  static inline const char* name = "herm.bench.oneway_client";
  uint32_t total = 0;
  uint32_t sent = 0;
  uint32_t acked = 0;
  uint32_t acked_at_tick = 0;
  bool finishing = false;
  int hello_tries = 0;
  int done_tries = 0;
  uint64_t allocs_start = 0, allocs_end = 0;
};

using oneway_client_actor = caf::stateful_actor<oneway_client_state>;

void fail(oneway_client_actor* self, std::string what) {
  self->state.result.error = std::move(what);
  finish(self);
}

void request_result(oneway_client_actor* self) {
  self->request(self->state.target, std::chrono::milliseconds(500), int32_t{0})
    .then(
      [self](uint64_t received, int64_t elapsed, double allocs) {
        auto& r = self->state.result;
        r.received = received;
        r.elapsed_ns = elapsed;
        r.server_allocs = allocs;
        finish(self);
      },
      [self](caf::error& err) {
        if (++self->state.done_tries < 20 && !self->state.result.error.size()) {
          request_result(self);
          return;
        }
        fail(self, "result: " + render(err));
      });
}

/// Sends while the window has room; asks for the result once every message
/// is acknowledged.
void pump(oneway_client_actor* self) {
  auto& st = self->state;
  while (st.sent < st.total && st.sent - st.acked < st.params.window) {
    if (st.sent == st.params.warmup)
      st.allocs_start = alloc_count();
    fill_payload(st.payload, st.sent);
    self->send(st.target, st.payload);
    ++st.sent;
    if (st.sent == st.total)
      st.allocs_end = alloc_count();
  }
  if (st.sent == st.total && st.acked >= st.total && !st.finishing) {
    st.finishing = true;
    auto& r = st.result;
    r.sent = st.params.count;
    if (st.params.count > 0)
      r.client_allocs = static_cast<double>(st.allocs_end - st.allocs_start)
                        / static_cast<double>(st.params.count);
    request_result(self);
  }
}

void hello(oneway_client_actor* self) {
  self->request(self->state.target, std::chrono::seconds(2), std::string{"hello"})
    .then(
      [self](std::string&) {
        self->delayed_send(self, self->state.params.stall, atom::tick_v);
        pump(self);
      },
      [self](caf::error& err) {
        // herm: the route may still be converging right after binding.
        if (++self->state.hello_tries < 100
            && (is(err, routing_ec::no_route) || err == caf::sec::request_timeout)) {
          self->delayed_send(self, std::chrono::milliseconds(50), atom::retry_v);
          return;
        }
        fail(self, "hello: " + render(err));
      });
}

caf::behavior oneway_client(oneway_client_actor* self, caf::actor target,
                            endpoint_params p,
                            std::shared_ptr<std::promise<client_result>> done) {
  auto& st = self->state;
  st.target = std::move(target);
  st.payload.resize(p.size);
  st.total = p.warmup + p.count;
  st.params = std::move(p);
  st.done = std::move(done);
  return {
    [self](atom::open) { hello(self); },
    [self](atom::retry) { hello(self); },
    [self](uint32_t acked) {
      auto& s = self->state;
      if (acked > s.acked && acked <= s.sent)
        s.acked = acked;
      pump(self);
    },
    [self](atom::tick) {
      auto& s = self->state;
      if (s.finishing)
        return;
      // No acknowledgement for a whole stall period while waiting for one:
      // a message or an acknowledgement was lost. Reopen the window.
      if (s.acked == s.acked_at_tick && s.acked < s.sent) {
        ++s.result.stalls;
        s.acked = s.sent;
        pump(self);
      }
      s.acked_at_tick = s.acked;
      if (!s.finishing)
        self->delayed_send(self, s.params.stall, atom::tick_v);
    },
  };
}

} // namespace

caf::actor spawn_oneway_client(caf::actor_system& sys, const caf::actor& target,
                               const endpoint_params& p,
                               std::shared_ptr<std::promise<client_result>> done) {
  return sys.spawn(oneway_client, target, p, std::move(done));
}

client_result run_oneway_client(const caf::actor& client,
                                std::future<client_result> outcome) {
  caf::anon_send(client, atom::open_v);
  return outcome.get();
}

caf::behavior count_actor(caf::stateful_actor<count_state>* self,
                          endpoint_params p, app_support_actor apps) {
  auto reset = [self, p] {
    auto& c = self->state.counter;
    c = oneway_counter{};
    c.warmup = p.warmup;
    c.total = p.warmup + p.count;
    c.ack_every = p.ack_every;
  };
  reset();
  return {
    [self](std::vector<uint8_t>& bytes) {
      auto& st = self->state;
      auto seq = payload_seq(bytes.data(), bytes.size());
      if (st.counter.on_message(seq, now_ns()) && st.ack)
        self->send(st.ack, st.counter.next);
    },
    [self, apps, reset](std::string& what) -> caf::result<std::string> {
      if (what != "hello")
        return make_error(ec::invalid_parameter, "expected hello");
      reset();
      if (!apps) {
        self->state.ack = caf::actor_cast<caf::actor>(self->current_sender());
        return std::string{"ok"};
      }
      auto rp = self->make_response_promise<std::string>();
      self->request(apps, std::chrono::seconds(5), atom::bind_v,
                    bind_request{query_by::name, "rtt.ack", 1000, false})
        .then(
          [self, rp](caf::actor& ack) mutable {
            self->state.ack = std::move(ack);
            rp.deliver(std::string{"ok"});
          },
          [rp](caf::error& err) mutable { rp.deliver(std::move(err)); });
      return rp;
    },
    [self](int32_t) -> caf::result<uint64_t, int64_t, double> {
      auto& c = self->state.counter;
      return {c.received, c.elapsed(), c.allocs_per_message()};
    },
  };
}

} // namespace herm::bench
