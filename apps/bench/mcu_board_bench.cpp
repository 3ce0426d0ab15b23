// The microcontroller client on RS232C (issue 17): a C++ module (the main
// controller's side, started in this process with herm::run_module) calls
// the echo APO of a board module over the paced null-modem cable of
// channels/testing/null_modem.hpp at 19,200 baud, 8N1, MTU 32.
//
// Two servers, each on a cable of its own, measured in the same run:
//   hermc_board  herm-mcu-board (apps/mcu/host: the C client's host build,
//                the board's main loop on a tty) with `--echo echo`, as a
//                child process: the board;
//   cxx_module   a second HERM module in this process with the same echo
//                APO (a string in, "echo:" + string out): the C++ stack on
//                both ends, the peer.
// The client binds to "echo" by name (discovery over the cable) and sends
// strings of exactly `size` bytes; every reply is checked.
//
// round_trip/SERVER/size:S   requests one at a time, the next when the reply
//   arrived; each timed from the request leaving the client's actor to the
//   reply reaching it. Counters (ms): p50_ms, p90_ms, min_ms, max_ms; and
//   wire bytes per request on each direction (req_wire_B, resp_wire_B: what
//   the cable carried, hellos and updates of the period included) next to
//   the framing's expected bytes for the request and response packets
//   (req_expect_B, resp_expect_B, from docs/protocol.md: fragment header,
//   CRC-32 of a fragmented packet, CRC-16, COBS, delimiter; the packets'
//   sizes from the C++ codecs: data header, ASL request/response, APO
//   payload).
// goodput/SERVER/size:S/window:W   `count` requests back to back with W in
//   flight (W 1: each sent when the previous reply arrived; W 2: the next
//   request is on the line while the board answers). Counters: up_Bps and
//   down_Bps (string bytes per second carried client->board and back: S and
//   S + 5 per request), line_Bps (baud / 10 = 1,920 B/s per direction),
//   up_ratio / down_ratio (against line_Bps), up_busy / down_busy (wire
//   bytes / line capacity over the period), up_eff / down_eff (string bytes
//   / wire bytes, measured), up_eff_expect / down_eff_expect (string bytes /
//   expected wire bytes of one packet) and frame_eff_expect (packet bytes /
//   expected wire bytes: COBS + CRC-16 + fragment header alone).
//
// Every case: a bounded count of requests and a deadline; a lost, failed or
// wrong reply stops the case with an error (the line is clean). Manual time
// of a case: first request sent to last reply received.
//
// Run: build/bin/bench_mcu_board   (about 45 s: two set-ups of a few
// seconds each, then line time)

#include <benchmark/benchmark.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"

#include "actors/asl_wire.hpp"
#include "actors/marshal.hpp"
#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "apps/bench/bench_common.hpp"
#include "channels/testing/null_modem.hpp"
#include "routing/wire.hpp"

extern char** environ;

using namespace herm;
using namespace std::chrono_literals;

namespace {

using clock_type = std::chrono::steady_clock;

constexpr uint64_t baud = 19200;
constexpr unsigned bits_per_char = 10;
constexpr size_t mtu = 32;
constexpr double line_Bps = double(baud) / bits_per_char;

/// Bound of the set-up (the route to the server and the binding).
constexpr auto setup_deadline = 30s;

/// Bound of one request.
constexpr auto request_timeout = 10s;

enum class server_kind { hermc_board, cxx_module };

// -- the expected wire bytes (docs/protocol.md) ------------------------------------

/// Bytes on the wire for one frame of `n` bytes: CRC-16 (2), COBS (1 for
/// n + 2 <= 254), delimiter (1). "Serial framing", "Frame on the wire".
size_t frame_wire(size_t n) {
  return n + 2 + 1 + (n + 2) / 254 + 1;
}

/// Bytes on the wire for one packet of `p` bytes at MTU 32 ("Fragment
/// header"): one single frame (1 header byte) when p + 1 <= MTU; else the
/// stream p + CRC-32 (4) in a first frame (header byte + LEB128 length)
/// and consecutive frames (1 header byte each: narrow sequence numbers
/// below MTU 64).
size_t packet_wire(size_t p) {
  if (p + 1 <= mtu)
    return frame_wire(p + 1);
  size_t len_bytes = p < 128 ? 1 : p < 16384 ? 2 : 3;
  size_t stream = p + 4;
  size_t first = mtu - 1 - len_bytes; // < stream, since p + 1 > mtu
  size_t total = frame_wire(mtu);
  size_t rest = stream - first;
  while (rest > 0) {
    auto k = std::min(rest, mtu - 1);
    total += frame_wire(1 + k);
    rest -= k;
  }
  return total;
}

/// The data packet that carries `msg` (an ASL message): data header and
/// the encoded message, as the C++ stack sends it to a neighbour.
size_t packet_size(const asl_message& msg) {
  byte_buffer out;
  data_header h;
  h.protocol = asl_protocol;
  encode(h, out);
  encode(msg, out);
  return out.size();
}

/// Request and response packet sizes for a string of `size` bytes.
std::pair<size_t, size_t> packet_sizes(caf::actor_system& sys, size_t size) {
  auto req = marshal(sys, caf::make_message(std::string(size, 'x')));
  auto resp = marshal(sys, caf::make_message(std::string(size + 5, 'x')));
  if (!req || !resp)
    return {0, 0};
  return {packet_size(asl_request{1, 1, *req}),
          packet_size(asl_response{1, true, *resp, {}})};
}

// -- the board process -----------------------------------------------------------------

/// herm-mcu-board as a child process, its output in `log`; stopped (SIGTERM,
/// then SIGKILL after 2 s) when this goes away.
class board_process {
public:
  board_process(const std::string& device, const std::string& log) {
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    std::vector<std::string> args{HERM_MCU_BOARD_BIN, "--device", device,
                                  "--baud", std::to_string(baud), "--echo",
                                  "echo"};
    std::vector<char*> argv;
    for (auto& a : args)
      argv.push_back(a.data());
    argv.push_back(nullptr);
    if (posix_spawn(&pid_, argv[0], &fa, nullptr, argv.data(), environ) != 0)
      pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }

  board_process(const board_process&) = delete;
  board_process& operator=(const board_process&) = delete;

  ~board_process() {
    if (pid_ <= 0 || !running())
      return;
    ::kill(pid_, SIGTERM);
    for (int i = 0; i < 200; ++i) {
      if (::waitpid(pid_, nullptr, WNOHANG) != 0)
        return;
      std::this_thread::sleep_for(10ms);
    }
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }

  bool started() const {
    return pid_ > 0;
  }

  /// False once the process ended (then reaped: never signalled again).
  bool running() {
    if (pid_ > 0 && ::waitpid(pid_, nullptr, WNOHANG) != 0)
      pid_ = -1;
    return pid_ > 0;
  }

private:
  pid_t pid_ = -1;
};

// -- a rig: cable, server and client ------------------------------------------------------

device_config serial_end(const std::string& path) {
  return {"rs0", "serial", path,
          {{"baud", std::to_string(baud)}, {"mtu", std::to_string(mtu)}}};
}

module_config module_on(module_id id, const std::string& path) {
  module_config mc;
  mc.routing.id = id;
  mc.routing.hello_interval = 1000ms; // the board's own interval
  mc.apps.request_timeout = request_timeout;
  mc.devices.push_back(serial_end(path));
  return mc;
}

/// The echo APO of the C++ server, as the board's (board.c, --echo).
caf::behavior echo_apo(caf::event_based_actor*) {
  return {
    [](std::string& s) -> std::string { return "echo:" + s; },
  };
}

/// One cable with a server on end B and the client module (0x10) on end A,
/// bound to the server's "echo". Everything it started stops when it goes
/// away (the client and the C++ server before the actor system).
class rig {
public:
  rig(caf::actor_system& sys, server_kind kind) : kind_(kind) {
    test::null_modem::config c;
    c.baud = baud;
    c.bits_per_char = bits_per_char;
    cable_ = test::null_modem::open(c, error_);
    if (!cable_) {
      error_ = "no pseudo-terminals: " + error_;
      return;
    }
    if (kind == server_kind::hermc_board) {
      board_ = std::make_unique<board_process>(cable_->path_b(),
                                               dir_.path() + "/board.log");
      if (!board_->started()) {
        error_ = "cannot start " HERM_MCU_BOARD_BIN;
        return;
      }
    } else {
      auto m = run_module(sys, module_on(0x21, cable_->path_b()));
      if (!m) {
        error_ = "server module: " + render(m.error());
        return;
      }
      server_ = std::move(*m);
      caf::scoped_actor self{sys};
      apo_ = self->spawn(echo_apo);
      caf::error err;
      self
        ->request(server_->apps, 5s, atom::add_v, std::string{"echo"},
                  std::string{"test.echo"}, apo_)
        .receive([](apo_ref&) {}, [&](caf::error& e) { err = e; });
      if (err) {
        error_ = "echo APO: " + render(err);
        return;
      }
    }
    auto m = run_module(sys, module_on(0x10, cable_->path_a()));
    if (!m) {
      error_ = "client module: " + render(m.error());
      return;
    }
    client_ = std::move(*m);
    bind(sys);
  }

  ~rig() {
    if (apo_)
      caf::anon_send_exit(apo_, caf::exit_reason::user_shutdown);
    client_.stop();
    server_.stop();
  }

  /// Empty when the rig is ready, else what went wrong.
  const std::string& error() const {
    return error_;
  }

  server_kind kind() const {
    return kind_;
  }

  caf::actor proxy() const {
    return proxy_;
  }

  test::null_modem& cable() {
    return *cable_;
  }

  /// The board's output so far (empty for the C++ server).
  std::string board_log() const {
    std::ifstream in{dir_.path() + "/board.log"};
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

private:
  /// Binds by name, retrying while routes converge; bounded.
  void bind(caf::actor_system& sys) {
    caf::scoped_actor self{sys};
    auto until = clock_type::now() + setup_deadline;
    caf::error err;
    while (!proxy_ && clock_type::now() < until) {
      if (board_ && !board_->running()) {
        error_ = "herm-mcu-board ended: " + board_log();
        return;
      }
      self
        ->request(client_->apps, 5s, atom::bind_v,
                  bind_request{query_by::name, "echo", 1000, false, false})
        .receive([&](caf::actor& p) { proxy_ = p; },
                 [&](caf::error& e) { err = e; });
      if (!proxy_)
        std::this_thread::sleep_for(100ms);
    }
    if (!proxy_)
      error_ = "no binding to 'echo' within "
               + std::to_string(setup_deadline.count()) + " s: "
               + (err ? render(err) : std::string{"?"});
  }

  server_kind kind_;
  std::string error_;
  bench::scratch_dir dir_{"herm-mcu-bench"};
  std::unique_ptr<test::null_modem> cable_;
  std::unique_ptr<board_process> board_;
  running_module server_;
  caf::actor apo_;
  running_module client_;
  caf::actor proxy_;
};

// -- the process-wide state ------------------------------------------------------------------

/// One actor system for the whole run, and the rig of the server last
/// measured (a case for the other server replaces it: one set-up per
/// server, not per case).
struct world {
  caf::actor_system_config cfg;
  std::unique_ptr<caf::actor_system> sys;
  std::unique_ptr<rig> current;

  world() {
    configure(cfg);
    sys = std::make_unique<caf::actor_system>(cfg);
  }

  ~world() {
    current.reset();
    sys.reset();
  }

  rig& rig_for(server_kind kind) {
    if (!current || current->kind() != kind || !current->error().empty()) {
      current.reset();
      current = std::make_unique<rig>(*sys, kind);
    }
    return *current;
  }
};

std::unique_ptr<world> the_world;

// -- the exchange --------------------------------------------------------------------------

/// Request i's string: exactly `size` bytes, distinct per i.
std::string make_text(uint32_t i, size_t size) {
  std::string s = std::to_string(i) + ":";
  while (s.size() < size)
    s += static_cast<char>('a' + (i * 7 + s.size() * 13) % 26);
  s.resize(size);
  return s;
}

/// What a run of requests gave: every round trip, the first error.
struct run_result {
  std::vector<double> rtt_ms;
  clock_type::time_point first_sent;
  clock_type::time_point last_done;
  uint32_t failed = 0;
  std::string first_error;
};

/// Keeps `window` requests in flight until `count` are answered, then
/// sends `true` to `main`. Runs on the loop thread; `out` is read by `main`
/// only after that message.
caf::behavior pump(caf::event_based_actor* self, caf::actor proxy,
                   caf::actor main, uint32_t count, size_t size,
                   uint32_t window, std::shared_ptr<run_result> out) {
  auto next = std::make_shared<uint32_t>(0);
  auto done = std::make_shared<uint32_t>(0);
  auto send_one = std::make_shared<std::function<void()>>();
  *send_one = [=] {
    auto i = (*next)++;
    auto text = make_text(i, size);
    auto expected = "echo:" + text;
    auto t0 = clock_type::now();
    if (i == 0)
      out->first_sent = t0;
    auto finish = [=](const std::string& problem) {
      auto t1 = clock_type::now();
      out->rtt_ms.push_back(
        std::chrono::duration<double, std::milli>(t1 - t0).count());
      out->last_done = t1;
      if (!problem.empty() && out->failed++ == 0)
        out->first_error = "request " + std::to_string(i) + ": " + problem;
      if (++*done == count) {
        self->send(main, true);
        self->quit();
      } else if (*next < count) {
        (*send_one)();
      }
    };
    self->request(proxy, request_timeout, text)
      .then(
        [=](std::string& reply) {
          finish(reply == expected ? std::string{}
                                   : "a wrong reply of "
                                       + std::to_string(reply.size())
                                       + " bytes");
        },
        [=](caf::error& e) { finish(render(e)); });
  };
  for (uint32_t k = 0; k < std::min(window, count); ++k)
    (*send_one)();
  // The closure holds itself through send_one: break the cycle at exit.
  self->attach_functor([send_one] { *send_one = nullptr; });
  return {};
}

/// Runs `count` requests of `size` bytes with `window` in flight on the
/// rig; nothing (after skipping the case) on any failure.
std::shared_ptr<run_result> exchange(benchmark::State& state, rig& r,
                                     uint32_t count, size_t size,
                                     uint32_t window) {
  auto& sys = *the_world->sys;
  auto out = std::make_shared<run_result>();
  caf::scoped_actor self{sys};
  auto main = caf::actor_cast<caf::actor>(self);
  sys.spawn(pump, r.proxy(), main, count, size, window, out);
  bool finished = false;
  self->receive([&](bool) { finished = true; },
                caf::after(request_timeout * (count + 1)) >> [] {});
  if (!finished) {
    state.SkipWithError("the requests did not end in time");
    return nullptr;
  }
  if (out->failed > 0) {
    auto what = std::to_string(out->failed) + " of " + std::to_string(count)
                + " requests failed on a clean line; first: "
                + out->first_error;
    state.SkipWithError(what.c_str());
    return nullptr;
  }
  return out;
}

rig* ready_rig(benchmark::State& state, server_kind kind) {
  auto& r = the_world->rig_for(kind);
  if (!r.error().empty()) {
    state.SkipWithError(r.error().c_str());
    return nullptr;
  }
  return &r;
}

const char* server_name(server_kind kind) {
  return kind == server_kind::hermc_board ? "hermc board (herm-mcu-board)"
                                          : "C++ module";
}

double percentile(std::vector<double> xs, double q) {
  std::sort(xs.begin(), xs.end());
  auto rank = static_cast<size_t>(std::ceil(q * double(xs.size())));
  return xs[std::min(rank > 0 ? rank - 1 : 0, xs.size() - 1)];
}

/// Requests of round_trip per size: a few seconds of line time each.
uint32_t round_trip_count(size_t size) {
  return size <= 16 ? 60 : 30;
}

constexpr uint32_t warm_up = 3;

void round_trip(benchmark::State& state, server_kind kind) {
  auto size = static_cast<size_t>(state.range(0));
  auto* r = ready_rig(state, kind);
  if (!r)
    return;
  auto count = round_trip_count(size);
  for (auto _ : state) {
    if (!exchange(state, *r, warm_up, size, 1))
      return;
    auto up0 = r->cable().a_to_b().written;
    auto down0 = r->cable().b_to_a().written;
    auto res = exchange(state, *r, count, size, 1);
    if (!res)
      return;
    state.SetIterationTime(
      std::chrono::duration<double>(res->last_done - res->first_sent).count());
    auto [req_p, resp_p] = packet_sizes(*the_world->sys, size);
    state.counters["p50_ms"] = percentile(res->rtt_ms, 0.5);
    state.counters["p90_ms"] = percentile(res->rtt_ms, 0.9);
    state.counters["min_ms"] = percentile(res->rtt_ms, 0);
    state.counters["max_ms"] = percentile(res->rtt_ms, 1);
    state.counters["requests"] = count;
    state.counters["req_pkt_B"] = double(req_p);
    state.counters["resp_pkt_B"] = double(resp_p);
    state.counters["req_expect_B"] = double(packet_wire(req_p));
    state.counters["resp_expect_B"] = double(packet_wire(resp_p));
    state.counters["req_wire_B"]
      = double(r->cable().a_to_b().written - up0) / count;
    state.counters["resp_wire_B"]
      = double(r->cable().b_to_a().written - down0) / count;
    state.counters["line_ms_expect"]
      = 1000.0 * double(packet_wire(req_p) + packet_wire(resp_p)) / line_Bps;
  }
  state.SetLabel(std::string{server_name(kind)} + ", "
                 + std::to_string(size) + " B strings, 19,200 baud 8N1, MTU 32");
}

void goodput(benchmark::State& state, server_kind kind) {
  auto size = static_cast<size_t>(state.range(0));
  auto window = static_cast<uint32_t>(state.range(1));
  auto* r = ready_rig(state, kind);
  if (!r)
    return;
  constexpr uint32_t count = 40;
  for (auto _ : state) {
    if (!exchange(state, *r, warm_up, size, window))
      return;
    auto up0 = r->cable().a_to_b().written;
    auto down0 = r->cable().b_to_a().written;
    auto res = exchange(state, *r, count, size, window);
    if (!res)
      return;
    auto seconds
      = std::chrono::duration<double>(res->last_done - res->first_sent).count();
    state.SetIterationTime(seconds);
    auto up_wire = double(r->cable().a_to_b().written - up0);
    auto down_wire = double(r->cable().b_to_a().written - down0);
    auto up_bytes = double(count * size);
    auto down_bytes = double(count * (size + 5));
    auto [req_p, resp_p] = packet_sizes(*the_world->sys, size);
    state.counters["up_Bps"] = up_bytes / seconds;
    state.counters["down_Bps"] = down_bytes / seconds;
    state.counters["line_Bps"] = line_Bps;
    state.counters["up_ratio"] = up_bytes / seconds / line_Bps;
    state.counters["down_ratio"] = down_bytes / seconds / line_Bps;
    state.counters["up_busy"] = up_wire / (line_Bps * seconds);
    state.counters["down_busy"] = down_wire / (line_Bps * seconds);
    state.counters["up_eff"] = up_bytes / up_wire;
    state.counters["down_eff"] = down_bytes / down_wire;
    state.counters["up_eff_expect"] = double(size) / packet_wire(req_p);
    state.counters["down_eff_expect"] = double(size + 5) / packet_wire(resp_p);
    state.counters["frame_eff_expect"]
      = double(req_p + resp_p) / double(packet_wire(req_p) + packet_wire(resp_p));
    state.counters["requests"] = count;
  }
  state.SetLabel(std::string{server_name(kind)} + ", "
                 + std::to_string(size) + " B strings, window "
                 + std::to_string(window) + ", 19,200 baud 8N1, MTU 32");
}

} // namespace

// Sizes: around a string of S bytes a request packet has 30 bytes more (data
// header 8; ASL version, kind, request id 8, APO id 4; APO payload version,
// count, name length, "@str", string length: 8) and a response 27 more
// besides "echo:" (ASL: version, kind, request id, ok). 8 B strings: 38 and
// 40 B packets, two frames each at MTU 32 (no request string fits one frame:
// the largest single-frame packet is 31 B); 100 B strings: 130 and 132 B, 5
// frames each. The counters report both.
BENCHMARK_CAPTURE(round_trip, hermc_board, server_kind::hermc_board)
  ->ArgNames({"size"})->Arg(8)->Arg(100)
  ->UseManualTime()->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(goodput, hermc_board, server_kind::hermc_board)
  ->ArgNames({"size", "window"})->Args({100, 1})->Args({100, 2})
  ->UseManualTime()->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(round_trip, cxx_module, server_kind::cxx_module)
  ->ArgNames({"size"})->Arg(8)->Arg(100)
  ->UseManualTime()->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(goodput, cxx_module, server_kind::cxx_module)
  ->ArgNames({"size", "window"})->Args({100, 1})->Args({100, 2})
  ->UseManualTime()->Iterations(1)->Unit(benchmark::kMillisecond);

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv))
    return 1;
  the_world = std::make_unique<world>();
  benchmark::RunSpecifiedBenchmarks();
  the_world.reset();
  return 0;
}
