#include "actors/module.hpp"

#include "caf/actor_system.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm {

caf::expected<module_handles> start_module(caf::actor_system& sys,
                                           const module_config& cfg,
                                           std::chrono::milliseconds timeout) {
  module_handles m;
  m.io = spawn_io_manager(sys);
  caf::scoped_actor self{sys};
  caf::error err;
  for (size_t i = 0; i < cfg.devices.size(); ++i) {
    auto& dev = cfg.devices[i];
    self->request(m.io, timeout, atom::add_v, dev)
      .receive([](device_info&) {}, [&](caf::error& e) { err = e; });
    if (!err)
      self->request(m.io, timeout, atom::open_v,
                    channel_request{dev.name, "*", true})
        .receive([](channel_actor&, channel_info&) {},
                 [&](caf::error& e) { err = e; });
    if (err) {
      self->send_exit(m.io, caf::exit_reason::user_shutdown);
      if (i < cfg.device_origins.size() && !cfg.device_origins[i].empty())
      {
        auto& ctx = err.context();
        auto what = ctx.match_elements<std::string>() ? ctx.get_as<std::string>(0)
                                                      : caf::to_string(ctx);
        return caf::error{err.code(), err.category(),
                          caf::make_message(cfg.device_origins[i] + ": " + what)};
      }
      return err;
    }
  }
  // The agent subscribes to the IO manager and learns the open channels.
  m.agent = spawn_routing_agent(sys, m.io, cfg.routing);
  m.apps = spawn_app_support(sys, m.agent, cfg.apps);
  return m;
}

void stop_module(const module_handles& m) {
  caf::anon_send_exit(m.apps, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(m.agent, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(m.io, caf::exit_reason::user_shutdown);
}

} // namespace herm
