// herm-example-calculator: a remote calculator in two processes, the
// smallest complete use of HERM's Application Support Layer.
//
//   herm-example-calculator serve        (module 0x20, UDP port 47100)
//   herm-example-calculator call         (module 0x21, UDP port 47101)
//
// The serving module registers an application object (APO) named
// "calculator"; the calling module binds to it by name and sends it
// requests as if it were a local actor. The modules talk over UDP on
// loopback here; over CAN, IEEE 1394 or a serial line the code is the same.
// Each process also serves a control socket named after its role
// ("calculator", "caller"), so hermctl sees it as it sees hermd:
// `hermctl --name calculator topic echo calculator.results`.
// docs/user-guide quotes the regions marked "// [name]" ... "// [name-end]".

#include <atomic>
#include <chrono>
#include <csignal>
#include <iostream>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include <herm/herm.hpp>

using namespace std::chrono_literals;

// [type]
// Message types of our own: plain structs, each made a HERM message type by
// one line that lists its fields. That is all they need to travel between
// modules (HERM marshals them field by field) and to be printed and typed
// by name in hermctl (`hermctl call calculator '{"a":1,"b":2,"op":"+"}'
// -t calc_request`).
struct calc_request {
  int32_t a = 0;
  int32_t b = 0;
  std::string op; // "+", "-", "*" or "/"
};
HERM_MESSAGE(calc_request, a, b, op)

struct calc_result {
  calc_request request;
  int32_t value = 0;
};
HERM_MESSAGE(calc_result, request, value)

// Our own type-ID block starts where HERM's ends. Both modules register it:
// a type's name ("calc_request") identifies it on the wire.
CAF_BEGIN_TYPE_ID_BLOCK(calculator_example, caf::id_block::herm::end)
  CAF_ADD_TYPE_ID(calculator_example, (calc_request))
  CAF_ADD_TYPE_ID(calculator_example, (calc_result))
CAF_END_TYPE_ID_BLOCK(calculator_example)
// [type-end]

namespace {

// Set by SIGTERM/SIGINT, which may run on any thread (CAF's workers
// included): a lock-free atomic, not a volatile sig_atomic_t, which only
// the interrupted thread may read safely.
std::atomic<bool> stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free);

/// Prints one whole line: the topic listener prints from another thread.
void say(const std::string& line) {
  std::cout << line + "\n" << std::flush;
}

// [apo]
// The APO is an ordinary CAF actor. What it returns goes back to the caller;
// an error is a value too and reaches the caller as a caf::error. It also
// publishes every result on the topic "calculator.results", for whoever
// subscribed, on any module.
caf::behavior calculator(herm::app_support_actor apps) {
  auto compute = [](const calc_request& r) -> caf::expected<int32_t> {
    if (r.op == "+")
      return r.a + r.b;
    if (r.op == "-")
      return r.a - r.b;
    if (r.op == "*")
      return r.a * r.b;
    if (r.op == "/" && r.b != 0)
      return r.a / r.b;
    return herm::make_error(herm::ec::invalid_parameter,
                            "cannot compute " + std::to_string(r.a) + " "
                              + r.op + " " + std::to_string(r.b));
  };
  return {
    [=](const calc_request& r) -> caf::result<int32_t> {
      auto x = compute(r);
      if (!x)
        return x.error();
      herm::publish(apps, "calculator.results", calc_result{r, *x});
      return *x;
    },
  };
}
// [apo-end]

// [start]
/// Starts this process's module in code: one UDP interface on loopback,
/// and its control socket under `name` (where hermctl looks for it). The
/// module stops when the result goes out of scope.
caf::expected<herm::served_module> start(caf::actor_system& sys,
                                         const std::string& name,
                                         const std::string& socket,
                                         herm::module_id id, uint16_t port,
                                         const std::string& peers) {
  herm::module_config mc;
  mc.routing.id = id;
  mc.routing.hello_interval = 100ms; // converge fast (default: 1 s)
  mc.devices.push_back({"eth0", "udp", "127.0.0.1:" + std::to_string(port),
                        {{"peers", peers}}});
  return herm::serve_module(sys, mc, name, socket);
}

/// Or from a configuration file, the same one hermd reads
/// (docs/user-guide.md, "Configuration reference"); its errors name the
/// file, line and field, and its control section names the socket.
caf::expected<herm::served_module> start_from(caf::actor_system& sys,
                                              const std::string& path) {
  auto cfg = herm::load_config(path);
  if (!cfg)
    return cfg.error();
  return herm::serve_module(sys, cfg->module, cfg->name,
                            cfg->control_socket.empty() ? "-"
                                                        : cfg->control_socket);
}
// [start-end]

int serve(caf::actor_system& sys, const herm::module_handles& m, int seconds) {
  caf::scoped_actor self{sys};
  // [register]
  // Registering makes the actor discoverable by name and by type from every
  // module; it stays registered until it exits.
  auto apo = sys.spawn(calculator, m.apps);
  caf::error err;
  self->request(m.apps, 5s, herm::atom::add_v, std::string{"calculator"},
                std::string{"example.calculator"}, apo)
    .receive(
      [](herm::apo_ref& ref) {
        std::cout << "registered '" << ref.name << "' as APO " << ref.apo
                  << std::endl;
      },
      [&](caf::error& e) { err = e; });
  // [register-end]
  if (err) {
    say("error " + herm::render(err));
    self->send_exit(apo, caf::exit_reason::user_shutdown);
    return 1;
  }
  auto until = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  while (!stop_requested
         && (seconds <= 0 || std::chrono::steady_clock::now() < until))
    std::this_thread::sleep_for(50ms);
  self->send_exit(apo, caf::exit_reason::user_shutdown);
  return 0;
}

// [bind]
// Finds the APO named "calculator" anywhere in the network and returns a
// proxy: a local caf::actor that stands for it. Right after start-up the
// routes are still converging: bind_within keeps looking until its
// deadline, then fails with a typed error (herm.not_found, herm.no_route).
caf::actor bind_calculator(caf::actor_system& sys, herm::app_support_actor asl) {
  auto proxy = herm::bind_within(sys, asl, "calculator", 10s);
  if (!proxy) {
    say("error " + herm::render(proxy.error()));
    return {};
  }
  return *proxy;
}
// [bind-end]

int call(caf::actor_system& sys, const herm::module_handles& m) {
  caf::scoped_actor self{sys};
  // [subscribe]
  // Any actor can subscribe to a topic and receives every value published
  // on any module. A typed subscription gets each calc_result with its
  // topic, publishing module and time.
  auto listener = herm::subscribe<calc_result>(
    sys, m.apps, "calculator.results",
    [](const herm::topic_message<calc_result>& x) {
      auto& r = x.value.request;
      say("published by " + herm::to_hex(x.publisher) + ": "
          + std::to_string(r.a) + " " + r.op + " " + std::to_string(r.b)
          + " = " + std::to_string(x.value.value));
    });
  if (!listener) {
    say("error " + herm::render(listener.error()));
    return 1;
  }
  // [subscribe-end]
  auto proxy = bind_calculator(sys, m.apps);
  if (!proxy) {
    self->send_exit(*listener, caf::exit_reason::user_shutdown);
    return 1;
  }
  // A monitor on the proxy learns when the calculator exits or its module
  // becomes unreachable, like a monitor on any actor.
  self->monitor(proxy);
  int failures = 0;
  for (auto& r : {calc_request{40, 2, "+"}, calc_request{6, 7, "*"},
                  calc_request{100, 58, "-"}, calc_request{84, 2, "/"}}) {
    // The request crosses the network; the reply comes back here.
    self->request(proxy, 5s, r).receive(
      [&](int32_t result) {
        say("result " + std::to_string(r.a) + " " + r.op + " "
            + std::to_string(r.b) + " = " + std::to_string(result));
      },
      [&](caf::error& err) {
        say("error " + herm::render(herm::typed_error(err)));
        ++failures;
      });
  }
  // Errors come back as values: dividing by zero is refused remotely.
  self->request(proxy, 5s, calc_request{7, 0, "/"}).receive(
    [&](int32_t) { ++failures; },
    [&](caf::error& err) {
      say("refused 7 / 0: " + herm::render(herm::typed_error(err)));
    });
  // Had the calculator gone away meanwhile, its down message would be here.
  self->receive(
    [&](caf::down_msg& down) {
      say("calculator gone: " + herm::render(down.reason));
    },
    caf::after(0ms) >> [] {});
  // Give the published results a moment to arrive before leaving.
  std::this_thread::sleep_for(500ms);
  self->send_exit(*listener, caf::exit_reason::user_shutdown);
  return failures == 0 ? 0 : 1;
}

} // namespace

int main(int argc, char** argv) {
  CLI::App app{"herm-example-calculator: a remote calculator over HERM"};
  app.fallthrough();
  uint16_t port = 0;
  std::string peer;
  std::string config;
  std::string socket;
  int seconds = 0;
  app.add_option("--port", port, "local UDP port (serve: 47100, call: 47101)");
  app.add_option("--peer", peer, "the other module's UDP address(es), comma-separated");
  app.add_option("--config", config,
                 "start the module from this configuration file instead");
  app.add_option("--control", socket,
                 "control socket (default: where hermctl looks for the "
                 "module named calculator or caller; -: none)");
  auto* serve_cmd = app.add_subcommand("serve", "register the calculator APO");
  serve_cmd->add_option("--seconds", seconds, "stop after N seconds (0: on SIGINT)");
  app.add_subcommand("call", "bind to the calculator and send it requests");
  app.require_subcommand(1);
  CLI11_PARSE(app, argc, argv);
  bool serving = serve_cmd->parsed();
  if (port == 0)
    port = serving ? 47100 : 47101;
  if (peer.empty())
    peer = serving ? "127.0.0.1:47101" : "127.0.0.1:47100";
  std::signal(SIGTERM, [](int) { stop_requested = true; });
  std::signal(SIGINT, [](int) { stop_requested = true; });

  // HERM's types, then ours.
  caf::actor_system_config cfg;
  herm::configure(cfg);
  herm::add_message_types<caf::id_block::calculator_example>(cfg);
  caf::actor_system sys{cfg};
  auto m = config.empty() ? start(sys, serving ? "calculator" : "caller",
                                  socket, serving ? 0x20 : 0x21, port, peer)
                          : start_from(sys, config);
  if (!m) {
    say("error " + herm::render(m.error()));
    return 1;
  }
  return serving ? serve(sys, *m, seconds) : call(sys, *m);
}
