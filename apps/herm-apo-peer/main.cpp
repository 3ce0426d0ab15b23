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
//   herm-apo-peer --id 0x31 --emu /tmp/l:ethernet:1 --emu-opt loss=0.3
//                 call --name echo --count 200 --reliable --window 8
//   herm-apo-peer --id 0x32 --emu /tmp/l:ethernet:2 --flap 2:3:emu0 route
//
// Fault injection (tests/faults): --emu-opt KEY=VALUE adds an option (loss,
// corrupt, duplicate, jitter_us, latency_us, seed) to every emu device;
// --flap AFTER:FOR[:DEVICE] sets loss 1 on the emu channels (of DEVICE
// only, e.g. "emu1") AFTER seconds from start (for `call`: from its first
// reply) for FOR seconds, then puts the configured loss back. Request strings carry a CRC-32 of themselves,
// which the echo APO checks ("corrupt" counts mismatches) and the caller
// compares with what it sent.
//
// Prints one flushed line per event on stdout: "ready", "served N ...",
// "reply I ok", "reply I bad ...", "reply I error ...", "done ok=K
// failed=F", "down REASON", "published V", "value V", "flap down",
// "flap up", "bad replies B", "stats asl ... nil ...", "error ...". Exit status: 0 success, 1 the
// exchange failed (a bad or missing reply, no down message, too few
// values), 2 bad arguments or the module did not start (the typed error is
// printed). SIGTERM and SIGINT end every role cleanly.

#include <atomic>
#include <csignal>
#include <map>
#include <mutex>
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

// Set by SIGTERM/SIGINT, which may run on any thread (CAF's workers
// included): a lock-free atomic, not a volatile sig_atomic_t, which only
// the interrupted thread may read safely.
std::atomic<bool> stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free);

/// Set by `call` at its first reply: a caller's --flap counts from there,
/// so that it falls among the requests however long start-up took.
std::atomic<bool> first_reply{false};

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
  // -- fault injection and reliable mode --
  std::vector<std::string> emu_opts;
  std::string flap;
  uint32_t tick_ms = 100;
  double request_timeout = 10;
  uint32_t rto_max_ms = 2000;
  bool reliable = false;
  bool rebind = false;
  uint32_t window = 1;
  uint32_t gap_ms = 0;
};

/// CRC-32 (IEEE 802.3, reflected), for request strings.
uint32_t crc32_of(const std::string& s) {
  uint32_t crc = 0xFFFFFFFF;
  for (unsigned char c : s) {
    crc ^= c;
    for (int k = 0; k < 8; ++k)
      crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

std::string hex8(uint32_t x) {
  static const char* digits = "0123456789abcdef";
  std::string result(8, '0');
  for (int i = 7; i >= 0; --i, x >>= 4)
    result[static_cast<size_t>(i)] = digits[x & 0xF];
  return result;
}

/// "I:BODY" followed by ":" and the CRC-32 of "I:BODY" in hex; -1 if `s`
/// is not of that form or its CRC does not match, else I.
int64_t check_text(const std::string& s) {
  if (s.size() < 10 || s[s.size() - 9] != ':')
    return -1;
  auto body = s.substr(0, s.size() - 9);
  if (hex8(crc32_of(body)) != s.substr(s.size() - 8))
    return -1;
  auto colon = body.find(':');
  if (colon == 0 || colon == std::string::npos || colon > 9)
    return -1;
  int64_t i = 0;
  for (size_t k = 0; k < colon; ++k) {
    if (body[k] < '0' || body[k] > '9')
      return -1;
    i = i * 10 + (body[k] - '0');
  }
  return i;
}

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

/// Request `i`'s string: at least `size` bytes, distinct for every `i` (a
/// decimal prefix, then a pattern derived from `i` and the position), then
/// ":" and its CRC-32 (check_text).
std::string make_text(uint32_t i, uint32_t size) {
  auto text = std::to_string(i) + ":";
  auto body = size > 9 ? size - 9 : 0;
  while (text.size() < body) {
    auto j = static_cast<uint32_t>(text.size());
    text += static_cast<char>('a' + (i * 7 + j * 13 + j / 26) % 26);
  }
  if (text.size() > body && body > std::to_string(i).size() + 1)
    text.resize(body);
  return text + ":" + hex8(crc32_of(text));
}

/// Sleeps `d` in short steps; false if a signal asked us to stop.
bool nap(std::chrono::milliseconds d) {
  auto until = clock_type::now() + d;
  while (!stop_requested && clock_type::now() < until)
    std::this_thread::sleep_for(std::min<clock_type::duration>(
      20ms, until - clock_type::now()));
  return !stop_requested;
}

// -- the actors ----------------------------------------------------------------------

/// What the echo APO saw: executions per request number, and strings
/// whose CRC did not match (delivered corrupted).
struct echo_log {
  std::mutex mtx;
  std::map<int64_t, uint32_t> runs;
  uint64_t corrupt = 0;
};

/// The APO of `serve`: echoes strings and adds pairs of int32.
caf::behavior echo_apo(caf::event_based_actor*,
                       std::shared_ptr<std::atomic<uint64_t>> served,
                       std::shared_ptr<echo_log> log) {
  return {
    [served, log](std::string& s) -> std::string {
      ++*served;
      auto i = check_text(s);
      {
        std::lock_guard<std::mutex> guard{log->mtx};
        if (i < 0)
          ++log->corrupt;
        else
          ++log->runs[i];
      }
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

/// Prints the ASL counters of reliable mode and the channels' receive
/// counters (summed over channels) on one line.
void print_stats(caf::scoped_actor& self, const module_handles& m) {
  app_support_stats a;
  self->request(m.apps, 5s, atom::get_v, atom::stats_v)
    .receive([&](app_support_stats& x) { a = x; }, [](caf::error&) {});
  channel_stats sum;
  std::vector<channel_entry> entries;
  self->request(m.io, 5s, atom::get_v, atom::channels_v)
    .receive([&](std::vector<channel_entry>& xs) { entries = std::move(xs); },
             [](caf::error&) {});
  for (auto& e : entries) {
    channel_actor ch;
    self->request(m.io, 5s, atom::get_v, e.id)
      .receive([&](channel_actor& x) { ch = x; }, [](caf::error&) {});
    if (!ch)
      continue;
    self->request(ch, 5s, atom::get_v, atom::stats_v)
      .receive(
        [&](channel_stats& cs) {
          sum.rx_frames += cs.rx_frames;
          sum.rx_packets += cs.rx_packets;
          sum.rx_malformed += cs.rx_malformed;
          sum.rx_reassembly_dropped += cs.rx_reassembly_dropped;
          sum.rx_duplicates += cs.rx_duplicates;
        },
        [](caf::error&) {});
  }
  std::cout << "stats asl requests_sent=" << a.requests_sent
            << " requests_served=" << a.requests_served
            << " reliable_sent=" << a.reliable_sent
            << " retransmissions=" << a.retransmissions
            << " duplicates_suppressed=" << a.duplicates_suppressed
            << " acks_sent=" << a.acks_sent
            << " acks_received=" << a.acks_received
            << " late_duplicates=" << a.late_duplicates
            << " reliable_waited=" << a.reliable_waited
            << " request_timeouts=" << a.request_timeouts
            << " rx_malformed=" << a.rx_malformed
            << " rx_unexpected_response=" << a.rx_unexpected_response
            << " nil rx_frames=" << sum.rx_frames
            << " rx_packets=" << sum.rx_packets
            << " rx_malformed=" << sum.rx_malformed
            << " rx_reassembly_dropped=" << sum.rx_reassembly_dropped
            << " rx_duplicates=" << sum.rx_duplicates << std::endl;
}

int serve(caf::scoped_actor& self, const module_handles& m, const options& o) {
  auto served = std::make_shared<std::atomic<uint64_t>>(0);
  auto log = std::make_shared<echo_log>();
  auto apo = self->spawn(echo_apo, served, log);
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
  uint64_t repeats = 0;
  size_t distinct = 0;
  uint64_t corrupt = 0;
  {
    std::lock_guard<std::mutex> guard{log->mtx};
    distinct = log->runs.size();
    for (auto& kv : log->runs)
      repeats += kv.second - 1;
    corrupt = log->corrupt;
  }
  std::cout << "served " << served->load() << " distinct=" << distinct
            << " repeats=" << repeats << " corrupt=" << corrupt << std::endl;
  print_stats(self, m);
  return 0;
}

/// Binds by name, retrying while routes converge (not_found, no_route).
caf::actor bind_by_name(caf::scoped_actor& self, const module_handles& m,
                        const std::string& name, clock_type::time_point until,
                        bool rebind = false, bool reliable = false) {
  caf::actor proxy;
  caf::error err;
  while (!proxy && !stop_requested && clock_type::now() < until) {
    self->request(m.apps, 5s, atom::bind_v,
                  bind_request{query_by::name, name, 1000, rebind, reliable})
      .receive([&](caf::actor& p) { proxy = p; },
               [&](caf::error& e) { err = e; });
    if (!proxy && !is(err, app_ec::not_found) && !is(err, routing_ec::no_route))
      break;
    if (!proxy)
      nap(100ms);
  }
  if (!proxy)
    std::cout << "error bind '" << name << "': "
              << (err ? render(err) : std::string{"interrupted"}) << std::endl;
  return proxy;
}

/// Sends one request and reports (index, status, reply or error) to
/// `main`: status 0 the expected echo, 1 another string, 2 an error.
caf::behavior requester(caf::event_based_actor* self, caf::actor proxy,
                        caf::actor main, uint32_t i, std::string text,
                        caf::timespan timeout) {
  auto expected = "echo:" + text;
  self->request(proxy, timeout, text)
    .then(
      [self, main, i, expected](std::string& reply) {
        self->send(main, i, int32_t{reply == expected ? 0 : 1}, reply);
      },
      [self, main, i](caf::error& e) {
        self->send(main, i, int32_t{2}, render(e));
      });
  return {};
}

int call(caf::scoped_actor& self, const module_handles& m, const options& o) {
  auto until = clock_type::now() + seconds(o.timeout);
  auto proxy = bind_by_name(self, m, o.name, until, o.rebind, o.reliable);
  if (!proxy)
    return 1;
  std::cout << "bound " << o.name << std::endl;
  uint32_t ok = 0, failed = 0, bad = 0;
  std::vector<uint32_t> todo;
  for (uint32_t i = o.count; i > 0; --i)
    todo.push_back(i - 1);
  uint32_t in_flight = 0;
  auto main = caf::actor_cast<caf::actor>(self);
  auto per_request = seconds(o.timeout);
  while ((!todo.empty() || in_flight > 0) && !stop_requested) {
    while (!todo.empty() && in_flight < std::max<uint32_t>(o.window, 1)) {
      auto i = todo.back();
      todo.pop_back();
      self->spawn(requester, proxy, main, i, make_text(i, o.size),
                  caf::timespan{per_request});
      ++in_flight;
      if (o.gap_ms > 0)
        nap(std::chrono::milliseconds(o.gap_ms));
    }
    self->receive(
      [&](uint32_t i, int32_t status, std::string& what) {
        --in_flight;
        if (status == 0) {
          ++ok;
          std::cout << "reply " << i << " ok" << std::endl;
          first_reply = true;
        } else if (status == 1) {
          ++bad;
          ++failed;
          std::cout << "reply " << i << " bad size=" << what.size() << std::endl;
        } else if (!o.reliable && what.find("no_route") != std::string::npos
                   && clock_type::now() < until) {
          // Plain mode: the binding proves the server has a route to us;
          // ours to it may still be converging.
          nap(100ms);
          todo.push_back(i);
        } else {
          ++failed;
          std::cout << "reply " << i << " error " << what << std::endl;
        }
      },
      caf::after(100ms) >> [] {});
  }
  // "bad" replies (a string other than the echo) are counted in failed too.
  std::cout << "done ok=" << ok << " failed=" << failed << std::endl;
  std::cout << "bad replies " << bad << std::endl;
  print_stats(self, m);
  int status = ok == o.count ? 0 : 1;
  if (o.watch) {
    self->monitor(proxy);
    bool down = false;
    auto deadline = clock_type::now() + seconds(o.timeout);
    while (!down && !stop_requested && clock_type::now() < deadline)
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

int route(caf::scoped_actor& self, const module_handles& m) {
  std::cout << "ready" << std::endl;
  while (nap(100ms)) {
  }
  print_stats(self, m);
  return 0;
}

/// --flap AFTER:FOR[:DEVICE]: loss 1 on the emu channels (of DEVICE only)
/// from AFTER to AFTER + FOR seconds, then the configured loss again. Runs
/// on its own thread; false if the argument does not parse.
bool parse_flap(const std::string& arg, double& after, double& len,
                std::string& device) {
  auto a = arg.find(':');
  if (a == std::string::npos)
    return false;
  auto b = arg.find(':', a + 1);
  try {
    after = std::stod(arg.substr(0, a));
    len = std::stod(arg.substr(a + 1, b == std::string::npos ? std::string::npos
                                                             : b - a - 1));
  } catch (...) {
    return false;
  }
  device = b == std::string::npos ? std::string{} : arg.substr(b + 1);
  return after >= 0 && len > 0;
}

void set_loss(caf::actor_system& sys, const module_handles& m,
              const std::string& device, const std::string& loss) {
  caf::scoped_actor self{sys};
  std::vector<channel_entry> entries;
  self->request(m.io, 5s, atom::get_v, atom::channels_v)
    .receive([&](std::vector<channel_entry>& xs) { entries = std::move(xs); },
             [](caf::error&) {});
  for (auto& e : entries) {
    if (e.request.device.rfind("emu", 0) != 0
        || (!device.empty() && e.request.device != device))
      continue;
    channel_actor ch;
    self->request(m.io, 5s, atom::get_v, e.id)
      .receive([&](channel_actor& x) { ch = x; }, [](caf::error&) {});
    if (ch)
      self->request(ch, 5s, atom::set_v, std::string{"loss"}, loss)
        .receive([](channel_info&) {},
                 [&](caf::error& err) {
                   std::cout << "error flap: " << render(err) << std::endl;
                 });
  }
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
  while (received < o.count && !stop_requested
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

/// Prints "error WHAT" (the line the tests read) and returns exit status 2.
int refuse(const std::string& what) {
  std::cout << "error " << what << std::endl;
  return 2;
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
  app.add_option("--emu-opt", o.emu_opts,
                 "KEY=VALUE option for every emu device (repeatable)");
  app.add_option("--flap", o.flap,
                 "AFTER:FOR[:DEVICE] seconds of loss 1 on the emu channels");
  app.add_option("--tick-ms", o.tick_ms, "ASL housekeeping tick, ms");
  app.add_option("--request-timeout", o.request_timeout,
                 "ASL request deadline, seconds");
  app.add_option("--rto-max-ms", o.rto_max_ms, "largest retransmission timeout");
  auto* serve_cmd = app.add_subcommand("serve", "register an echo APO");
  serve_cmd->add_option("--name", o.name, "APO name")->required();
  auto* call_cmd = app.add_subcommand("call", "bind to an APO and send requests");
  call_cmd->add_option("--name", o.name, "APO name")->required();
  call_cmd->add_option("--count", o.count, "requests");
  call_cmd->add_option("--size", o.size, "bytes per request string");
  call_cmd->add_flag("--watch", o.watch, "then wait for the proxy's down message");
  call_cmd->add_flag("--reliable", o.reliable, "bind in reliable mode");
  call_cmd->add_flag("--rebind", o.rebind, "a rebinding proxy");
  call_cmd->add_option("--window", o.window, "requests in flight at once");
  call_cmd->add_option("--gap-ms", o.gap_ms, "pause after sending each request");
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
  if (!id || !is_unicast(*id) || *id >= first_dynamic_module)
    return refuse("--id '" + o.id + "' is not a static module id");
  mc.routing.id = *id;
  mc.routing.hello_interval = std::chrono::milliseconds(o.hello_ms);
  mc.apps.unreachable_grace = 500ms;
  mc.apps.subscription_lease = 1500ms;
  mc.apps.rebind_interval = 300ms;
  mc.apps.tick = std::chrono::milliseconds(std::max<uint32_t>(o.tick_ms, 1));
  mc.apps.request_timeout = seconds(o.request_timeout);
  mc.apps.reliable_cache_ttl
    = std::max(mc.apps.reliable_cache_ttl, mc.apps.request_timeout + 5s);
  mc.apps.retransmit_max = std::chrono::milliseconds(o.rto_max_ms);
  mc.apps.retransmit_initial
    = std::min(mc.apps.retransmit_initial, mc.apps.retransmit_max);
  for (auto& arg : o.udp) {
    auto dev = parse_udp(arg, mc.devices.size());
    if (!dev)
      return refuse("--udp '" + arg + "' is not LOCAL=PEER[,PEER...]");
    mc.devices.push_back(std::move(*dev));
  }
  for (auto& arg : o.emu) {
    auto dev = parse_emu(arg, mc.devices.size());
    if (!dev)
      return refuse("--emu '" + arg + "' is not DIR:PROFILE:STATION");
    for (auto& kv : o.emu_opts) {
      auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0)
        return refuse("--emu-opt '" + kv + "' is not KEY=VALUE");
      dev->options[kv.substr(0, eq)] = kv.substr(eq + 1);
    }
    mc.devices.push_back(std::move(*dev));
  }
  double flap_after = 0, flap_len = 0;
  std::string flap_device;
  if (!o.flap.empty() && !parse_flap(o.flap, flap_after, flap_len, flap_device))
    return refuse("--flap '" + o.flap + "' is not AFTER:FOR[:DEVICE]");
  std::signal(SIGTERM, [](int) { stop_requested = true; });
  std::signal(SIGINT, [](int) { stop_requested = true; });

  caf::actor_system_config cfg;
  configure(cfg);
  caf::actor_system sys{cfg};
  auto m = start_module(sys, mc);
  if (!m)
    return refuse(render(m.error()));
  std::thread flapper;
  if (flap_len > 0) {
    std::string loss = "0";
    for (auto& kv : o.emu_opts)
      if (kv.rfind("loss=", 0) == 0)
        loss = kv.substr(5);
    bool is_caller = call_cmd->parsed();
    flapper = std::thread{[&sys, &m, flap_after, flap_len, flap_device, loss,
                           is_caller] {
      while (is_caller && !first_reply && nap(20ms)) {
        // A caller's flap counts from its first reply.
      }
      if (!nap(seconds(flap_after)))
        return;
      set_loss(sys, *m, flap_device, "1");
      std::cout << "flap down" << std::endl;
      nap(seconds(flap_len));
      set_loss(sys, *m, flap_device, loss);
      std::cout << "flap up" << std::endl;
    }};
  }
  int status = 0;
  {
    caf::scoped_actor self{sys};
    if (serve_cmd->parsed())
      status = serve(self, *m, o);
    else if (call_cmd->parsed())
      status = call(self, *m, o);
    else if (route_cmd->parsed())
      status = route(self, *m);
    else if (pub_cmd->parsed())
      status = publish(*m, o);
    else
      status = subscribe(self, *m, o);
  }
  if (flapper.joinable()) {
    stop_requested = true;
    flapper.join();
  }
  stop_module(*m);
  return status;
}
