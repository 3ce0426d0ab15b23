#include "apps/dds_gateway/service_client.hpp"

#include <map>
#include <vector>

#include <spdlog/spdlog.h>

#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/response_promise.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/error.hpp"

namespace herm::dds_gateway {

namespace {

using timeout_atom = caf::atom_constant<caf::atom("gw_svc_to")>;

struct client_state {
  static inline const char* name = "herm.dds_service_client";
  mapping m;
  dds_entity_t writer = 0;
  uint64_t guid = 0;
  int64_t seq = 0;
  std::map<int64_t, caf::response_promise> pending;
  std::shared_ptr<std::atomic<uint32_t>> backlog;
};

using client_actor = caf::stateful_actor<client_state>;

bool server_matched(dds_entity_t writer) {
  dds_publication_matched_status_t st;
  return dds_get_publication_matched_status(writer, &st) == 0
         && st.current_count > 0;
}

caf::result<caf::message> call(client_actor* self, caf::message req) {
  auto& st = self->state;
  auto& m = st.m;
  auto what = "DDS service '" + m.dds_topic + "' (domain "
              + std::to_string(m.domain) + ")";
  if (st.pending.size() >= max_calls)
    return make_error(ec::queue_full, what + ": " + std::to_string(max_calls)
                                        + " calls outstanding");
  if (!server_matched(st.writer))
    return make_error(app_ec::not_found, what + ": no server");
  request_header h{st.guid, ++st.seq};
  std::vector<unsigned char> sample(m.service->request_size);
  if (auto err = m.service->request_to_dds(req, h, sample.data()))
    return err;
  if (auto rc = dds_write(st.writer, sample.data()); rc < 0)
    return make_error(ec::device_failed,
                      what + ": dds_write: " + dds_strretcode(rc));
  auto rp = self->make_response_promise();
  st.pending.emplace(h.seq, rp);
  self->delayed_send(self, m.timeout, timeout_atom::value, h.seq);
  return rp;
}

caf::behavior service_client(client_actor* self, mapping m,
                             dds_entity_t writer, uint64_t guid,
                             std::shared_ptr<std::atomic<uint32_t>> backlog) {
  auto& st = self->state;
  st.m = std::move(m);
  st.writer = writer;
  st.guid = guid;
  st.backlog = std::move(backlog);
  // Any other message is a call.
  self->set_default_handler(
    [self](caf::scheduled_actor*,
           caf::message_view& x) -> caf::result<caf::message> {
      return call(self, x.move_content_to_message());
    });
  return {
    [self](svc_reply_atom, uint64_t reply_guid, int64_t seq, caf::message& resp) {
      auto& s = self->state;
      s.backlog->fetch_sub(1);
      if (reply_guid != s.guid)
        return;
      auto i = s.pending.find(seq);
      if (i == s.pending.end())
        return;
      i->second.deliver(std::move(resp));
      s.pending.erase(i);
    },
    [self](timeout_atom, int64_t seq) {
      auto& s = self->state;
      auto i = s.pending.find(seq);
      if (i == s.pending.end())
        return;
      i->second.deliver(make_error(
        ec::timeout, "DDS service '" + s.m.dds_topic + "' did not answer in "
                       + std::to_string(s.m.timeout.count()) + " ms"));
      s.pending.erase(i);
    },
  };
}

} // namespace

caf::actor spawn_service_client(caf::actor_system& sys, mapping m,
                                dds_entity_t writer, uint64_t guid,
                                std::shared_ptr<std::atomic<uint32_t>> backlog) {
  return sys.spawn(service_client, std::move(m), writer, guid,
                   std::move(backlog));
}

} // namespace herm::dds_gateway
