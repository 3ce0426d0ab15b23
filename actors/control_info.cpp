#include "actors/control_info.hpp"

#include <string>
#include <vector>

#include "caf/event_based_actor.hpp"
#include "caf/local_actor.hpp"

#include "actors/control.hpp"
#include "actors/control_json.hpp"
#include "actors/control_topics.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm {

namespace {

using namespace control_json;

/// The read-only herm.info APO (actors/control.hpp): "types" and "topics",
/// answered from this process's descriptions and the ASL's topic table.
caf::behavior info_fun(caf::event_based_actor* self, app_support_actor apps) {
  return {
    [self, apps](std::string& text) -> caf::result<std::string> {
      auto req = json::parse(text, nullptr, false);
      auto cmd = req.is_object() ? string_field(req, "cmd") : std::string{};
      if (cmd == "types")
        return ok_reply(control_topics::descriptions_json(req["names"]));
      if (cmd != "topics")
        return error_reply("unknown_command",
                           std::string{info_apo_name}
                             + " answers \"types\" and \"topics\" only");
      auto rp = self->make_response_promise<std::string>();
      self->request(apps, default_control_timeout, atom::get_v, atom::topics_v)
        .then(
          [rp](std::vector<topic_info>& rows) mutable {
            rp.deliver(ok_reply(control_topics::topics_json(rows)));
          },
          [rp](caf::error& err) mutable { rp.deliver(error_reply(err)); });
      return rp;
    },
  };
}

} // namespace

caf::actor spawn_info_apo(caf::local_actor* parent, app_support_actor apps) {
  return parent->spawn<caf::linked>(info_fun, std::move(apps));
}

} // namespace herm
