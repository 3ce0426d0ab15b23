// hermd: runs one HERM module configured by a YAML file.
//
//   hermd robot.yaml            run the module until SIGINT or SIGTERM
//   hermd --check robot.yaml    validate the file and exit (0: valid)
//
// Start-up is all or nothing: a bad config or a device that cannot be
// opened stops hermd with the file, line and field before anything runs.
// --check, a start and a reload check channel options alike, with each link
// kind's own parser (check_channels): a misspelled option or a host name
// where an IPv4 address is needed is a config error (exit 2), not a device
// that fails to open.
// SIGINT/SIGTERM: the module says goodbye on every channel (neighbours drop
// its routes at once), stops its APOs and exits 0. SIGHUP, or `hermctl
// reload`, re-reads the file and applies its channel changes: new channels
// open, removed ones close, changed ones reopen; the others are untouched.
// Exit status: 0 clean stop or valid config, 1 start-up failed, 2 bad config
// or usage, 3 the module failed while running: a core actor (IO manager,
// routing agent, application support, control service) ended, e.g. on an
// exception, or the routing agent refused to join because another module
// holds the configured static id. The log names the actor and the reason;
// a supervisor (systemd's Restart=on-failure) restarts hermd.
//
//   hermd --fault-injection robot.yaml
//     also serves the local control command {"cmd":"fault","actor":A}, A
//     one of io, routing, apps, control: ends that core actor with
//     exit_reason::kill, as a crash would, to test the supervision of a
//     deployment (and hermd's own, in tests/apps/hermd_failure_test.cpp).
//     Off by default; only on the local control socket (never remote).

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/spdlog.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/config.hpp"
#include "actors/control.hpp"
#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/hermd/apo_kinds.hpp"
#include "apps/hermd/change_log.hpp"
#include "apps/hermd/testbed_types.hpp"
#include "channels/fragmentation.hpp"
#include "routing/module_id.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

// -- configuration checks --------------------------------------------------------

/// Checks what the parser cannot: that every APO kind exists and its options
/// are right. Errors name file and line.
caf::error check_apos(const file_config& cfg) {
  for (size_t i = 0; i < cfg.apos.size(); ++i) {
    auto& a = cfg.apos[i];
    auto at = cfg.path + ":" + std::to_string(a.line) + ": apos["
              + std::to_string(i) + "]";
    auto* kind = hermd::find_apo_kind(a.kind);
    if (kind == nullptr) {
      std::string known;
      for (auto& k : hermd::apo_kinds())
        known += (known.empty() ? "" : ", ") + k.name;
      return make_error(ec::invalid_config, at + ".kind: unknown APO kind '"
                                              + a.kind + "' (known: " + known
                                              + ")");
    }
    if (auto err = kind->check(a))
      return make_error(ec::invalid_config, at + ": " + [&] {
        auto& ctx = err.context();
        return ctx.match_elements<std::string>() ? ctx.get_as<std::string>(0)
                                                 : render(err);
      }());
  }
  return caf::none;
}

std::vector<std::string> origins(const file_config& cfg) {
  std::vector<std::string> result;
  for (size_t i = 0; i < cfg.module.devices.size(); ++i)
    result.push_back(cfg.path + ":"
                     + std::to_string(i < cfg.device_lines.size()
                                        ? cfg.device_lines[i]
                                        : 0)
                     + ": channels[" + std::to_string(i) + "] '"
                     + cfg.module.devices[i].name + "'");
  return result;
}

// -- logs --------------------------------------------------------------------------

/// `%*` in a pattern: the message as the inside of a JSON string.
class json_message : public spdlog::custom_flag_formatter {
public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    for (char c : msg.payload) {
      switch (c) {
        case '"':
          dest.append(std::string_view{"\\\""});
          break;
        case '\\':
          dest.append(std::string_view{"\\\\"});
          break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof(buf), "\\u%04x", c);
            dest.append(std::string_view{buf});
          } else {
            dest.push_back(c);
          }
      }
    }
  }

  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<json_message>();
  }
};

void setup_logs(const file_config& cfg) {
  auto logger = spdlog::stdout_color_mt("hermd");
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::from_str(cfg.log_level));
  if (cfg.log_format == "json") {
    // Module names are [A-Za-z0-9_.-]: no escaping needed.
    auto f = std::make_unique<spdlog::pattern_formatter>();
    f->add_flag<json_message>('*').set_pattern(
      R"({"time":"%Y-%m-%dT%H:%M:%S.%e","module":")" + cfg.name
      + R"(","level":"%l","msg":"%*"})");
    spdlog::set_formatter(std::move(f));
  } else
    spdlog::set_pattern("%H:%M:%S.%e " + cfg.name + " %^%-5l%$ %v");
  spdlog::flush_on(spdlog::level::trace);
}

/// Frames a packet of `bytes` takes on a link of `mtu` (1 without
/// fragmentation).
size_t frames(uint32_t bytes, uint32_t mtu) {
  if (mtu == 0 || bytes <= mtu)
    return 1;
  return fragmenter{std::max(mtu, min_fragment_mtu)}.frames_for(bytes);
}

/// Debug log of every unicast data packet: the path it takes and why.
void trace_packet(const packet_trace& t) {
  if (!spdlog::should_log(spdlog::level::debug))
    return;
  auto ids = to_hex(t.src) + "->" + to_hex(t.dst);
  auto out = [&] {
    auto n = frames(t.bytes, t.out_mtu);
    return fmt::format("via {} to {} (route cost {}, path {}){}", t.out_link,
                       to_hex(t.next), t.cost, t.forwarding,
                       n > 1 ? fmt::format(", fragmented into {} frames of <= {} B",
                                           n, t.out_mtu)
                             : std::string{});
  };
  auto in = [&] {
    auto n = frames(t.bytes, t.in_mtu);
    return n > 1 ? fmt::format(" (reassembled from {} {} frames)", n, t.in_link)
                 : fmt::format(" (one {} frame)", t.in_link);
  };
  switch (t.what) {
    case packet_trace::originated:
      spdlog::debug("packet {} {} B sent {}", ids, t.bytes, out());
      break;
    case packet_trace::forwarded:
      spdlog::debug("packet {} {} B arrived on {}{}, forwarded {}", ids,
                    t.bytes, t.in_link, in(), out());
      break;
    case packet_trace::delivered:
      spdlog::debug("packet {} {} B delivered{}", ids, t.bytes, in());
      break;
  }
}

/// Logs every change of a destination's selected route, from the route
/// event alone (never a table query: a query per event made a flood of
/// advertisements cost O(N^2)), and every link (neighbour) that comes up or
/// goes down, as the agent's on_neighbour callback sends them here: one line
/// per change (apps/hermd/change_log.hpp). At a bounded rate per kind: a
/// neighbour that advertises thousands of destinations, or a flapping link,
/// must not make the daemon write thousands of lines (nor block on a full
/// log pipe); what the bound holds back is summed up once a second.
/// Spawned before the module, so that no link event is missed; told the
/// routing agent to subscribe to once it runs.
struct change_logger_state {
  static inline const char* name = "hermd.change_logger";
  /// `burst` lines at once (a network of a few hundred modules starting up
  /// is logged in full), then `rate` per second.
  static constexpr double burst = 200;
  static constexpr double rate = 20;
  hermd::line_budget routes{burst, rate, std::chrono::steady_clock::now()};
  hermd::line_budget links{burst, rate, std::chrono::steady_clock::now()};
  bool summary_due = false;

  /// True if a line may go out now; else schedules the summary.
  template <class Self>
  bool admit(Self* self, hermd::line_budget& budget) {
    if (budget.take(std::chrono::steady_clock::now()))
      return true;
    if (!summary_due) {
      summary_due = true;
      self->delayed_send(self, 1s, atom::tick_v);
    }
    return false;
  }
};

caf::behavior change_logger(caf::stateful_actor<change_logger_state>* self) {
  return {
    [self](caf::actor& agent) {
      // The routing agent (a routing_agent_actor: typed handles have no
      // type ID of their own to travel in a message).
      self->send(caf::actor_cast<routing_agent_actor>(agent),
                 atom::subscribe_v, atom::routes_v,
                 caf::actor_cast<route_listener_actor>(self));
    },
    [self](reachability& r) {
      if (self->state.admit(self, self->state.routes))
        spdlog::info("{}", hermd::route_line(r));
    },
    [self](std::string& link_line) {
      if (self->state.admit(self, self->state.links))
        spdlog::info("{}", link_line);
    },
    [self](atom::tick) {
      auto& st = self->state;
      st.summary_due = false;
      auto text = hermd::held_back_line(st.routes.held_back(),
                                        st.links.held_back(),
                                        change_logger_state::rate);
      if (!text.empty())
        spdlog::info("{}", text);
    },
  };
}

// -- failures ------------------------------------------------------------------------

/// Set by the module's supervisor when a core actor ended; main exits 3.
std::atomic<bool> module_failed{false};

/// Runs in the supervisor's thread: logs which actor and why, then wakes
/// main (blocked in sigwait) with a SIGTERM that finds module_failed set.
void on_module_failure(const module_failure& f) {
  spdlog::critical("core actor {} ended: {}; the module cannot work without "
                   "it, exiting",
                   f.actor, render(f.reason));
  module_failed = true;
  ::kill(::getpid(), SIGTERM);
}

/// Logs a dispute over this module's static id (routing_config).
void on_id_conflict(const id_conflict& c) {
  if (c.refused)
    spdlog::critical("module id {} is already held by instance {} (heard on "
                     "{}): not joining; give this module another id",
                     to_hex(c.id), c.other_instance, c.heard);
  else
    spdlog::error("duplicate module id {}: instance {} also uses it (heard on "
                  "{}); this module keeps it (it held it first), the other "
                  "must get another id",
                  to_hex(c.id), c.other_instance, c.heard);
}

// -- the daemon ----------------------------------------------------------------------

class module_daemon {
public:
  module_daemon(caf::actor_system& sys, file_config cfg,
                bool fault_injection = false)
    : sys_(sys), cfg_(std::move(cfg)), fault_injection_(fault_injection) {
    // nop
  }

  /// Starts everything or nothing.
  caf::error start() {
    auto mc = cfg_.module;
    mc.device_origins = origins(cfg_);
    mc.routing.tracer = trace_packet;
    mc.routing.on_id_conflict = on_id_conflict;
    route_logger_ = sys_.spawn(change_logger);
    // Runs in the agent's thread: formats there, writes in the logger.
    mc.routing.on_neighbour = [logger = route_logger_](const neighbour_event& e) {
      caf::anon_send(logger, hermd::link_line(e));
    };
    mc.on_failure = on_module_failure;
    auto m = start_module(sys_, mc);
    if (!m) {
      stop(false);
      return m.error();
    }
    m_ = *m;
    auto self = caf::scoped_actor{sys_};
    for (auto& ch : cfg_.module.devices)
      spdlog::info("channel '{}' up: {} {}", ch.name, ch.kind, ch.interface);
    caf::anon_send(route_logger_, caf::actor_cast<caf::actor>(m_.agent));
    control_ = spawn_control(sys_, m_, cfg_.name);
    watch_module_actor(m_, caf::actor_cast<caf::actor>(control_),
                       "herm.control");
    if (!cfg_.control_socket.empty()) {
      local_commands locals;
      locals["reload"] = [this](const std::string&) { return reload_json(); };
      if (fault_injection_)
        locals["fault"] = [this](const std::string& req) {
          return fault_json(req);
        };
      auto server = control_server::start(sys_, control_, cfg_.control_socket,
                                          std::move(locals));
      if (!server) {
        stop(false);
        return server.error();
      }
      server_ = std::move(*server);
      spdlog::info("control socket {}", cfg_.control_socket);
    }
    hermd::apo_context ctx{&sys_, m_, cfg_.name};
    for (auto& a : cfg_.apos) {
      auto apo = hermd::find_apo_kind(a.kind)->spawn(ctx, a);
      caf::error err = apo ? caf::error{} : apo.error();
      if (!err)
        self->request(m_.apps, 5s, atom::add_v, a.name,
                      a.type.empty() ? "herm." + a.kind : a.type, *apo)
          .receive(
            [&](apo_ref& ref) {
              spdlog::info("APO '{}' ({}) registered as {}:{}", a.name, a.kind,
                           to_hex(ref.module), ref.apo);
            },
            [&](caf::error& e) { err = e; });
      if (err) {
        if (apo)
          self->send_exit(*apo, caf::exit_reason::user_shutdown);
        stop(false);
        return make_error(ec::invalid_config,
                          cfg_.path + ":" + std::to_string(a.line) + ": APO '"
                            + a.name + "': " + render(err));
      }
      apos_.push_back(*apo);
    }
    spdlog::info("module '{}' running as {} ({} channels, {} APOs)", cfg_.name,
                 cfg_.module.routing.id == no_module
                   ? std::string{"dynamic"}
                   : to_hex(cfg_.module.routing.id),
                 cfg_.module.devices.size(), apos_.size());
    return caf::none;
  }

  /// Leaves the network cleanly: goodbyes first, then every actor.
  void stop(bool goodbye = true) {
    server_.reset();
    caf::scoped_actor self{sys_};
    for (auto& a : apos_)
      self->send_exit(a, caf::exit_reason::user_shutdown);
    apos_.clear();
    if (goodbye && m_.agent) {
      self->request(m_.agent, 2s, atom::close_v)
        .receive([] {}, [](caf::error& err) {
          spdlog::warn("goodbye not confirmed: {}", render(err));
        });
      // Let drivers with transmit queues (emulated media) put it on the wire.
      std::this_thread::sleep_for(100ms);
      self->request(m_.agent, 2s, atom::get_v, atom::stats_v)
        .receive(
          [](routing_stats& st) {
            spdlog::info("routing counters: delivered {}, forwarded {}, "
                         "originated {}, dropped (no route {}, hop limit {}), "
                         "malformed {}",
                         st.delivered, st.forwarded, st.originated,
                         st.dropped_no_route, st.dropped_hop_limit,
                         st.rx_malformed);
          },
          [](caf::error&) {});
    }
    if (control_)
      self->send_exit(control_, caf::exit_reason::user_shutdown);
    if (route_logger_)
      self->send_exit(route_logger_, caf::exit_reason::user_shutdown);
    if (m_.io)
      stop_module(m_);
    m_ = {};
  }

  /// Re-reads the file; applies channel changes. Returns a JSON reply.
  std::string reload_json() {
    std::lock_guard<std::mutex> guard{reload_mtx_};
    auto fresh = load_config(cfg_.path);
    if (fresh)
      if (auto err = check_channels(*fresh))
        fresh = std::move(err);
    if (!fresh) {
      spdlog::error("reload refused: {}", render(fresh.error()));
      return R"({"ok":false,"error":{"code":"invalid_config","message":)"
             + quote(render(fresh.error())) + "}}";
    }
    std::vector<std::string> added, removed, changed, failed;
    caf::scoped_actor self{sys_};
    auto same = [](const device_config& a, const device_config& b) {
      return a.kind == b.kind && a.interface == b.interface
             && a.options == b.options;
    };
    auto find = [](const std::vector<device_config>& v, const std::string& n)
      -> const device_config* {
      for (auto& d : v)
        if (d.name == n)
          return &d;
      return nullptr;
    };
    auto close = [&](const std::string& name) {
      self->request(m_.io, 5s, atom::close_v, name)
        .receive([] {}, [&](caf::error& err) {
          failed.push_back(name + ": " + render(err));
        });
    };
    auto open = [&](const device_config& dev) {
      caf::error err;
      self->request(m_.io, 5s, atom::add_v, dev)
        .receive([](device_info&) {}, [&](caf::error& e) { err = e; });
      if (!err)
        self->request(m_.io, 5s, atom::open_v,
                      channel_request{dev.name, "*", true})
          .receive([](channel_actor&, channel_info&) {},
                   [&](caf::error& e) { err = e; });
      if (err) {
        // Forget the device too, so that a later reload can add it anew.
        self->request(m_.io, 5s, atom::close_v, dev.name)
          .receive([] {}, [](caf::error&) {});
        failed.push_back(dev.name + ": " + render(err));
      }
      return !err;
    };
    auto& old_devs = cfg_.module.devices;
    auto& new_devs = fresh->module.devices;
    for (auto& d : old_devs)
      if (find(new_devs, d.name) == nullptr) {
        close(d.name);
        removed.push_back(d.name);
      }
    // What runs afterwards: a channel that failed to open is left out, so
    // that the next reload of the same file tries it again.
    std::vector<device_config> running;
    for (auto& d : new_devs) {
      auto* before = find(old_devs, d.name);
      if (before != nullptr && same(*before, d)) {
        running.push_back(d);
        continue;
      }
      if (before != nullptr)
        close(d.name);
      if (!open(d))
        continue;
      (before == nullptr ? added : changed).push_back(d.name);
      running.push_back(d);
    }
    cfg_.module.devices = std::move(running);
    auto list = [](const std::vector<std::string>& xs) {
      std::string out = "[";
      for (auto& x : xs)
        out += (out.size() > 1 ? "," : "") + quote(x);
      return out + "]";
    };
    spdlog::info("reloaded {}: {} added, {} removed, {} changed, {} failed",
                 cfg_.path, added.size(), removed.size(), changed.size(),
                 failed.size());
    for (auto& f : failed)
      spdlog::error("reload: {}", f);
    return R"({"ok":true,"result":{"added":)" + list(added) + R"(,"removed":)"
           + list(removed) + R"(,"changed":)" + list(changed) + R"(,"failed":)"
           + list(failed) + "}}";
  }

  /// --fault-injection: ends the core actor the request names with
  /// exit_reason::kill.
  std::string fault_json(const std::string& req) {
    std::pair<const char*, caf::actor> actors[] = {
      {"io", caf::actor_cast<caf::actor>(m_.io)},
      {"routing", caf::actor_cast<caf::actor>(m_.agent)},
      {"apps", caf::actor_cast<caf::actor>(m_.apps)},
      {"control", caf::actor_cast<caf::actor>(control_)},
    };
    auto j = nlohmann::json::parse(req, nullptr, false);
    std::string which;
    if (j.is_object() && j.contains("actor") && j["actor"].is_string())
      which = j["actor"].get<std::string>();
    for (auto& [name, a] : actors)
      if (which == name) {
        spdlog::warn("fault injection: killing core actor '{}'", name);
        caf::anon_send_exit(a, caf::exit_reason::kill);
        return R"({"ok":true,"result":{"killed":")" + std::string{name}
               + R"("}})";
      }
    return R"({"ok":false,"error":{"code":"invalid_request","message":)"
           R"("fault: \"actor\" must be io, routing, apps or control"}})";
  }

private:
  static std::string quote(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
      if (c == '"' || c == '\\')
        out += '\\';
      if (static_cast<unsigned char>(c) < 0x20)
        out += ' ';
      else
        out += c;
    }
    return out + "\"";
  }

  caf::actor_system& sys_;
  file_config cfg_;
  module_handles m_;
  control_actor control_;
  caf::actor route_logger_;
  std::unique_ptr<control_server> server_;
  std::vector<caf::actor> apos_;
  std::mutex reload_mtx_;
  bool fault_injection_ = false;
};

} // namespace

int main(int argc, char** argv) {
  CLI::App app{"hermd: runs one HERM module configured by a YAML file"};
  std::string path;
  bool check = false;
  std::string level;
  app.add_option("config", path, "the module's configuration file")->required();
  app.add_flag("--check", check, "validate the file and exit");
  bool fault_injection = false;
  app.add_flag("--fault-injection", fault_injection,
               "serve the local control command 'fault' that kills a core "
               "actor (tests of supervision only)");
  app.add_option("--log-level", level,
                 "override log.level (trace, debug, info, warn, error, off)");
  CLI11_PARSE(app, argc, argv);

  auto cfg = load_config(path);
  if (!cfg) {
    std::cerr << "hermd: " << render(cfg.error()) << std::endl;
    return 2;
  }
  if (auto err = check_channels(*cfg)) {
    std::cerr << "hermd: " << render(err) << std::endl;
    return 2;
  }
  if (auto err = check_apos(*cfg)) {
    std::cerr << "hermd: " << render(err) << std::endl;
    return 2;
  }
  if (!level.empty())
    cfg->log_level = level;
  if (check) {
    std::cout << path << ": valid: module '" << cfg->name << "' ("
              << (cfg->module.routing.id == no_module
                    ? std::string{"dynamic"}
                    : to_hex(cfg->module.routing.id))
              << "), " << cfg->module.devices.size() << " channels, "
              << cfg->apos.size() << " APOs" << std::endl;
    return 0;
  }
  setup_logs(*cfg);

  // Signals go to the main thread only: block them before CAF starts its
  // threads (which inherit the mask), then wait for them below.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  sigaddset(&sigs, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  caf::actor_system_config sys_cfg;
  configure(sys_cfg, cfg->scheduler, cfg->threads, cfg->busy_poll_us);
  hermd::add_apo_types(sys_cfg);
  caf::actor_system sys{sys_cfg};
  module_daemon d{sys, *cfg, fault_injection};
  if (auto err = d.start()) {
    spdlog::error("start-up failed: {}", render(err));
    std::cerr << "hermd: " << render(err) << std::endl;
    return 1;
  }
  for (;;) {
    int sig = 0;
    if (sigwait(&sigs, &sig) != 0)
      continue;
    if (sig == SIGHUP) {
      spdlog::info("SIGHUP: reloading {}", path);
      d.reload_json();
      continue;
    }
    if (module_failed) {
      // The module is broken: stop what is left, bounded (an actor that
      // is wedged must not keep the supervisor from restarting us).
      std::thread{[] {
        std::this_thread::sleep_for(5s);
        spdlog::critical("stopping took over 5 s; exiting anyway");
        std::_Exit(3);
      }}.detach();
      d.stop();
      spdlog::info("stopped after a failure; exit status 3");
      return 3;
    }
    spdlog::info("{}: leaving the network", sig == SIGINT ? "SIGINT" : "SIGTERM");
    d.stop();
    spdlog::info("stopped");
    return 0;
  }
}
