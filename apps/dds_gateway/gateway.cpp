#include "apps/dds_gateway/gateway.hpp"

#include <atomic>
#include <deque>
#include <map>
#include <memory>
#include <stdexcept>

#include <spdlog/spdlog.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/atoms.hpp"
#include "actors/runtime/error.hpp"
#include "actors/type_description.hpp"
#include "actors/unexpected.hpp"
#include "apps/dds_gateway/service_client.hpp"

namespace herm::dds_gateway {

namespace {

using namespace std::chrono_literals;

// The gateway's own messages (atoms: at most 10 of [A-Za-z0-9_]).
using dds_in_atom = caf::atom_constant<caf::atom("gw_dds_in")>;
using reject_atom = caf::atom_constant<caf::atom("gw_reject")>;
using out_atom = caf::atom_constant<caf::atom("gw_out")>;
using ready_atom = caf::atom_constant<caf::atom("gw_ready")>;
/// A DDS service request for a server mapping: index, guid, seq, request.
using svc_request_atom = caf::atom_constant<caf::atom("gw_svc_rq")>;

/// Remembered own publications per `both` mapping (see gateway.hpp).
constexpr size_t max_echoes = 64;
/// Samples one dds_take loans at most.
constexpr int32_t take_batch = 16;

// -- the DDS side ---------------------------------------------------------------------

/// What a reader reads: a topic's samples, a server mapping's requests or
/// a client mapping's replies.
enum class reads { topic, requests, replies };

/// What a reader's listener needs; owned by the bridge, stable in memory.
struct reader_ctx {
  /// The gateway, or a client mapping's proxy (replies).
  caf::weak_actor_ptr target;
  /// The gateway: counts what does not convert.
  caf::weak_actor_ptr gateway;
  reads what = reads::topic;
  uint32_t index = 0;
  const mapping* m = nullptr;
  /// Samples taken on this reader (Cyclone's thread only).
  uint64_t count = 0;
  /// Replies: the client's own guid (others' replies are not taken up).
  uint64_t guid = 0;
  std::shared_ptr<std::atomic<uint32_t>> backlog;
  std::atomic<uint64_t>* backlog_dropped = nullptr;
  uint32_t max_backlog = 0;
};

/// The gateway's DDS entities. Built by spawn_dds_gateway before the actor
/// hears gw_ready, then read-only; deleting it deletes the participants,
/// which waits for running listeners to return.
struct bridge {
  gateway_config cfg;
  std::map<uint32_t, dds_entity_t> participants;
  /// Per mapping; 0 where the mapping has none.
  std::vector<dds_entity_t> writers;
  std::vector<dds_entity_t> readers;
  /// Per mapping: a client mapping's proxy APO.
  std::vector<caf::actor> clients;
  std::vector<std::unique_ptr<reader_ctx>> contexts;
  std::shared_ptr<std::atomic<uint32_t>> backlog
    = std::make_shared<std::atomic<uint32_t>>(0);
  std::atomic<uint64_t> backlog_dropped{0};

  ~bridge() {
    for (auto& kv : participants)
      dds_delete(kv.second);
  }
};

/// One sample to its actor, converted (Cyclone's thread).
void hand_over(reader_ctx* c, const caf::actor& to, const void* sample) {
  auto& m = *c->m;
  caf::expected<caf::message> v{caf::message{}};
  request_header h;
  switch (c->what) {
    case reads::topic:
      v = m.type->from_dds(sample, m.conv, c->count++);
      break;
    case reads::requests:
      v = m.service->request_from_dds(sample, h);
      if (v) {
        caf::anon_send(to, svc_request_atom::value, c->index, h.guid, h.seq,
                       std::move(*v));
        return;
      }
      break;
    case reads::replies:
      v = m.service->reply_from_dds(sample, h);
      if (v) {
        caf::anon_send(to, svc_reply_atom::value, h.guid, h.seq,
                       std::move(*v));
        return;
      }
      break;
  }
  if (v) {
    caf::anon_send(to, dds_in_atom::value, c->index, std::move(*v));
    return;
  }
  // Counted by the gateway, whoever the sample was for.
  if (auto gw = caf::actor_cast<caf::actor>(c->gateway.lock()))
    caf::anon_send(gw, reject_atom::value, c->index, render(v.error()));
  else
    c->backlog->fetch_sub(1);
}

/// Whether a reply sample is for this client (others' are not taken up).
bool for_us(const reader_ctx* c, const void* sample) {
  if (c->what != reads::replies)
    return true;
  request_header h;
  return c->m->service->reply_from_dds(sample, h) && h.guid == c->guid;
}

/// Cyclone's receive thread: takes what the reader holds, converts it and
/// hands it to the gateway (or a client's proxy). Never waits.
void on_data_available(dds_entity_t reader, void* arg) {
  auto* c = static_cast<reader_ctx*>(arg);
  auto gw = caf::actor_cast<caf::actor>(c->target.lock());
  void* samples[take_batch];
  dds_sample_info_t infos[take_batch];
  for (;;) {
    samples[0] = nullptr; // loaned by Cyclone
    auto n = dds_take(reader, samples, infos, take_batch, take_batch);
    if (n <= 0)
      return;
    for (int32_t i = 0; i < n; ++i) {
      if (!infos[i].valid_data || !gw || !for_us(c, samples[i]))
        continue;
      if (c->backlog->fetch_add(1) >= c->max_backlog) {
        c->backlog->fetch_sub(1);
        c->backlog_dropped->fetch_add(1);
        continue;
      }
      hand_over(c, gw, samples[i]);
    }
    dds_return_loan(reader, samples, n);
  }
}

caf::error dds_failure(const std::string& what, dds_return_t rc) {
  return make_error(ec::device_unavailable,
                    what + ": " + dds_strretcode(rc));
}

/// ROS 2's QoS names on a mapping's readers and writers, XCDR1 as
/// rmw_cyclonedds, and never matching the gateway's own participant.
dds_qos_t* make_qos(const mapping& m) {
  auto* q = dds_create_qos();
  dds_qset_reliability(q,
                       m.reliable ? DDS_RELIABILITY_RELIABLE
                                  : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, m.depth);
  dds_qset_durability(q, m.transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL
                                           : DDS_DURABILITY_VOLATILE);
  dds_qset_ignorelocal(q, DDS_IGNORELOCAL_PARTICIPANT);
  dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(q, 1, &xcdr1);
  return q;
}

/// A reader of `topic` for mapping `i` whose listener hands samples to
/// `target`.
dds_entity_t open_reader(bridge& b, size_t i, dds_entity_t pp,
                         dds_entity_t topic, const dds_qos_t* qos, reads what,
                         const caf::actor& target, const caf::actor& gw,
                         uint64_t guid = 0) {
  auto c = std::make_unique<reader_ctx>();
  c->target = caf::actor_cast<caf::weak_actor_ptr>(target);
  c->gateway = caf::actor_cast<caf::weak_actor_ptr>(gw);
  c->what = what;
  c->index = static_cast<uint32_t>(i);
  c->m = &b.cfg.mappings[i];
  c->guid = guid;
  c->backlog = b.backlog;
  c->backlog_dropped = &b.backlog_dropped;
  c->max_backlog = b.cfg.max_backlog;
  auto* l = dds_create_listener(c.get());
  dds_lset_data_available(l, on_data_available);
  auto r = dds_create_reader(pp, topic, qos, l);
  dds_delete_listener(l);
  b.contexts.push_back(std::move(c));
  return r;
}

/// A service mapping's two topics, its writer and its reader (a client's
/// reader feeds its proxy, spawned here).
caf::error open_service(bridge& b, size_t i, dds_entity_t pp,
                        const dds_qos_t* qos, const caf::actor& gw,
                        caf::actor_system& sys) {
  auto& m = b.cfg.mappings[i];
  auto where = "DDS service '" + m.dds_topic + "' (domain "
               + std::to_string(m.domain) + ")";
  auto rq = dds_create_topic(pp, m.service->request_descriptor,
                             m.request_topic().c_str(), nullptr, nullptr);
  if (rq < 0)
    return dds_failure(where + ", " + m.request_topic(), rq);
  auto rr = dds_create_topic(pp, m.service->reply_descriptor,
                             m.reply_topic().c_str(), nullptr, nullptr);
  if (rr < 0)
    return dds_failure(where + ", " + m.reply_topic(), rr);
  if (m.server) {
    b.writers[i] = dds_create_writer(pp, rr, qos, nullptr);
    if (b.writers[i] < 0)
      return dds_failure(where + ", reply writer", b.writers[i]);
    b.readers[i] = open_reader(b, i, pp, rq, qos, reads::requests, gw, gw);
    if (b.readers[i] < 0)
      return dds_failure(where + ", request reader", b.readers[i]);
    return caf::none;
  }
  b.writers[i] = dds_create_writer(pp, rq, qos, nullptr);
  if (b.writers[i] < 0)
    return dds_failure(where + ", request writer", b.writers[i]);
  dds_instance_handle_t guid = 0;
  dds_get_instance_handle(b.writers[i], &guid);
  b.clients[i] = spawn_service_client(sys, m, b.writers[i], guid, b.backlog);
  b.readers[i] = open_reader(b, i, pp, rr, qos, reads::replies, b.clients[i],
                             gw, guid);
  if (b.readers[i] < 0)
    return dds_failure(where + ", reply reader", b.readers[i]);
  return caf::none;
}

/// Creates every entity of `b` for the actor `gw`.
caf::error open_dds(bridge& b, const caf::actor& gw, caf::actor_system& sys) {
  auto n = b.cfg.mappings.size();
  b.writers.assign(n, 0);
  b.readers.assign(n, 0);
  b.clients.assign(n, caf::actor{});
  for (size_t i = 0; i < n; ++i) {
    auto& m = b.cfg.mappings[i];
    auto p = b.participants.find(m.domain);
    if (p == b.participants.end()) {
      auto e = dds_create_participant(m.domain, nullptr, nullptr);
      if (e < 0)
        return dds_failure("DDS domain " + std::to_string(m.domain), e);
      p = b.participants.emplace(m.domain, e).first;
    }
    std::unique_ptr<dds_qos_t, void (*)(dds_qos_t*)> qos{make_qos(m),
                                                        dds_delete_qos};
    if (m.service != nullptr) {
      if (auto err = open_service(b, i, p->second, qos.get(), gw, sys))
        return err;
      continue;
    }
    auto where = "DDS topic '" + m.dds_topic + "' (domain "
                 + std::to_string(m.domain) + ")";
    auto topic = dds_create_topic(p->second, m.type->descriptor,
                                  m.dds_topic.c_str(), nullptr, nullptr);
    if (topic < 0)
      return dds_failure(where, topic);
    if (m.to_dds()) {
      b.writers[i] = dds_create_writer(p->second, topic, qos.get(), nullptr);
      if (b.writers[i] < 0)
        return dds_failure(where + ", writer", b.writers[i]);
    }
    if (m.from_dds()) {
      b.readers[i] = open_reader(b, i, p->second, topic, qos.get(),
                                 reads::topic, gw, gw);
      if (b.readers[i] < 0)
        return dds_failure(where + ", reader", b.readers[i]);
    }
  }
  return caf::none;
}

// -- the HERM side --------------------------------------------------------------------

/// Subscribed to one HERM topic: hands every value to the gateway with the
/// mapping's index (a subscriber receives values without their topic).
caf::behavior relay(caf::event_based_actor* self, caf::actor gw,
                    uint32_t index) {
  self->set_default_handler(
    [gw, index](caf::scheduled_actor*,
                caf::message_view& x) -> caf::result<caf::message> {
      caf::anon_send(gw, out_atom::value, index, x.move_content_to_message());
      return caf::message{};
    });
  return {
    [](ready_atom) {},
  };
}

/// A DDS request waiting for its server mapping's APO to be bound.
struct held_request {
  request_header h;
  caf::message req;
};

/// A server mapping's binding to its HERM APO, made at the first request
/// (and again after a failure); requests wait for it, at most max_held.
struct served_apo {
  static constexpr size_t max_held = 16;
  /// Requests of one mapping the APO has not answered yet, at most.
  static constexpr size_t max_in_flight = 64;
  caf::actor proxy;
  bool binding = false;
  size_t in_flight = 0;
  std::deque<held_request> held;
};

struct gateway_state {
  static inline const char* name = "herm.dds_gateway";
  std::shared_ptr<bridge> dds;
  module_handles module;
  gateway_stats stats;
  /// Per mapping: what it published on HERM and has not seen come back.
  std::vector<std::deque<std::string>> echoes;
  /// Per mapping: a server mapping's APO.
  std::vector<served_apo> served;
};

using gateway_actor = caf::stateful_actor<gateway_state>;

void subscribe_all(gateway_actor* self) {
  auto& st = self->state;
  auto& maps = st.dds->cfg.mappings;
  for (size_t i = 0; i < maps.size(); ++i) {
    if (!maps[i].to_dds())
      continue;
    auto r = self->spawn<caf::linked>(relay, caf::actor_cast<caf::actor>(self),
                                      static_cast<uint32_t>(i));
    auto topic = maps[i].herm_topic;
    self->request(st.module.apps, 5s, atom::subscribe_v, topic, r)
      .then([topic] { spdlog::debug("dds_gateway: subscribed to '{}'", topic); },
            [topic](caf::error& err) {
              spdlog::warn("dds_gateway: cannot subscribe to '{}': {}", topic,
                           render(err));
            });
  }
}

// -- services -------------------------------------------------------------------------

void serve_failed(gateway_actor* self, const mapping& m,
                  const std::string& why) {
  auto& st = self->state;
  ++st.stats.serve_failed;
  spdlog::warn("dds_gateway: service '{}' -> APO '{}': no reply ({} so far): {}",
               m.dds_topic, m.apo, st.stats.serve_failed, why);
}

/// Requests the APO of server mapping `i` and writes its answer as the
/// reply to `h`.
void serve(gateway_actor* self, uint32_t i, request_header h,
           caf::message req) {
  auto& m = self->state.dds->cfg.mappings[i];
  auto& sv = self->state.served[i];
  if (sv.in_flight >= served_apo::max_in_flight) {
    serve_failed(self, m, std::to_string(served_apo::max_in_flight)
                            + " requests in flight already");
    return;
  }
  ++sv.in_flight;
  m.service->call(
    self, sv.proxy, m.timeout, std::move(req),
    [self, i, h](caf::expected<caf::message> resp) {
      auto& st = self->state;
      --st.served[i].in_flight;
      auto& mi = st.dds->cfg.mappings[i];
      if (!resp) {
        serve_failed(self, mi, render(resp.error()));
        return;
      }
      std::vector<unsigned char> sample(mi.service->reply_size);
      if (auto err = mi.service->reply_to_dds(*resp, h, sample.data())) {
        serve_failed(self, mi, render(err));
        return;
      }
      if (auto rc = dds_write(st.dds->writers[i], sample.data()); rc < 0) {
        ++st.stats.write_failed;
        serve_failed(self, mi, std::string{"dds_write: "} + dds_strretcode(rc));
        return;
      }
      ++st.stats.served;
    });
}

/// Binds server mapping `i`'s APO unless bound or binding; then serves
/// what was held.
void bind_served(gateway_actor* self, uint32_t i) {
  auto& sv = self->state.served[i];
  if (sv.proxy || sv.binding)
    return;
  sv.binding = true;
  auto& m = self->state.dds->cfg.mappings[i];
  self->request(self->state.module.apps, 5s, atom::bind_v,
                bind_request{query_by::name, m.apo, 1000, true, false})
    .then(
      [self, i](caf::actor& proxy) {
        auto& s = self->state.served[i];
        s.binding = false;
        s.proxy = proxy;
        while (!s.held.empty()) {
          auto x = std::move(s.held.front());
          s.held.pop_front();
          serve(self, i, x.h, std::move(x.req));
        }
      },
      [self, i](caf::error& err) {
        auto& s = self->state.served[i];
        s.binding = false;
        auto& mi = self->state.dds->cfg.mappings[i];
        while (!s.held.empty()) {
          s.held.pop_front();
          serve_failed(self, mi, "cannot bind APO '" + mi.apo + "': "
                                   + render(err));
        }
      });
}

void on_service_request(gateway_actor* self, uint32_t i, request_header h,
                        caf::message& req) {
  auto& st = self->state;
  auto& sv = st.served[i];
  if (sv.proxy) {
    serve(self, i, h, std::move(req));
    return;
  }
  if (sv.held.size() >= served_apo::max_held) {
    serve_failed(self, st.dds->cfg.mappings[i],
                 "APO not bound yet and " + std::to_string(served_apo::max_held)
                   + " requests waiting");
    return;
  }
  sv.held.push_back({h, std::move(req)});
  bind_served(self, i);
}

/// Registers each client mapping's proxy APO under its name.
void register_clients(gateway_actor* self) {
  auto& st = self->state;
  auto& maps = st.dds->cfg.mappings;
  for (size_t i = 0; i < maps.size(); ++i) {
    auto& proxy = st.dds->clients[i];
    if (!proxy)
      continue;
    self->link_to(proxy);
    auto name = maps[i].herm_topic;
    self->request(st.module.apps, 5s, atom::add_v, name,
                  std::string{"ros."} + maps[i].service->name, proxy)
      .then([name](apo_ref&) {
              spdlog::info("dds_gateway: APO '{}' calls the DDS service", name);
            },
            [name](caf::error& err) {
              spdlog::warn("dds_gateway: cannot register APO '{}': {}", name,
                           render(err));
            });
  }
}

// -- topics ---------------------------------------------------------------------------

void to_dds(gateway_actor* self, uint32_t i, caf::message& v) {
  auto& st = self->state;
  auto& m = st.dds->cfg.mappings[i];
  if (m.from_dds()) {
    auto& echoes = st.echoes[i];
    if (!echoes.empty() && echoes.front() == caf::to_string(v)) {
      echoes.pop_front();
      ++st.stats.looped_back;
      return;
    }
  }
  std::vector<unsigned char> sample(m.type->sample_size);
  if (auto err = m.type->to_dds(v, m.conv, dds_time(), sample.data())) {
    ++st.stats.herm_rejected;
    spdlog::warn("dds_gateway: '{}' -> {}: dropped a value ({} so far): {}",
                 m.herm_topic, m.dds_topic, st.stats.herm_rejected,
                 render(err));
    return;
  }
  auto rc = dds_write(st.dds->writers[i], sample.data());
  if (rc < 0) {
    ++st.stats.write_failed;
    spdlog::warn("dds_gateway: writing {} failed ({} so far): {}", m.dds_topic,
                 st.stats.write_failed, dds_strretcode(rc));
    return;
  }
  ++st.stats.to_dds;
}

caf::behavior gateway(gateway_actor* self, std::shared_ptr<bridge> dds,
                      module_handles module) {
  auto& st = self->state;
  st.dds = std::move(dds);
  st.module = std::move(module);
  st.echoes.resize(st.dds->cfg.mappings.size());
  st.served.resize(st.dds->cfg.mappings.size());
  self->set_default_handler(log_unexpected);
  return {
    [self](ready_atom) {
      subscribe_all(self);
      register_clients(self);
    },
    [self](svc_request_atom, uint32_t i, uint64_t guid, int64_t seq,
           caf::message& req) {
      self->state.dds->backlog->fetch_sub(1);
      on_service_request(self, i, request_header{guid, seq}, req);
    },
    [self](dds_in_atom, uint32_t i, caf::message& v) {
      auto& s = self->state;
      s.dds->backlog->fetch_sub(1);
      auto& m = s.dds->cfg.mappings[i];
      if (m.to_dds()) {
        auto& echoes = s.echoes[i];
        if (echoes.size() >= max_echoes)
          echoes.pop_front();
        echoes.push_back(caf::to_string(v));
      }
      self->send(s.module.apps, atom::publish_v, m.herm_topic, std::move(v));
      ++s.stats.from_dds;
    },
    [self](reject_atom, uint32_t i, std::string& why) {
      auto& s = self->state;
      s.dds->backlog->fetch_sub(1);
      ++s.stats.dds_rejected;
      auto& m = s.dds->cfg.mappings[i];
      spdlog::warn("dds_gateway: {} -> '{}': dropped a sample ({} so far): {}",
                   m.dds_topic, m.herm_topic, s.stats.dds_rejected, why);
    },
    [self](out_atom, uint32_t i, caf::message& v) { to_dds(self, i, v); },
    [self](atom::get, atom::stats) {
      auto s = self->state.stats;
      s.backlog_dropped = self->state.dds->backlog_dropped.load();
      return s;
    },
  };
}

} // namespace

caf::expected<caf::actor> spawn_dds_gateway(caf::actor_system& sys,
                                            const module_handles& module,
                                            gateway_config cfg) {
  auto b = std::make_shared<bridge>();
  b->cfg = std::move(cfg);
  auto gw = sys.spawn(gateway, b, module);
  if (auto err = open_dds(*b, gw, sys)) {
    caf::anon_send_exit(gw, caf::exit_reason::user_shutdown);
    for (auto& c : b->clients)
      if (c)
        caf::anon_send_exit(c, caf::exit_reason::user_shutdown);
    return err;
  }
  for (auto& m : b->cfg.mappings)
    if (m.service != nullptr)
      spdlog::info("dds_gateway: {} DDS service {} ({}, {} / {}, domain {}, "
                   "timeout {} ms)",
                   m.server ? "APO '" + m.apo + "' offered as"
                            : "APO '" + m.herm_topic + "' calls",
                   m.dds_topic, m.service->name, m.request_topic(),
                   m.reply_topic(), m.domain, m.timeout.count());
    else
      spdlog::info("dds_gateway: '{}' {} DDS {} ({}, domain {}, {}, depth {}, {})",
                 m.herm_topic,
                 m.dir == direction::both       ? "<->"
                 : m.dir == direction::to_dds ? "->"
                                                : "<-",
                 m.dds_topic, dds_type_name(m.type->name), m.domain,
                 m.reliable ? "reliable" : "best_effort", m.depth,
                 m.transient_local ? "transient_local" : "volatile");
  caf::anon_send(gw, ready_atom::value);
  return gw;
}

void add_gateway_types(caf::actor_system_config& cfg) {
  cfg.add_message_types<caf::id_block::herm_gateway>();
  // Field names, so that hermctl prints and parses them by name (a twist
  // on cmd_vel with `hermctl topic echo`).
  for (auto err :
       {describe_type<vector3>("herm::dds_gateway::vector3", {"x", "y", "z"}),
        describe_type<twist>("herm::dds_gateway::twist", {"linear", "angular"}),
        describe_type<gateway_stats>(
          "herm::dds_gateway::gateway_stats",
          {"to_dds", "from_dds", "dds_rejected", "herm_rejected", "looped_back",
           "backlog_dropped", "write_failed", "served", "serve_failed"})})
    if (err)
      throw std::logic_error(render(err));
}

} // namespace herm::dds_gateway
