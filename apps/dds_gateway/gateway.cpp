#include "apps/dds_gateway/gateway.hpp"

#include <atomic>
#include <deque>
#include <map>
#include <memory>

#include <spdlog/spdlog.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/atoms.hpp"
#include "actors/runtime/error.hpp"
#include "actors/unexpected.hpp"

namespace herm::dds_gateway {

namespace {

using namespace std::chrono_literals;

// The gateway's own messages (atoms: at most 10 of [A-Za-z0-9_]).
using dds_in_atom = caf::atom_constant<caf::atom("gw_dds_in")>;
using reject_atom = caf::atom_constant<caf::atom("gw_reject")>;
using out_atom = caf::atom_constant<caf::atom("gw_out")>;
using ready_atom = caf::atom_constant<caf::atom("gw_ready")>;

/// Remembered own publications per `both` mapping (see gateway.hpp).
constexpr size_t max_echoes = 64;
/// Samples one dds_take loans at most.
constexpr int32_t take_batch = 16;

// -- the DDS side ---------------------------------------------------------------------

/// What a reader's listener needs; owned by the bridge, stable in memory.
struct reader_ctx {
  caf::weak_actor_ptr gateway;
  uint32_t index = 0;
  const mapping* m = nullptr;
  /// Samples taken on this reader (Cyclone's thread only).
  uint64_t count = 0;
  std::atomic<uint32_t>* backlog = nullptr;
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
  std::vector<std::unique_ptr<reader_ctx>> contexts;
  std::atomic<uint32_t> backlog{0};
  std::atomic<uint64_t> backlog_dropped{0};

  ~bridge() {
    for (auto& kv : participants)
      dds_delete(kv.second);
  }
};

/// Cyclone's receive thread: takes what the reader holds, converts it and
/// hands it to the gateway. Never waits.
void on_data_available(dds_entity_t reader, void* arg) {
  auto* c = static_cast<reader_ctx*>(arg);
  auto gw = caf::actor_cast<caf::actor>(c->gateway.lock());
  void* samples[take_batch];
  dds_sample_info_t infos[take_batch];
  for (;;) {
    samples[0] = nullptr; // loaned by Cyclone
    auto n = dds_take(reader, samples, infos, take_batch, take_batch);
    if (n <= 0)
      return;
    for (int32_t i = 0; i < n; ++i) {
      if (!infos[i].valid_data || !gw)
        continue;
      if (c->backlog->fetch_add(1) >= c->max_backlog) {
        c->backlog->fetch_sub(1);
        c->backlog_dropped->fetch_add(1);
        continue;
      }
      auto v = c->m->type->from_dds(samples[i], c->m->conv, c->count++);
      if (v)
        caf::anon_send(gw, dds_in_atom::value, c->index, std::move(*v));
      else
        caf::anon_send(gw, reject_atom::value, c->index, render(v.error()));
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

/// Creates every entity of `b` for the actor `gw`.
caf::error open_dds(bridge& b, const caf::actor& gw) {
  auto n = b.cfg.mappings.size();
  b.writers.assign(n, 0);
  b.readers.assign(n, 0);
  for (size_t i = 0; i < n; ++i) {
    auto& m = b.cfg.mappings[i];
    auto where = "DDS topic '" + m.dds_topic + "' (domain "
                 + std::to_string(m.domain) + ")";
    auto p = b.participants.find(m.domain);
    if (p == b.participants.end()) {
      auto e = dds_create_participant(m.domain, nullptr, nullptr);
      if (e < 0)
        return dds_failure("DDS domain " + std::to_string(m.domain), e);
      p = b.participants.emplace(m.domain, e).first;
    }
    auto topic = dds_create_topic(p->second, m.type->descriptor,
                                  m.dds_topic.c_str(), nullptr, nullptr);
    if (topic < 0)
      return dds_failure(where, topic);
    std::unique_ptr<dds_qos_t, void (*)(dds_qos_t*)> qos{make_qos(m),
                                                        dds_delete_qos};
    if (m.to_dds()) {
      b.writers[i] = dds_create_writer(p->second, topic, qos.get(), nullptr);
      if (b.writers[i] < 0)
        return dds_failure(where + ", writer", b.writers[i]);
    }
    if (m.from_dds()) {
      auto c = std::make_unique<reader_ctx>();
      c->gateway = caf::actor_cast<caf::weak_actor_ptr>(gw);
      c->index = static_cast<uint32_t>(i);
      c->m = &m;
      c->backlog = &b.backlog;
      c->backlog_dropped = &b.backlog_dropped;
      c->max_backlog = b.cfg.max_backlog;
      auto* l = dds_create_listener(c.get());
      dds_lset_data_available(l, on_data_available);
      b.readers[i] = dds_create_reader(p->second, topic, qos.get(), l);
      dds_delete_listener(l);
      b.contexts.push_back(std::move(c));
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

struct gateway_state {
  static inline const char* name = "herm.dds_gateway";
  std::shared_ptr<bridge> dds;
  module_handles module;
  gateway_stats stats;
  /// Per mapping: what it published on HERM and has not seen come back.
  std::vector<std::deque<std::string>> echoes;
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
  self->set_default_handler(log_unexpected);
  return {
    [self](ready_atom) { subscribe_all(self); },
    [self](dds_in_atom, uint32_t i, caf::message& v) {
      auto& s = self->state;
      s.dds->backlog.fetch_sub(1);
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
      s.dds->backlog.fetch_sub(1);
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
  if (auto err = open_dds(*b, gw)) {
    caf::anon_send_exit(gw, caf::exit_reason::user_shutdown);
    return err;
  }
  for (auto& m : b->cfg.mappings)
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
}

} // namespace herm::dds_gateway
