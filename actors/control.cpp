// The control service actor: JSON requests in, JSON replies out, answered
// from the module's IO manager, routing agent and application support actor
// without ever blocking. Requests for another module go to that module's
// control service through a proxy (cached per module). Protocol:
// docs/protocol.md ("Control requests").

#include "actors/control.hpp"
#include "actors/control_info.hpp"
#include "actors/control_state.hpp"
#include "actors/control_topics.hpp"
#include "actors/text_form.hpp"

#include <algorithm>
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>

#include "caf/actor_cast.hpp"
#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/sec.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"
#include "actors/unexpected.hpp"

namespace herm::control_detail {

void with_self_id(control_impl self, ms timeout, reply_promise rp,
                  std::function<void(routing_stats&)> next) {
  self->request(self->state.m.agent, timeout, atom::get_v, atom::stats_v)
    .then([next](routing_stats& rs) { next(rs); }, fail_with(rp));
}

void resolve(control_impl self, module_id target, module_id self_id,
             ms timeout, std::function<void(caf::expected<caf::actor>)> next,
             bool info) {
  if (target == self_id) {
    next(caf::actor_cast<caf::actor>(self));
    return;
  }
  auto& st = self->state;
  auto& proxies = info ? st.info_proxies : st.proxies;
  const std::string apo_name = info ? info_apo_name : control_apo_name;
  const std::string apo_type = info ? info_apo_type : control_apo_type;
  if (auto i = proxies.find(target); i != proxies.end()) {
    next(i->second);
    return;
  }
  auto unknown = [target] {
    return make_error(app_ec::not_found, "unknown module " + to_hex(target)
                                       + " (not reachable or no control service)");
  };
  auto bind = [self, target, timeout, next, info](apo_ref ref) {
    // Remote control travels signed in a keyed network (apo_access); the
    // read-only herm.info is open.
    self->request(self->state.m.apps, timeout, atom::bind_v, ref,
                  info ? apo_access::open : apo_access::signed_only)
      .then(
        [self, target, next, info](caf::actor& proxy) {
          (info ? self->state.info_proxies : self->state.proxies)[target]
            = proxy;
          next(proxy);
        },
        [next](caf::error& err) { next(std::move(err)); });
  };
  auto discover = [self, target, timeout, next, bind, unknown, apo_name,
                   apo_type] {
    apo_query q{query_by::name, apo_name, discovery_ms, false};
    self
      ->request(self->state.m.apps, timeout + ms(discovery_ms), atom::find_v,
                std::move(q))
      .then(
        [target, next, bind, unknown, apo_type](std::vector<apo_ref>& found) {
          for (auto& ref : found)
            if (ref.module == target && ref.type == apo_type) {
              bind(ref);
              return;
            }
          next(unknown());
        },
        [next](caf::error& err) { next(std::move(err)); });
  };
  self->request(st.m.apps, timeout, atom::get_v, atom::apps_v)
    .then(
      [target, bind, discover, apo_name, apo_type](std::vector<apo_info>& rows) {
        for (auto& row : rows)
          if (!row.local && row.ref.module == target
              && row.ref.name == apo_name && row.ref.type == apo_type) {
            bind(row.ref);
            return;
          }
        discover();
      },
      [next](caf::error& err) { next(std::move(err)); });
}

namespace {

/// Sends `text` to the control service of `target` and relays its reply.
/// A failure through a cached proxy (the module restarted, the binding
/// ended) is retried once with a fresh binding.
void forward(control_impl self, module_id target, module_id self_id,
             std::string text, ms timeout, reply_promise rp, bool retried,
             bool info = false) {
  auto& proxies = info ? self->state.info_proxies : self->state.proxies;
  bool cached = proxies.count(target) > 0;
  resolve(self, target, self_id, timeout,
          [=](caf::expected<caf::actor> dest) mutable {
            if (!dest) {
              rp.deliver(error_reply(dest.error()));
              return;
            }
            self->request(*dest, timeout, text)
              .then([rp](std::string& reply) mutable { rp.deliver(reply); },
                    [=](caf::error& err) mutable {
                      (info ? self->state.info_proxies : self->state.proxies)
                        .erase(target);
                      bool timed_out
                        = is(err, ec::timeout)
                          || err == caf::make_error(caf::sec::request_timeout);
                      if (cached && !retried && !timed_out)
                        forward(self, target, self_id, text, timeout, rp, true,
                                info);
                      else
                        rp.deliver(error_reply(err));
                    });
          },
          info);
}

// -- commands ----------------------------------------------------------------------------

void cmd_info(control_impl self, ms timeout, reply_promise rp) {
  with_self_id(self, timeout, rp, [self, timeout, rp](routing_stats& rs) {
    auto& st = self->state;
    json j{{"name", st.module_name},
           {"module", to_hex(rs.self)},
           {"id", rs.self},
           {"instance", rs.instance},
           {"assigned", rs.assigned},
           {"uptime_ms", std::chrono::duration_cast<ms>(clock_type::now()
                                                         - st.started)
                           .count()},
           {"reachable", rs.reachable},
           {"registered", st.registered}};
    self->request(st.m.apps, timeout, atom::get_v, atom::stats_v)
      .then(
        [self, timeout, rp, j](app_support_stats& as) mutable {
          j["apps"] = {{"local", as.local_apos},
                       {"known_remote", as.known_remote_apos},
                       {"bindings", as.live_bindings}};
          self->request(self->state.m.agent, timeout, atom::get_v,
                        atom::neighbors_v)
            .then(
              [self, timeout, rp, j](std::vector<neighbour_info>& ns) mutable {
                j["neighbours"] = ns.size();
                self->request(self->state.m.io, timeout, atom::get_v,
                              atom::channels_v)
                  .then(
                    [rp, j](std::vector<channel_entry>& cs) mutable {
                      size_t up = 0;
                      for (auto& c : cs)
                        up += c.state == "up" ? 1 : 0;
                      j["channels"] = {{"up", up}, {"total", cs.size()}};
                      rp.deliver(ok_reply(std::move(j)));
                    },
                    fail_with(rp));
              },
              fail_with(rp));
        },
        fail_with(rp));
  });
}

/// The Channel Table with each up channel's counters; `done` gets the rows.
void collect_channels(control_impl self, ms timeout, reply_promise rp,
                      std::function<void(json)> done) {
  self->request(self->state.m.io, timeout, atom::get_v, atom::channels_v)
    .then(
      [self, timeout, done](std::vector<channel_entry>& entries) {
        auto rows = std::make_shared<json>(json::array());
        auto join = std::make_shared<join_counter>();
        join->done = [rows, done] { done(std::move(*rows)); };
        join->pending = 1; // released below, after every request is out
        for (auto& e : entries) {
          rows->push_back(to_json(e));
          if (e.state != "up")
            continue;
          auto index = rows->size() - 1;
          ++join->pending;
          self->request(self->state.m.io, timeout, atom::get_v, e.id)
            .then(
              [self, timeout, rows, join, index](channel_actor& ch) {
                self->request(ch, timeout, atom::get_v, atom::stats_v)
                  .then(
                    [rows, join, index](channel_stats& s) {
                      (*rows)[index]["stats"] = to_json(s);
                      join->finish_one();
                    },
                    [join](caf::error&) { join->finish_one(); });
              },
              [join](caf::error&) { join->finish_one(); });
        }
        join->finish_one();
      },
      fail_with(rp));
}

/// Every route, or with "all": false only the selected ones of class 0
/// (what forwarding uses for small packets; keeps replies from large
/// networks small).
void cmd_routes(control_impl self, const json& req, ms timeout,
                reply_promise rp) {
  auto ai = req.find("all");
  bool all = ai == req.end() || !ai->is_boolean() || ai->get<bool>();
  auto& st = self->state;
  self->request(st.m.agent, timeout, atom::get_v, atom::routes_v)
    .then(
      [self, timeout, rp, all](std::vector<route_info>& routes) {
        if (!all)
          routes.erase(std::remove_if(routes.begin(), routes.end(),
                                      [](const route_info& r) {
                                        return !r.selected || r.size_class != 0;
                                      }),
                       routes.end());
        self->request(self->state.m.agent, timeout, atom::get_v,
                      atom::neighbors_v)
          .then(
            [rp, routes](std::vector<neighbour_info>& ns) mutable {
              json rows = json::array();
              for (auto& r : routes)
                rows.push_back(to_json(r, ns));
              rp.deliver(ok_reply(std::move(rows)));
            },
            fail_with(rp));
      },
      fail_with(rp));
}

/// Asks `dest` for its table `what` (rows of type Row) and replies with the
/// rows as a JSON array.
template <class Row, class Handle, class Atom>
void reply_rows(control_impl self, const Handle& dest, Atom what, ms timeout,
                reply_promise rp) {
  self->request(dest, timeout, atom::get_v, what)
    .then(
      [rp](std::vector<Row>& rows) mutable {
        rp.deliver(ok_reply(rows_json(rows)));
      },
      fail_with(rp));
}

/// The application table: local APOs and those discovered so far; with
/// "all": true it first asks the whole network (a flooded query for every
/// APO, answers collected for "wait_ms", default discovery_ms), so every
/// APO the network knows is in the rows, with its module and type.
void cmd_apps(control_impl self, const json& req, ms timeout,
              reply_promise rp) {
  auto ai = req.find("all");
  if (ai == req.end() || !ai->is_boolean() || !ai->get<bool>()) {
    reply_rows<apo_info>(self, self->state.m.apps, atom::apps_v, timeout, rp);
    return;
  }
  auto wait = uint_field(req, "wait_ms", discovery_ms, 1, max_wait_ms);
  if (!wait) {
    rp.deliver(error_reply("invalid_parameter",
                           "wait_ms must be 1 to " + std::to_string(max_wait_ms)));
    return;
  }
  apo_query q{query_by::any, std::string{}, *wait, false};
  self
    ->request(self->state.m.apps, timeout + ms(*wait), atom::find_v,
              std::move(q))
    .then(
      [self, timeout, rp](std::vector<apo_ref>&) mutable {
        reply_rows<apo_info>(self, self->state.m.apps, atom::apps_v, timeout,
                             rp);
      },
      fail_with(rp));
}

void cmd_stats(control_impl self, ms timeout, reply_promise rp) {
  auto& st = self->state;
  self->request(st.m.agent, timeout, atom::get_v, atom::stats_v)
    .then(
      [self, timeout, rp](routing_stats& rs) {
        self->request(self->state.m.apps, timeout, atom::get_v, atom::stats_v)
          .then(
            [self, timeout, rp, rj = to_json(rs)](app_support_stats& as) {
              collect_channels(
                self, timeout, rp,
                [rp, rj, aj = to_json(as)](json channels) mutable {
                  json cs = json::array();
                  for (auto& c : channels) {
                    json row{{"id", c["id"]}, {"device", c["device"]},
                             {"state", c["state"]},
                             {"restarts", c["restarts"]}};
                    if (c["stats"].is_object())
                      row.update(c["stats"]);
                    cs.push_back(std::move(row));
                  }
                  rp.deliver(ok_reply(
                    {{"routing", rj}, {"apps", aj}, {"channels", cs}}));
                });
            },
            fail_with(rp));
      },
      fail_with(rp));
}

void cmd_echo(control_impl self, ms timeout, reply_promise rp) {
  with_self_id(self, timeout, rp, [self, rp](routing_stats& rs) mutable {
    rp.deliver(ok_reply({{"module", to_hex(rs.self)},
                         {"id", rs.self},
                         {"name", self->state.module_name}}));
  });
}

void cmd_link(control_impl self, const json& req, ms timeout, reply_promise rp) {
  auto device = string_field(req, "device");
  auto state = string_field(req, "state");
  if (device.empty() || (state != "up" && state != "down")) {
    rp.deliver(error_reply("invalid_parameter",
                           "link needs \"device\" and \"state\": \"up\" or "
                           "\"down\""));
    return;
  }
  auto& io = self->state.m.io;
  self->request(io, timeout, atom::get_v, atom::devices_v)
    .then(
      [self, timeout, rp, device, state](std::vector<device_info>& devs) mutable {
        auto known = std::any_of(devs.begin(), devs.end(), [&](auto& d) {
          return d.config.name == device;
        });
        if (!known) {
          rp.deliver(error_reply("unknown_device",
                                 "no device named '" + device + "'"));
          return;
        }
        self->request(self->state.m.io, timeout, atom::get_v, atom::channels_v)
          .then(
            [self, timeout, rp, device, state](
              std::vector<channel_entry>& entries) mutable {
              std::vector<channel_id> ids;
              for (auto& e : entries)
                if (e.request.device == device)
                  ids.push_back(e.id);
              if (state == "up") {
                if (!ids.empty()) {
                  rp.deliver(ok_reply({{"device", device},
                                       {"state", "up"},
                                       {"channels", ids},
                                       {"opened", false}}));
                  return;
                }
                self
                  ->request(self->state.m.io, timeout, atom::open_v,
                            channel_request{device, "*", true})
                  .then(
                    [rp, device](channel_actor&, channel_info& info) mutable {
                      rp.deliver(ok_reply({{"device", device},
                                           {"state", "up"},
                                           {"channels", json::array({info.id})},
                                           {"opened", true}}));
                    },
                    fail_with(rp));
                return;
              }
              auto closed = std::make_shared<json>(json::array());
              auto join = std::make_shared<join_counter>();
              join->pending = ids.size() + 1;
              join->done = [rp, device, closed]() mutable {
                rp.deliver(ok_reply({{"device", device},
                                     {"state", "down"},
                                     {"closed", *closed}}));
              };
              for (auto id : ids)
                self->request(self->state.m.io, timeout, atom::close_v, id)
                  .then(
                    [closed, join, id] {
                      closed->push_back(id);
                      join->finish_one();
                    },
                    [join](caf::error&) { join->finish_one(); });
              join->finish_one();
            },
            fail_with(rp));
      },
      fail_with(rp));
}

/// Progress of one ping: echoes are sent one after the other.
struct ping_run {
  module_id target = no_module;
  module_id self_id = no_module;
  uint32_t count = 0;
  uint32_t sent = 0;
  json rtts = json::array();
  uint32_t lost = 0;
  caf::error first_error;
  ms timeout{0};
  reply_promise rp;
};

void ping_next(control_impl self, std::shared_ptr<ping_run> run);

void ping_finish(std::shared_ptr<ping_run> run) {
  if (run->rtts.empty() && run->first_error) {
    run->rp.deliver(error_reply(run->first_error));
    return;
  }
  json j{{"module", to_hex(run->target)},
         {"count", run->count},
         {"received", run->rtts.size()},
         {"lost", run->lost},
         {"rtt_us", run->rtts}};
  if (!run->rtts.empty()) {
    uint64_t lo = UINT64_MAX, hi = 0, sum = 0;
    for (auto& v : run->rtts) {
      auto x = v.get<uint64_t>();
      lo = std::min(lo, x);
      hi = std::max(hi, x);
      sum += x;
    }
    j["min_us"] = lo;
    j["avg_us"] = sum / run->rtts.size();
    j["max_us"] = hi;
  }
  run->rp.deliver(ok_reply(std::move(j)));
}

void ping_next(control_impl self, std::shared_ptr<ping_run> run) {
  if (run->sent == run->count) {
    ping_finish(run);
    return;
  }
  ++run->sent;
  resolve(self, run->target, run->self_id, run->timeout,
          [self, run](caf::expected<caf::actor> dest) {
            if (!dest) {
              // Nothing will answer: the remaining echoes are lost too.
              if (!run->first_error)
                run->first_error = dest.error();
              run->lost += run->count - run->sent + 1;
              run->sent = run->count;
              ping_finish(run);
              return;
            }
            auto start = clock_type::now();
            self->request(*dest, run->timeout, std::string{R"({"cmd":"echo"})"})
              .then(
                [self, run, start](std::string&) {
                  auto rtt = std::chrono::duration_cast<std::chrono::microseconds>(
                    clock_type::now() - start);
                  run->rtts.push_back(static_cast<uint64_t>(rtt.count()));
                  ping_next(self, run);
                },
                [self, run](caf::error& err) {
                  self->state.proxies.erase(run->target);
                  if (!run->first_error)
                    run->first_error = err;
                  ++run->lost;
                  ping_next(self, run);
                });
          });
}

void cmd_ping(control_impl self, const json& req, ms timeout, reply_promise rp) {
  auto mi = req.find("module");
  auto target = mi != req.end() ? module_field(*mi) : std::nullopt;
  auto count = uint_field(req, "count", 1, 1, max_ping_count);
  if (!target || !count) {
    rp.deliver(error_reply("invalid_parameter",
                           "ping needs \"module\" (a module id) and a "
                           "\"count\" in [1, "
                             + std::to_string(max_ping_count) + "]"));
    return;
  }
  with_self_id(self, timeout, rp,
               [self, rp, timeout, target, count](routing_stats& rs) {
                 auto run = std::make_shared<ping_run>();
                 run->target = *target;
                 run->self_id = rs.self;
                 run->count = *count;
                 run->timeout = timeout;
                 run->rp = rp;
                 ping_next(self, run);
               });
}

/// Answers one request (docs/protocol.md, "Control requests").
void dispatch(control_impl self, const std::string& text, reply_promise rp) {
  auto req = json::parse(text, nullptr, false);
  if (req.is_discarded() || !req.is_object()) {
    rp.deliver(error_reply("invalid_request",
                           "a request is one JSON object with a \"cmd\""));
    return;
  }
  auto cmd = string_field(req, "cmd");
  if (cmd.empty()) {
    rp.deliver(error_reply("invalid_request",
                           "a request needs \"cmd\" (a string)"));
    return;
  }
  auto timeout_ms = uint_field(req, "timeout_ms",
                               static_cast<uint32_t>(default_control_timeout.count()),
                               1, max_timeout_ms);
  if (!timeout_ms) {
    rp.deliver(error_reply("invalid_parameter",
                           "\"timeout_ms\" must be an integer in [1, "
                             + std::to_string(max_timeout_ms) + "]"));
    return;
  }
  auto timeout = ms(*timeout_ms);
  // Ping's "module" is its target; any other command's is where it runs.
  auto mi = req.find("module");
  if (mi != req.end() && cmd != "ping") {
    auto target = module_field(*mi);
    if (!target || !is_unicast(*target)) {
      rp.deliver(error_reply("invalid_parameter",
                             "\"module\" must be a module id such as "
                             "\"0x4E\" or 78, got "
                               + dump(*mi)));
      return;
    }
    auto rest = req;
    rest.erase("module");
    with_self_id(self, timeout, rp,
                 [self, rp, timeout, target, rest](routing_stats& rs) {
                   // What herm.info answers goes there: no key needed.
                   auto what = string_field(rest, "cmd");
                   auto info = what == "types" || what == "topics";
                   if (*target == rs.self)
                     dispatch(self, dump(rest), rp);
                   else
                     forward(self, *target, rs.self, dump(rest), timeout, rp,
                             false, info);
                 });
    return;
  }
  if (cmd == "info")
    cmd_info(self, timeout, rp);
  else if (cmd == "channels")
    collect_channels(self, timeout, rp, [rp](json rows) mutable {
      rp.deliver(ok_reply(std::move(rows)));
    });
  else if (cmd == "routes")
    cmd_routes(self, req, timeout, rp);
  else if (cmd == "neighbors" || cmd == "neighbours")
    reply_rows<neighbour_info>(self, self->state.m.agent, atom::neighbors_v,
                               timeout, rp);
  else if (cmd == "apps")
    cmd_apps(self, req, timeout, rp);
  else if (cmd == "stats")
    cmd_stats(self, timeout, rp);
  else if (cmd == "echo")
    cmd_echo(self, timeout, rp);
  else if (cmd == "link")
    cmd_link(self, req, timeout, rp);
  else if (cmd == "ping")
    cmd_ping(self, req, timeout, rp);
  else if (cmd == "topics")
    cmd_topics(self, req, timeout, rp);
  else if (cmd == "publish")
    cmd_publish(self, req, timeout, rp);
  else if (cmd == "call")
    cmd_call(self, req, timeout, rp);
  else if (cmd == "types")
    rp.deliver(ok_reply(control_topics::descriptions_json(req["names"])));
  else if (cmd == "subscribe")
    rp.deliver(error_reply("invalid_request",
                           "\"subscribe\" opens a stream: send it on the "
                           "control socket"));
  else
    rp.deliver(error_reply("unknown_command", "unknown command '" + cmd + "'"));
}

control_actor::behavior_type control_fun(control_impl self, module_handles m,
                                         std::string module_name) {
  self->state.m = std::move(m);
  self->state.module_name = std::move(module_name);
  self->state.started = clock_type::now();
  // Anything but a request line comes from another module's mistake or
  // malice: counted and logged at a bounded rate, never printed whole.
  self->set_default_handler(log_unexpected);
  // Other modules reach it only by signed requests, or unsigned ones when
  // this module has no key and allows them (apo_access::signed_only).
  self->request(self->state.m.apps, std::chrono::seconds(10), atom::add_v,
                std::string{control_apo_name}, std::string{control_apo_type},
                caf::actor_cast<caf::actor>(self), apo_access::signed_only)
    .then([self](apo_ref&) { self->state.registered = "yes"; },
          [self](caf::error& err) { self->state.registered = render(err); });
  // Its read-only companion, open to every module; it ends with us.
  auto info = spawn_info_apo(self, self->state.m.apps);
  self->request(self->state.m.apps, std::chrono::seconds(10), atom::add_v,
                std::string{info_apo_name}, std::string{info_apo_type}, info)
    .then([](apo_ref&) {}, [](caf::error&) {});
  return {
    [self](std::string& text) -> caf::result<std::string> {
      auto rp = self->make_response_promise<std::string>();
      try {
        dispatch(self, text, rp);
      } catch (const std::exception& e) {
        // nlohmann's accessors throw on odd shapes we failed to check.
        rp.deliver(error_reply("invalid_request", e.what()));
      }
      return rp;
    },
    [self](atom::subscribe, std::string& text,
           caf::actor& writer) -> caf::result<std::string> {
      auto rp = self->make_response_promise<std::string>();
      open_stream(self, text, writer, rp);
      return rp;
    },
  };
}

} // namespace

} // namespace herm::control_detail

namespace herm {

control_actor spawn_control(caf::actor_system& sys, const module_handles& m,
                            std::string module_name) {
  return sys.spawn(control_detail::control_fun, m, std::move(module_name));
}

std::chrono::milliseconds control_deadline(const std::string& request) {
  using namespace control_detail;
  auto timeout = default_control_timeout;
  uint64_t times = 1;
  // apps --all collecting answers for "wait_ms".
  ms wait{0};
  auto req = json::parse(request, nullptr, false);
  if (req.is_object()) {
    if (auto t = uint_field(req, "timeout_ms", 0, 1, max_timeout_ms); t && *t)
      timeout = ms(*t);
    if (string_field(req, "cmd") == "ping")
      if (auto n = uint_field(req, "count", 1, 1, max_ping_count))
        times = *n;
    if (auto w = uint_field(req, "wait_ms", 0, 1, max_wait_ms); w && *w)
      wait = ms(*w);
  }
  // Each echo of a ping, and a forwarded request, may need a discovery
  // first; a forwarded request may be retried once after a failed cached
  // proxy.
  auto one = timeout + ms(discovery_ms);
  if (times > 1)
    return one * static_cast<int64_t>(times) + std::chrono::seconds(1);
  return 2 * one + wait + std::chrono::seconds(1);
}

} // namespace herm
