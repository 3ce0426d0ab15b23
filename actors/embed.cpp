#include "actors/embed.hpp"

#include <thread>

#include "caf/exit_reason.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/sec.hpp"

#include "actors/config.hpp"
#include "actors/runtime/error.hpp"

namespace herm {

// -- served_module ----------------------------------------------------------------------

served_module::served_module(running_module m, control_actor service,
                             std::unique_ptr<control_server> server)
  : module_(std::move(m)),
    service_(std::move(service)),
    server_(std::move(server)) {
}

served_module& served_module::operator=(served_module&& other) noexcept {
  if (this != &other) {
    stop();
    module_ = std::move(other.module_);
    service_ = std::move(other.service_);
    server_ = std::move(other.server_);
  }
  return *this;
}

served_module::~served_module() {
  stop();
}

void served_module::stop() {
  server_.reset();
  if (service_) {
    caf::anon_send_exit(service_, caf::exit_reason::user_shutdown);
    service_ = nullptr;
  }
  module_.stop();
}

std::string served_module::socket() const {
  return server_ ? server_->path() : std::string{};
}

caf::expected<served_module>
serve_module(caf::actor_system& sys, const module_config& cfg,
             const std::string& name, std::string socket,
             std::chrono::milliseconds timeout) {
  auto m = run_module(sys, cfg, timeout);
  if (!m)
    return m.error();
  auto service = spawn_control(sys, *m, name);
  watch_module_actor(*m, caf::actor_cast<caf::actor>(service), "herm.control");
  std::unique_ptr<control_server> server;
  if (socket != "-") {
    if (socket.empty())
      socket = default_control_socket(name);
    auto s = control_server::start(sys, service, socket);
    if (!s) {
      caf::anon_send_exit(service, caf::exit_reason::user_shutdown);
      return s.error();
    }
    server = std::move(*s);
  }
  return served_module{std::move(*m), std::move(service), std::move(server)};
}

// -- binding ------------------------------------------------------------------------------

caf::expected<caf::actor>
bind_within(caf::actor_system& sys, const app_support_actor& apps,
            bind_request req, std::chrono::milliseconds deadline) {
  using clock = std::chrono::steady_clock;
  auto end = clock::now() + deadline;
  caf::scoped_actor self{sys};
  caf::error last;
  for (;;) {
    caf::actor proxy;
    caf::error err;
    self
      ->request(apps, std::chrono::milliseconds(req.timeout_ms) + std::chrono::seconds(5),
                atom::bind_v, req)
      .receive([&](caf::actor& p) { proxy = std::move(p); },
               [&](caf::error& e) { err = typed_error(e); });
    if (proxy)
      return proxy;
    if (!is(err, app_ec::not_found) && !is(err, routing_ec::no_route))
      return err;
    last = err;
    if (clock::now() + std::chrono::milliseconds(200) >= end)
      break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  auto within = " within " + std::to_string(deadline.count()) + " ms";
  if (is(last, routing_ec::no_route))
    return make_error(routing_ec::no_route,
                      "the APO '" + req.pattern + "' stayed unreachable"
                        + within);
  return make_error(app_ec::not_found, std::string{"no APO "}
                                         + (req.by == query_by::type
                                              ? "of type '"
                                              : "named '")
                                         + req.pattern + "'" + within);
}

caf::expected<caf::actor>
bind_within(caf::actor_system& sys, const app_support_actor& apps,
            const std::string& name, std::chrono::milliseconds deadline) {
  return bind_within(sys, apps, bind_request{query_by::name, name, 500},
                     deadline);
}

} // namespace herm
