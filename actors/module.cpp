#include "actors/module.hpp"

#include <map>

#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm {

namespace {

// -- supervisor ------------------------------------------------------------------

struct supervisor_state {
  static inline const char* name = "herm.module";
  /// The core actors, by address, and their names.
  std::map<caf::actor_addr, std::string> watched;
  std::function<void(const module_failure&)> on_failure;
};

/// Watches the core actors (and whatever watch_module_actor adds). Ends
/// with user_shutdown when stopped (stop_module sends it first, as an exit
/// message, which overtakes the down messages of the actors it stops);
/// ends with the failed actor's reason otherwise.
caf::behavior supervisor(caf::stateful_actor<supervisor_state>* self,
                         std::function<void(const module_failure&)> on_failure) {
  self->state.on_failure = std::move(on_failure);
  self->set_down_handler([self](caf::down_msg& msg) {
    auto& st = self->state;
    auto i = st.watched.find(msg.source);
    if (i == st.watched.end())
      return;
    auto name = i->second;
    st.watched.erase(i);
    if (msg.reason == caf::exit_reason::user_shutdown)
      return; // stopped on purpose by its owner
    auto reason = msg.reason ? msg.reason
                             : caf::make_error(caf::exit_reason::normal);
    if (st.on_failure)
      st.on_failure(module_failure{name, reason});
    auto& ctx = reason.context();
    auto what = ctx.match_elements<std::string>() ? ctx.get_as<std::string>(0)
                : ctx.empty()                     ? std::string{}
                                                  : caf::to_string(ctx);
    self->quit(caf::error{reason.code(), reason.category(),
                          caf::make_message(name + (what.empty() ? "" : ": ")
                                            + what)});
  });
  return {
    [self](atom::add, caf::actor& a, std::string& name) {
      if (!a)
        return;
      self->state.watched.emplace(a.address(), std::move(name));
      self->monitor(a);
    },
  };
}

} // namespace

caf::expected<module_handles> start_module(caf::actor_system& sys,
                                           const module_config& cfg,
                                           std::chrono::milliseconds timeout) {
  module_handles m;
  // The agent publishes its established routes and its receivers;
  // application support sends on them, and the channels hand packets for
  // those receivers straight to them (routing/fast_routes.hpp).
  auto routing = cfg.routing;
  auto apps = cfg.apps;
  if (!routing.fast_routes)
    routing.fast_routes = std::make_shared<route_cell>();
  apps.fast_routes = routing.fast_routes;
  m.io = spawn_io_manager(sys, {},
                          std::make_shared<fast_receiver>(routing.fast_routes));
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
  m.agent = spawn_routing_agent(sys, m.io, std::move(routing));
  m.apps = spawn_app_support(sys, m.agent, std::move(apps));
  m.supervisor = sys.spawn(supervisor, cfg.on_failure);
  watch_module_actor(m, caf::actor_cast<caf::actor>(m.io), "herm.io");
  watch_module_actor(m, caf::actor_cast<caf::actor>(m.agent), "herm.routing");
  watch_module_actor(m, caf::actor_cast<caf::actor>(m.apps), "herm.apps");
  return m;
}

void watch_module_actor(const module_handles& m, caf::actor a,
                        std::string name) {
  if (m.supervisor)
    caf::anon_send(m.supervisor, atom::add_v, std::move(a), std::move(name));
}

void stop_module(const module_handles& m) {
  if (m.supervisor)
    caf::anon_send_exit(m.supervisor, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(m.apps, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(m.agent, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(m.io, caf::exit_reason::user_shutdown);
}

} // namespace herm

namespace herm {

// -- running_module --------------------------------------------------------------

running_module::running_module(running_module&& other) noexcept
  : m_(other.release()) {
  // nop
}

running_module& running_module::operator=(running_module&& other) noexcept {
  if (this != &other) {
    stop();
    m_ = other.release();
  }
  return *this;
}

running_module::~running_module() {
  stop();
}

void running_module::stop(std::chrono::milliseconds timeout) {
  if (!m_.io)
    return;
  auto m = release();
  caf::scoped_actor self{m.io->home_system()};
  std::vector<caf::actor> core{caf::actor_cast<caf::actor>(m.io),
                               caf::actor_cast<caf::actor>(m.agent),
                               caf::actor_cast<caf::actor>(m.apps)};
  size_t left = 0;
  for (auto& a : core)
    if (a) {
      self->monitor(a);
      ++left;
    }
  stop_module(m);
  auto deadline = std::chrono::steady_clock::now() + timeout;
  while (left > 0) {
    auto now = std::chrono::steady_clock::now();
    if (now >= deadline)
      break;
    bool timed_out = false;
    self->receive([&](caf::down_msg&) { --left; },
                  caf::after(deadline - now) >> [&] { timed_out = true; });
    if (timed_out)
      break;
  }
}

module_handles running_module::release() {
  auto m = std::move(m_);
  m_ = {};
  return m;
}

caf::expected<running_module> run_module(caf::actor_system& sys,
                                         const module_config& cfg,
                                         std::chrono::milliseconds timeout) {
  auto m = start_module(sys, cfg, timeout);
  if (!m)
    return m.error();
  return running_module{std::move(*m)};
}

} // namespace herm
