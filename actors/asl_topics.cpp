#include "actors/asl_state.hpp"

// Topics in the Application Support Layer's actor: local publications and
// their delivery to local subscribers (the topic table, actors/
// topic_table.hpp, decides what goes to other modules).

#include "caf/actor_cast.hpp"
#include "caf/timestamp.hpp"

#include "actors/asl_errors.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm::asl_detail {

void deliver_topic(asl_impl self, const std::string& name,
                   const topic_table::topic& t, module_id publisher,
                   uint32_t seq, const caf::message* msg,
                   const byte_buffer& payload) {
  auto& st = self->state;
  if (msg != nullptr)
    for (auto& sub : t.local_subs) {
      post(self, caf::actor_cast<caf::strong_actor_ptr>(sub), nullptr,
           caf::make_message_id(), *msg);
      ++st.stats.publications_delivered;
    }
  if (t.sample_subs.empty())
    return;
  auto sample = caf::make_message(topic_sample{
    name, publisher, seq, caf::make_timestamp(), payload});
  for (auto& sub : t.sample_subs) {
    post(self, caf::actor_cast<caf::strong_actor_ptr>(sub), nullptr,
         caf::make_message_id(), sample);
    ++st.stats.publications_delivered;
  }
}

namespace {

/// Publishes `payload` (the marshalled `msg`; `msg` empty when this
/// process cannot decode it) from this module.
void publish_local(asl_impl self, const std::string& topic, caf::message msg,
                   byte_buffer payload) {
  auto& st = self->state;
  auto typed = !msg.empty();
  auto& t = st.topics->publish(topic, msg, std::move(payload),
                               self->clock().now(), st.out);
  flush(self);
  deliver_topic(self, topic, t, st.self_id, t.seq, typed ? &t.last : nullptr,
                t.last_payload);
}

} // namespace

void on_publish_local(asl_impl self, const std::string& topic,
                      caf::message& msg) {
  auto& st = self->state;
  auto payload = marshal(self->system(), msg);
  if (asl_error::check_label("a topic", topic) || !payload
      || payload->size() > st.cfg.max_message) {
    ++st.stats.tx_refused;
    return;
  }
  publish_local(self, topic, msg, std::move(*payload));
}

caf::error on_publish_raw(asl_impl self, const std::string& topic,
                          byte_buffer& payload) {
  auto& st = self->state;
  if (auto err = asl_error::check_label("a topic", topic))
    return err;
  if (auto err = check_raw(payload))
    return err;
  if (payload.size() > st.cfg.max_message) {
    ++st.stats.tx_refused;
    return make_error(ec::packet_too_large,
                      std::to_string(payload.size()) + " bytes, above "
                        + std::to_string(st.cfg.max_message));
  }
  // Decoded only for local subscribers that take messages; a type this
  // process lacks still reaches the others.
  caf::message msg;
  auto* t = st.topics->find(topic);
  if (t != nullptr && !t->local_subs.empty())
    if (auto m = unmarshal(self->system(), payload.data(), payload.size(),
                           st.cfg.limits))
      msg = std::move(*m);
  publish_local(self, topic, std::move(msg), std::move(payload));
  return {};
}

} // namespace herm::asl_detail
