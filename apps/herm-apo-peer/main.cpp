// herm-apo-peer: one HERM module (IO manager, routing agent, application
// support) per process, for multi-process tests of APOs, proxies and topics.
//
//   herm-apo-peer --id 0x33 --emu /tmp/bus:can2.0:2 serve --name echo
//   herm-apo-peer --id 0x32 --udp 127.0.0.1:41001=127.0.0.1:41000
//                 --emu /tmp/bus:can2.0:1 route
//   herm-apo-peer --id 0x31 --udp 127.0.0.1:41000=127.0.0.1:41001
//                 call --name echo --count 20 --size 200
//   herm-apo-peer --id 0x40 --emu /tmp/eth:ethernet:1 publish --topic t --count 10
//   herm-apo-peer --id 0x41 --emu /tmp/eth:ethernet:2 subscribe --topic t --count 5
//
// Prints one flushed line per event on stdout: "ready", "served N",
// "reply I ok", "reply I bad ...", "done ok=K failed=F", "down REASON",
// "published V", "value V", "error ...". Exit status: 0 success, 1 the
// exchange failed (a bad or missing reply, no down message, too few
// values), 2 bad arguments or the module did not start (the typed error is
// printed). SIGTERM and SIGINT end every role cleanly.

#include <atomic>
#include <csignal>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

volatile std::sig_atomic_t stop_requested = 0;

using clock_type = std::chrono::steady_clock;

struct options {
  std::string id = "0x30";
  std::vector<std::string> udp;
  std::vector<std::string> emu;
  uint32_t hello_ms = 100;
  double timeout = 10;
  std::string name;
  std::string topic;
  uint32_t count = 1;
  uint32_t size = 16;
  uint32_t period_ms = 200;
  bool watch = false;
};

std::chrono::milliseconds seconds(double s) {
  return std::chrono::milliseconds(static_cast<int64_t>(s * 1000));
}

/// "LOCAL=PEER[,PEER...]" as a udp device.
std::optional<device_config> parse_udp(const std::string& arg, size_t n) {
  auto eq = arg.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == arg.size())
    return std::nullopt;
  return device_config{"udp" + std::to_string(n), "udp", arg.substr(0, eq),
                       {{"peers", arg.substr(eq + 1)}}};
}

/// "DIR:PROFILE:STATION" as an emu device (the directory may hold colons).
std::optional<device_config> parse_emu(const std::string& arg, size_t n) {
  auto last = arg.rfind(':');
  if (last == std::string::npos || last == 0)
    return std::nullopt;
  auto mid = arg.rfind(':', last - 1);
  if (mid == std::string::npos || mid == 0 || mid + 1 == last)
    return std::nullopt;
  return device_config{"emu" + std::to_string(n), "emu", arg.substr(0, mid),
                       {{"profile", arg.substr(mid + 1, last - mid - 1)},
                        {"station", arg.substr(last + 1)}}};
}

/// Request `i`'s string: `size` bytes, distinct for every `i` (a decimal
/// prefix, then a pattern derived from `i` and the position).
std::string make_text(uint32_t i, uint32_t size) {
  auto text = std::to_string(i) + ":";
  while (text.size() < size) {
    auto j = static_cast<uint32_t>(text.size());
    text += static_cast<char>('a' + (i * 7 + j * 13 + j / 26) % 26);
  }
  text.resize(size);
  return text;
}

/// Sleeps `d` in short steps; false if a signal asked us to stop.
bool nap(std::chrono::milliseconds d) {
  auto until = clock_type::now() + d;
  while (stop_requested == 0 && clock_type::now() < until)
    std::this_thread::sleep_for(std::min<clock_type::duration>(
      20ms, until - clock_type::now()));
  return stop_requested == 0;
}

// -- the actors ----------------------------------------------------------------------

/// The APO of `serve`: echoes strings and adds pairs of int32.
caf::behavior echo_apo(caf::event_based_actor*,
                       std::shared_ptr<std::atomic<uint64_t>> served) {
  return {
    [served](std::string& s) -> std::string {
      ++*served;
      return "echo:" + s;
    },
    [served](int32_t a, int32_t b) -> int32_t {
      ++*served;
      return a + b;
    },
  };
}

/// The subscriber of `subscribe`: hands each int32 to `main`, which prints
/// it (one thread writes stdout, so lines never interleave).
caf::behavior recorder(caf::event_based_actor* self, caf::actor main) {
  return {
    [self, main](int32_t v) { self->send(main, v); },
  };
}

// -- the roles ----------------------------------------------------------------------

int serve(caf::scoped_actor& self, const module_handles& m, const options& o) {
  auto served = std::make_shared<std::atomic<uint64_t>>(0);
  auto apo = self->spawn(echo_apo, served);
  caf::error err;
  self->request(m.apps, 5s, atom::add_v, o.name, std::string{"test.echo"}, apo)
    .receive([](apo_ref&) {}, [&](caf::error& e) { err = e; });
  if (err) {
    std::cout << "error " << render(err) << std::endl;
    self->send_exit(apo, caf::exit_reason::user_shutdown);
    return 2;
  }
  std::cout << "ready" << std::endl;
  while (nap(100ms)) {
  }
  self->send_exit(apo, caf::exit_reason::user_shutdown);
  std::cout << "served " << served->load() << std::endl;
  return 0;
}

/// Binds by name, retrying while routes converge (not_found, no_route).
caf::actor bind_by_name(caf::scoped_actor& self, const module_handles& m,
                        const std::string& name, clock_type::time_point until) {
  caf::actor proxy;
  caf::error err;
  while (!proxy && stop_requested == 0 && clock_type::now() < until) {
    self->request(m.apps, 5s, atom::bind_v,
                  bind_request{query_by::name, name, 1000, false})
      .receive([&](caf::actor& p) { proxy = p; },
               [&](caf::error& e) { err = e; });
    if (!proxy && !is(err, ec::not_found) && !is(err, ec::no_route))
      break;
    if (!proxy)
      nap(100ms);
  }
  if (!proxy)
    std::cout << "error bind '" << name << "': "
              << (err ? render(err) : std::string{"interrupted"}) << std::endl;
  return proxy;
}

int call(caf::scoped_actor& self, const module_handles& m, const options& o) {
  auto until = clock_type::now() + seconds(o.timeout);
  auto proxy = bind_by_name(self, m, o.name, until);
  if (!proxy)
    return 1;
  std::cout << "bound " << o.name << std::endl;
  uint32_t ok = 0, failed = 0;
  for (uint32_t i = 0; i < o.count && stop_requested == 0; ++i) {
    auto text = make_text(i, o.size);
    auto expected = "echo:" + text;
    // The binding proves the server has a route to us; ours to it may
    // still be converging, so no_route is retried until the deadline.
    for (bool again = true; again;) {
      again = false;
      self->request(proxy, seconds(o.timeout), text)
        .receive(
          [&](std::string& reply) {
            if (reply == expected) {
              ++ok;
              std::cout << "reply " << i << " ok" << std::endl;
            } else {
              ++failed;
              std::cout << "reply " << i << " bad size=" << reply.size()
                        << " expected=" << expected.size() << std::endl;
            }
          },
          [&](caf::error& e) {
            if (is(e, ec::no_route) && clock_type::now() < until && nap(100ms)) {
              again = true;
              return;
            }
            ++failed;
            std::cout << "reply " << i << " error " << render(e) << std::endl;
          });
    }
  }
  std::cout << "done ok=" << ok << " failed=" << failed << std::endl;
  int status = ok == o.count ? 0 : 1;
  if (o.watch) {
    self->monitor(proxy);
    bool down = false;
    auto deadline = clock_type::now() + seconds(o.timeout);
    while (!down && stop_requested == 0 && clock_type::now() < deadline)
      self->receive(
        [&](caf::down_msg& msg) {
          std::cout << "down " << render(msg.reason) << std::endl;
          down = true;
        },
        caf::after(100ms) >> [] {});
    if (!down) {
      std::cout << "no down message" << std::endl;
      status = 1;
    }
  }
  return status;
}

int route(const options&) {
  std::cout << "ready" << std::endl;
  while (nap(100ms)) {
  }
  return 0;
}

int publish(const module_handles& m, const options& o) {
  std::cout << "ready" << std::endl;
  for (int32_t v = 1; v <= static_cast<int32_t>(o.count); ++v) {
    caf::anon_send(m.apps, atom::publish_v, o.topic, caf::make_message(v));
    std::cout << "published " << v << std::endl;
    if (!nap(std::chrono::milliseconds(o.period_ms)))
      break;
  }
  return 0;
}

int subscribe(caf::scoped_actor& self, const module_handles& m,
              const options& o) {
  auto rec = self->spawn(recorder, caf::actor_cast<caf::actor>(self));
  caf::error err;
  self->request(m.apps, 5s, atom::subscribe_v, o.topic, rec)
    .receive([] {}, [&](caf::error& e) { err = e; });
  if (err) {
    std::cout << "error " << render(err) << std::endl;
    self->send_exit(rec, caf::exit_reason::user_shutdown);
    return 2;
  }
  std::cout << "ready" << std::endl;
  uint32_t received = 0;
  auto deadline = clock_type::now() + seconds(o.timeout);
  while (received < o.count && stop_requested == 0
         && clock_type::now() < deadline)
    self->receive(
      [&](int32_t v) {
        ++received;
        std::cout << "value " << v << std::endl;
      },
      caf::after(100ms) >> [] {});
  self->send_exit(rec, caf::exit_reason::user_shutdown);
  std::cout << "done values=" << received << std::endl;
  return received == o.count ? 0 : 1;
}

} // namespace

int main(int argc, char** argv) {
  options o;
  CLI::App app{"herm-apo-peer: one HERM module with APOs, for tests"};
  app.fallthrough();
  app.add_option("--id", o.id, "static module id (0x30)");
  app.add_option("--udp", o.udp, "udp device LOCAL=PEER[,PEER...] (repeatable)");
  app.add_option("--emu", o.emu, "emu device DIR:PROFILE:STATION (repeatable)");
  app.add_option("--hello-ms", o.hello_ms, "hello interval, ms");
  app.add_option("--timeout", o.timeout, "seconds to wait (bind, replies, values)");
  auto* serve_cmd = app.add_subcommand("serve", "register an echo APO");
  serve_cmd->add_option("--name", o.name, "APO name")->required();
  auto* call_cmd = app.add_subcommand("call", "bind to an APO and send requests");
  call_cmd->add_option("--name", o.name, "APO name")->required();
  call_cmd->add_option("--count", o.count, "requests");
  call_cmd->add_option("--size", o.size, "bytes per request string");
  call_cmd->add_flag("--watch", o.watch, "then wait for the proxy's down message");
  auto* route_cmd = app.add_subcommand("route", "a router module without APOs");
  auto* pub_cmd = app.add_subcommand("publish", "publish int32 values 1..count");
  pub_cmd->add_option("--topic", o.topic, "topic")->required();
  pub_cmd->add_option("--period-ms", o.period_ms, "ms between values");
  pub_cmd->add_option("--count", o.count, "values");
  auto* sub_cmd = app.add_subcommand("subscribe", "print a topic's int32 values");
  sub_cmd->add_option("--topic", o.topic, "topic")->required();
  sub_cmd->add_option("--count", o.count, "values to wait for");
  app.require_subcommand(1);
  CLI11_PARSE(app, argc, argv);

  module_config mc;
  auto id = parse_module_id(o.id);
  if (!id || !is_unicast(*id) || *id >= first_dynamic_module) {
    std::cout << "error --id '" << o.id << "' is not a static module id"
              << std::endl;
    return 2;
  }
  mc.routing.id = *id;
  mc.routing.hello_interval = std::chrono::milliseconds(o.hello_ms);
  mc.apps.unreachable_grace = 500ms;
  mc.apps.subscription_lease = 1500ms;
  mc.apps.rebind_interval = 300ms;
  for (auto& arg : o.udp) {
    auto dev = parse_udp(arg, mc.devices.size());
    if (!dev) {
      std::cout << "error --udp '" << arg << "' is not LOCAL=PEER[,PEER...]"
                << std::endl;
      return 2;
    }
    mc.devices.push_back(std::move(*dev));
  }
  for (auto& arg : o.emu) {
    auto dev = parse_emu(arg, mc.devices.size());
    if (!dev) {
      std::cout << "error --emu '" << arg << "' is not DIR:PROFILE:STATION"
                << std::endl;
      return 2;
    }
    mc.devices.push_back(std::move(*dev));
  }
  std::signal(SIGTERM, [](int) { stop_requested = 1; });
  std::signal(SIGINT, [](int) { stop_requested = 1; });

  caf::actor_system_config cfg;
  configure(cfg);
  caf::actor_system sys{cfg};
  auto m = start_module(sys, mc);
  if (!m) {
    std::cout << "error " << render(m.error()) << std::endl;
    return 2;
  }
  int status = 0;
  {
    caf::scoped_actor self{sys};
    if (serve_cmd->parsed())
      status = serve(self, *m, o);
    else if (call_cmd->parsed())
      status = call(self, *m, o);
    else if (route_cmd->parsed())
      status = route(o);
    else if (pub_cmd->parsed())
      status = publish(*m, o);
    else
      status = subscribe(self, *m, o);
  }
  stop_module(*m);
  return status;
}
