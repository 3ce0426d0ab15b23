// herm-bench-rtt: request round-trip latency and one-way throughput between
// processes on 127.0.0.1, for HERM and for the systems a robot builder would
// pick instead, in one run (issue 7, "Benchmarks side by side with peers").
//
//   herm-bench-rtt                       the full default suite (minutes)
//   herm-bench-rtt --quick               a smoke run (seconds)
//   herm-bench-rtt --only herm,udp --sizes 16 --repeat 5 --json rtt.json
//   herm-bench-rtt --modes oneway,router --policies loop
//
// Modes: back-to-back and gap-10ms (request round trips between two
// processes), oneway (messages per second at the receiver under a credit
// window, 64 bytes by default), inprocess (round trips between two actors of
// one process: through HERM's application support layer, and plain CAF),
// router (HERM round trips across a third process, a router module).
//
// For every case (transport, payload size, back to back or with a gap) and
// every repetition, this process starts a fresh server and a fresh client
// (itself, re-executed with --role server / --role client), so no state
// carries over between cases. The client times each round trip with the
// monotonic clock and hands the times back on its stdout.
//
// Placements (--placements): every case runs in each, with raw UDP and DDS
// alongside, so ratios are taken within a placement: one-cpu (every
// process of the case pinned to vCPU 0) and per-cpu (server and router on
// vCPU 0, client on vCPU 1). Next to the times, per round trip and process
// (probes.hpp): thread wake-ups and voluntary switches and allocations over
// the timed part, and syscalls from a separate shorter counting pass
// (--syscall-count). Transports:
// transport.hpp; the table and the JSON hold every figure. Exit status 0
// when every available transport completed every case with positive
// figures, 1 otherwise, 2 on bad arguments.

#include <signal.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "apps/bench/peers/cases.hpp"
#include "apps/bench/peers/children.hpp"
#include "apps/bench/peers/per_round_trip.hpp"
#include "apps/bench/peers/probes.hpp"
#include "apps/bench/peers/transport.hpp"

using namespace herm::bench;
using namespace std::chrono_literals;

namespace {

// -- what is measured ---------------------------------------------------------------

struct run_figures {
  double p50 = 0, p99 = 0, min = 0, max = 0, mean = 0; // µs
  size_t n = 0;
  // oneway
  double msgs_per_s = 0, client_allocs = -1, server_allocs = -1;
  uint64_t sent = 0, received = 0, lost = 0, stalls = 0;
  // latency modes: counts per round trip of the timed part (syscalls: -1,
  // they come from the counting pass)
  per_rt counts = unmeasured();
};

struct case_result {
  variant v;
  const mode* m = nullptr;
  size_t size = 0;
  const placement* where = nullptr;
  std::vector<run_figures> runs;
  std::vector<std::string> errors;
  // latency modes: the syscall counting pass (probes.hpp), once per case
  per_rt syscall_pass = unmeasured();
  uint32_t syscall_round_trips = 0;
  std::string syscall_error;
};

double percentile(const std::vector<double>& sorted, double q) {
  auto rank = static_cast<size_t>(std::ceil(q * static_cast<double>(sorted.size())));
  return sorted[std::clamp<size_t>(rank, 1, sorted.size()) - 1];
}

double median(std::vector<double> xs) {
  std::sort(xs.begin(), xs.end());
  auto n = xs.size();
  return n % 2 == 1 ? xs[n / 2] : (xs[n / 2 - 1] + xs[n / 2]) / 2;
}

run_figures summarize(const std::vector<int64_t>& ns) {
  std::vector<double> us;
  us.reserve(ns.size());
  double sum = 0;
  for (auto x : ns) {
    us.push_back(static_cast<double>(x) / 1000.0);
    sum += us.back();
  }
  std::sort(us.begin(), us.end());
  run_figures f;
  f.n = us.size();
  if (us.empty())
    return f;
  f.p50 = percentile(us, 0.50);
  f.p99 = percentile(us, 0.99);
  f.min = us.front();
  f.max = us.back();
  f.mean = sum / static_cast<double>(us.size());
  return f;
}

// -- the child roles -----------------------------------------------------------------

} // namespace

const std::vector<transport>& herm::bench::transports() {
  static const std::vector<transport> all{
    {"udp", udp_server, udp_client, {}},
    {"herm", herm_server, herm_client, {}},
    {"caf", caf_server, caf_client, {}},
#ifdef HERM_BENCH_HAVE_ZMQ
    {"zmq", zmq_server, zmq_client, {}},
#else
    missing_transport("zmq", "libzmq", "libzmq3-dev"),
#endif
#ifdef HERM_BENCH_HAVE_DDS
    {"dds", dds_server, dds_client, {}},
#else
    missing_transport("dds", "Cyclone DDS", "cyclonedds-dev"),
#endif
  };
  return all;
}

const transport* herm::bench::find_transport(const std::string& name) {
  for (auto& t : transports())
    if (t.name == name)
      return &t;
  return nullptr;
}

namespace {

int run_endpoint(const std::string& role, const endpoint_params& p) {
  if (p.counter_fd >= 0)
    attach_counter_page(p.counter_fd, role == "router"   ? slot_router
                                      : role == "server" ? slot_server
                                                         : slot_client);
  if (p.mode == "oneway")
    alloc_counting(true);
  if (role == "client")
    set_case_processes(p.server_pid, p.router_pid, p.count_syscalls);
  if (role == "router")
    return herm_router(p);
  client_result res;
  if (p.mode == "inprocess" && role == "client") {
    res = inprocess_client(p);
  } else {
    auto* t = find_transport(p.transport);
    if (t == nullptr) {
      std::cout << "error unknown transport '" << p.transport << "'" << std::endl;
      return 2;
    }
    if (!t->unavailable.empty()) {
      std::cout << "error " << t->unavailable << std::endl;
      return 1;
    }
    if (role == "server")
      return t->server(p);
    res = t->client(p);
  }
  if (!res.error.empty()) {
    std::cout << "error " << res.error << std::endl;
    std::cout.flush();
    ::_exit(1); // some libraries' threads would outlive a normal exit
  }
  std::string line;
  if (p.mode == "oneway") {
    std::ostringstream out;
    out << "oneway " << res.sent << " " << res.received << " " << res.elapsed_ns << " "
        << res.stalls << " " << res.client_allocs << " " << res.server_allocs;
    line = out.str();
  } else {
    line = "rtt " + std::to_string(res.rtt_ns.size());
    for (auto x : res.rtt_ns)
      line += " " + std::to_string(x);
    line += " " + format_counts(timed_part_counts());
  }
  std::cout << line << std::endl;
  std::cout.flush();
  ::_exit(0);
}

// -- reporting -----------------------------------------------------------------------

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in{s};
  std::string item;
  while (std::getline(in, item, ','))
    if (!item.empty())
      out.push_back(item);
  return out;
}

std::string read_first_line(const char* path, const std::string& prefix = {}) {
  std::ifstream in{path};
  std::string line;
  while (std::getline(in, line))
    if (prefix.empty() || line.rfind(prefix, 0) == 0)
      return prefix.empty() ? line : line.substr(line.find(':') + 2);
  return {};
}

std::string fmt(double x) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), x < 100 ? "%.1f" : "%.0f", x);
  return buf;
}

/// A case over its runs: medians, with the min and max over runs where
/// asked for.
struct summary {
  double p50 = 0, p50_min = 0, p50_max = 0, p99 = 0, min = 0, max = 0;
  double msgs = 0, msgs_min = 0, msgs_max = 0, lost = 0, stalls = 0;
  double client_allocs = -1, server_allocs = -1;
  per_rt counts = unmeasured(); // timed runs' medians, the counting pass's syscalls
};

double min_of(const std::vector<double>& xs) {
  return xs.empty() ? 0 : *std::min_element(xs.begin(), xs.end());
}

double max_of(const std::vector<double>& xs) {
  return xs.empty() ? 0 : *std::max_element(xs.begin(), xs.end());
}

summary summarize(const case_result& c) {
  summary s;
  if (c.runs.empty())
    return s;
  std::vector<double> p50s, p99s, msgs, lost, stalls, ca, sa;
  s.min = 1e300;
  for (auto& r : c.runs) {
    p50s.push_back(r.p50);
    p99s.push_back(r.p99);
    s.min = std::min(s.min, r.min);
    s.max = std::max(s.max, r.max);
    msgs.push_back(r.msgs_per_s);
    lost.push_back(static_cast<double>(r.lost));
    stalls.push_back(static_cast<double>(r.stalls));
    ca.push_back(r.client_allocs);
    sa.push_back(r.server_allocs);
  }
  s.p50 = median(p50s);
  s.p50_min = min_of(p50s);
  s.p50_max = max_of(p50s);
  s.p99 = median(p99s);
  s.msgs = median(msgs);
  s.msgs_min = min_of(msgs);
  s.msgs_max = max_of(msgs);
  s.lost = median(lost);
  s.stalls = median(stalls);
  s.client_allocs = median(ca);
  s.server_allocs = median(sa);
  std::vector<per_rt> counts;
  for (auto& r : c.runs)
    counts.push_back(r.counts);
  s.counts = with_syscalls(median_of(counts), c.syscall_pass);
  return s;
}

} // namespace

int main(int argc, char** argv) {
  CLI::App app{"herm-bench-rtt: request round trips and one-way throughput between "
               "processes on 127.0.0.1, HERM and its peers side by side"};
  std::string role = "run";
  endpoint_params ep;
  uint32_t hello_ms = 1000, gap_us = 0, timeout_ms = 2000, stall_ms = 100;
  std::string only, sizes_arg = "16,256,1400", policies_arg = "loop,sharing:1,stealing";
  std::string modes_arg, oneway_sizes_arg = "64";
  std::string json_path, placements_arg = "one-cpu,per-cpu";
  uint32_t syscall_count = 200;
  int count_syscalls = 0;
  uint32_t count = 2000, warmup = 200, gap_count = 300, gap_warmup = 20;
  uint32_t oneway_count = 20000, oneway_warmup = 1000;
  uint32_t gap_ms = 10, repeat = 3;
  int batch = 0;
  bool quick = false;
  app.add_option("--only", only, "transports to run, comma-separated: udp,herm,caf,zmq,dds (default: all)");
  app.add_option("--modes", modes_arg, "modes to run, comma-separated: back-to-back,gap,oneway,inprocess,router (default: all)");
  app.add_option("--sizes", sizes_arg, "payload sizes in bytes of every mode (latency modes: 16,256,1400; oneway: 64)");
  app.add_option("--policies", policies_arg, "schedulers for herm and caf, POLICY[:THREADS] (loop, loop:US, sharing:1, sharing, stealing; loop = HERM's loop scheduler, loop:50 = the same busy-polling 50 us before it sleeps, sharing:1 = one worker, sharing = one per core)");
  struct count_option {
    const char* name;
    uint32_t* value;
    const char* help;
  };
  for (const auto& o : {
         count_option{"--count", &count, "measured round trips back to back, inprocess and router (2000)"},
         count_option{"--warmup", &warmup, "unmeasured round trips before them (200)"},
         count_option{"--gap-count", &gap_count, "measured round trips with a gap (300)"},
         count_option{"--gap-warmup", &gap_warmup, "unmeasured ones before them (20)"},
         count_option{"--gap-ms", &gap_ms, "the gap after each reply, ms (10)"},
         count_option{"--oneway-count", &oneway_count, "oneway: measured messages per run (20000)"},
         count_option{"--oneway-warmup", &oneway_warmup, "oneway: unmeasured messages before them (1000)"},
         count_option{"--window", &ep.window, "oneway: most unacknowledged messages (128)"},
         count_option{"--ack-every", &ep.ack_every, "oneway: the receiver acknowledges every N messages (16)"},
         count_option{"--stall-ms", &stall_ms, "oneway: a window full for this long is reopened and counted as a stall (100)"},
         count_option{"--repeat", &repeat, "repetitions of every case (3)"},
         count_option{"--syscall-count", &syscall_count, "round trips of each latency case's separate syscall counting pass (200; 0: none)"}})
    app.add_option(o.name, *o.value, o.help);
  app.add_option("--json", json_path, "write every figure to this file");
  app.add_option("--placements", placements_arg, "where the processes of every case run, comma-separated: one-cpu (all on vCPU 0), per-cpu (server and router on vCPU 0, client on vCPU 1), any (unpinned) (default: one-cpu,per-cpu)");
  app.add_flag("--quick", quick, "a short smoke run: 256 bytes (oneway 64), 1 repetition, few round trips, 100 ms hellos");
  app.add_option("--hello-ms", hello_ms, "herm: routing hello interval, ms (1000, HERM's default)");
  app.add_option("--timeout-ms", timeout_ms, "a round trip slower than this fails the case (2000)");
  // The child roles (the orchestrator starts them).
  app.add_option("--role", role, "run (default), or server/client/router: one end of one case")->group("");
  app.add_option("--transport", ep.transport)->group("");
  app.add_option("--mode", ep.mode)->group("");
  app.add_option("--policy", ep.policy)->group("");
  app.add_option("--port", ep.port)->group("");
  app.add_option("--port2", ep.port2)->group("");
  app.add_option("--port3", ep.port3)->group("");
  app.add_option("--port4", ep.port4)->group("");
  app.add_option("--size", ep.size)->group("");
  app.add_option("--gap-us", gap_us)->group("");
  app.add_option("--batch", batch)->group("");
  app.add_option("--tag", ep.tag)->group("");
  app.add_option("--counter-fd", ep.counter_fd)->group("");
  app.add_option("--server-pid", ep.server_pid)->group("");
  app.add_option("--router-pid", ep.router_pid)->group("");
  app.add_option("--count-syscalls", count_syscalls)->group("");
  CLI11_PARSE(app, argc, argv);
  ep.hello = std::chrono::milliseconds(hello_ms);
  ep.timeout = std::chrono::milliseconds(timeout_ms);
  ep.stall = std::chrono::milliseconds(stall_ms);
  ep.batch = batch != 0;
  ep.count_syscalls = count_syscalls != 0;

  if (role == "server" || role == "client" || role == "router") {
    ep.count = count;
    ep.warmup = warmup;
    ep.gap = std::chrono::microseconds(gap_us);
    return run_endpoint(role, ep);
  }
  if (role != "run") {
    std::cerr << "--role must be run, server, client or router" << std::endl;
    return 2;
  }
  ::signal(SIGPIPE, SIG_IGN);

  if (quick) {
    // --quick's defaults; an option given on the command line wins.
    struct quick_default {
      const char* option;
      uint32_t* value;
      uint32_t quick;
    };
    for (const auto& d : {quick_default{"--count", &count, 100},
                          quick_default{"--warmup", &warmup, 20},
                          quick_default{"--gap-count", &gap_count, 10},
                          quick_default{"--gap-warmup", &gap_warmup, 2},
                          quick_default{"--oneway-count", &oneway_count, 2000},
                          quick_default{"--oneway-warmup", &oneway_warmup, 200},
                          quick_default{"--repeat", &repeat, 1},
                          quick_default{"--syscall-count", &syscall_count, 50}})
      if (app.count(d.option) == 0)
        *d.value = d.quick;
    if (app.count("--sizes") == 0)
      sizes_arg = "256";
    if (app.count("--hello-ms") == 0)
      ep.hello = 100ms; // the modules find each other sooner
  }
  if (ep.window == 0 || ep.ack_every == 0 || ep.ack_every > ep.window) {
    std::cerr << "--window and --ack-every must be positive, --ack-every at most --window"
              << std::endl;
    return 2;
  }
  auto parse_sizes = [](const std::string& arg, std::vector<size_t>& out) {
    for (auto& s : split(arg)) {
      size_t n = 0;
      try {
        n = std::stoul(s);
      } catch (const std::exception&) {
      }
      if (n < 4 || n > 1400) {
        std::cerr << "--sizes: " << s << " is not in 4..1400 (one datagram)" << std::endl;
        return false;
      }
      out.push_back(n);
    }
    return true;
  };
  std::vector<size_t> sizes, oneway_sizes;
  if (!parse_sizes(sizes_arg, sizes)
      || !parse_sizes(app.count("--sizes") > 0 ? sizes_arg : oneway_sizes_arg, oneway_sizes))
    return 2;
  std::vector<std::string> families;
  if (only.empty())
    for (auto& t : transports())
      families.push_back(t.name);
  else
    families = split(only);
  std::vector<std::pair<std::string, std::string>> skipped;
  std::vector<std::string> available;
  for (auto& f : families) {
    auto* t = find_transport(f);
    if (t == nullptr) {
      std::cerr << "--only: unknown transport '" << f << "'" << std::endl;
      return 2;
    }
    if (t->unavailable.empty())
      available.push_back(f);
    else
      skipped.emplace_back(f, t->unavailable);
  }
  auto policies = split(policies_arg);
  for (auto& pol : policies) {
    auto [name, threads] = std::pair<std::string, size_t>{};
    try {
      std::tie(name, threads) = split_policy(pol);
    } catch (const std::exception&) {
      name.clear();
    }
    if (name != "loop" && name != "sharing" && name != "stealing") {
      std::cerr << "--policies: '" << pol << "' is not loop, or sharing or stealing[:THREADS]" << std::endl;
      return 2;
    }
  }
  // Where the processes run (children.hpp); a placement this machine cannot
  // give (one vCPU) is skipped with the reason, like a missing transport.
  const std::vector<placement> known_placements{
    {"one-cpu", 0, 0, 0}, {"per-cpu", 1, 0, 0}, {"any", -1, -1, -1}};
  std::vector<placement> placements;
  std::vector<std::pair<std::string, std::string>> skipped_placements;
  for (auto& name : split(placements_arg)) {
    auto i = std::find_if(known_placements.begin(), known_placements.end(),
                          [&](const placement& x) { return x.name == name; });
    if (i == known_placements.end()) {
      std::cerr << "--placements: unknown placement '" << name << "' (one-cpu, per-cpu, any)"
                << std::endl;
      return 2;
    }
    std::string why;
    for (int cpu : {i->client_cpu, i->server_cpu, i->router_cpu})
      if (cpu >= 0 && !cpu_allowed(cpu))
        why = "vCPU " + std::to_string(cpu) + " is not available to this process";
    if (why.empty())
      placements.push_back(*i);
    else
      skipped_placements.emplace_back(name, why);
  }
  if (placements.empty()) {
    std::cerr << "--placements: none of the placements can run on this machine" << std::endl;
    return 2;
  }
  auto gap_name = "gap-" + std::to_string(gap_ms) + "ms";
  std::vector<mode> all_modes{
    {"back-to-back", "rtt", 0us, count, warmup},
    {gap_name, "rtt", std::chrono::microseconds(gap_ms * 1000), gap_count, gap_warmup},
    {"oneway", "oneway", 0us, oneway_count, oneway_warmup},
    {"inprocess", "inprocess", 0us, count, warmup},
    {"router", "router", 0us, count, warmup},
  };
  std::vector<mode> modes;
  if (modes_arg.empty()) {
    modes = all_modes;
  } else {
    auto wanted = split(modes_arg);
    for (auto& w : wanted)
      if (w != "gap" && std::none_of(all_modes.begin(), all_modes.end(),
                                     [&](const mode& m) { return m.name == w; })) {
        std::cerr << "--modes: unknown mode '" << w << "'" << std::endl;
        return 2;
      }
    for (auto& m : all_modes)
      if (has(wanted, m.name) || (m.name == gap_name && has(wanted, "gap")))
        modes.push_back(m);
  }

  std::string command;
  for (int i = 0; i < argc; ++i)
    command += (i > 0 ? " " : "") + std::string{i == 0 ? "herm-bench-rtt" : argv[i]};
  auto load_before = read_first_line("/proc/loadavg");
  for (auto& [name, why] : skipped)
    std::cout << "skipped " << name << ": " << why << std::endl;
  for (auto& [name, why] : skipped_placements)
    std::cout << "skipped placement " << name << ": " << why << std::endl;

  // Repetitions outermost, so slow drifts of the machine's load spread over
  // every transport alike.
  std::vector<case_result> results;
  for (auto& m : modes)
    for (auto& where : placements)
      for (auto size : m.kind == "oneway" ? oneway_sizes : sizes)
        for (auto& v : variants_for(m, available, policies)) {
          results.push_back({v, &m, size, &where, {}, {}});
        }
  auto exe = self_exe();
  auto params_for = [&](const case_result& c) {
    endpoint_params p = ep;
    p.transport = c.v.family;
    p.mode = c.m->kind;
    p.policy = c.v.policy;
    p.batch = c.v.batch;
    p.size = c.size;
    p.count = c.m->count;
    p.warmup = c.m->warmup;
    p.gap = c.m->gap;
    return p;
  };
  size_t runs_total = results.size() * repeat, done = 0;
  for (uint32_t r = 0; r < repeat; ++r) {
    for (auto& c : results) {
      auto out = run_pair(exe, params_for(c), *c.where);
      ++done;
      std::cerr << "[" << done << "/" << runs_total << "] " << c.v.name << " " << c.m->name << " "
                << c.size << " B " << c.where->name << " run " << (r + 1) << ": ";
      if (auto* err = std::get_if<std::string>(&out)) {
        c.errors.push_back(*err);
        std::cerr << "FAILED " << *err << std::endl;
        continue;
      }
      auto& res = std::get<client_result>(out);
      run_figures f;
      if (c.m->kind == "oneway") {
        f.sent = res.sent;
        f.received = res.received;
        f.lost = res.sent > res.received ? res.sent - res.received : 0;
        f.stalls = res.stalls;
        f.client_allocs = res.client_allocs;
        f.server_allocs = res.server_allocs;
        if (res.received > 1 && res.elapsed_ns > 0)
          f.msgs_per_s = static_cast<double>(res.received - 1) * 1e9
                         / static_cast<double>(res.elapsed_ns);
        std::cerr << fmt(f.msgs_per_s) << " msgs/s, " << f.lost << " lost, " << f.stalls
                  << " stalls" << std::endl;
      } else {
        f = summarize(res.rtt_ns);
        f.counts = per_round_trip(res.counts, c.m->count);
        std::cerr << "p50 " << fmt(f.p50) << " us, p99 " << fmt(f.p99) << " us" << std::endl;
      }
      c.runs.push_back(f);
    }
  }
  // Syscalls: a separate, shorter pass per latency case, with perf counters
  // on the syscall tracepoint that would slow the timed runs (probes.hpp).
  auto syscalls_why = syscall_count == 0 ? std::string{"--syscall-count 0"}
                                         : syscall_counting_unavailable();
  if (!syscalls_why.empty())
    std::cout << "syscalls per round trip: n/a, " << syscalls_why << std::endl;
  for (auto& c : results) {
    if (!syscalls_why.empty())
      break;
    if (!c.m->latency())
      continue;
    auto p = params_for(c);
    p.count = std::min(p.count, syscall_count);
    p.count_syscalls = true;
    auto out = run_pair(exe, p, *c.where);
    std::cerr << "[syscalls] " << c.v.name << " " << c.m->name << " " << c.size << " B "
              << c.where->name << ": ";
    if (auto* err = std::get_if<std::string>(&out)) {
      c.syscall_error = *err;
      std::cerr << "FAILED " << *err << std::endl;
      continue;
    }
    c.syscall_pass = per_round_trip(std::get<client_result>(out).counts, p.count);
    c.syscall_round_trips = p.count;
    std::cerr << fmt(total(c.syscall_pass, f_syscalls)) << " per round trip" << std::endl;
  }

  // -- the table and the JSON ------------------------------------------------------------
  // Reference figures of the same run: raw UDP (and DDS) per mode and size,
  // plain CAF per policy and size (inprocess), direct herm per policy and
  // size (router: the back-to-back case).
  // Every reference is taken within the case's own placement.
  std::map<std::tuple<std::string, std::string, size_t, std::string>, summary> by_name;
  for (auto& c : results)
    if (!c.runs.empty())
      by_name[{c.v.name, c.m->name, c.size, c.where->name}] = summarize(c);
  std::string where_now; // the placement of the case being reported
  auto ref = [&](const std::string& name, const std::string& mode_name, size_t size) {
    auto i = by_name.find({name, mode_name, size, where_now});
    return i == by_name.end() ? summary{} : i->second;
  };
  auto ratio = [](double a, double b) { return a > 0 && b > 0 ? a / b : 0; };
  nlohmann::json cases = nlohmann::json::array();
  bool ok = true;
  std::cout << "\nAll figures: the median over " << repeat
            << " run(s) [min..max over runs]; every run in fresh processes on 127.0.0.1.\n"
            << "Latency modes, microseconds: p50 of each run, p99: median of the runs' p99, "
               "min/max: over all round trips of all runs.\n";
  for (auto& m : modes) {
    bool oneway = m.kind == "oneway";
    std::string ratio_name = m.kind == "inprocess" ? "ratio_to_caf_local"
                             : m.kind == "router"  ? "ratio_to_direct"
                                                   : "ratio_to_udp";
    if (oneway) {
      std::cout << "\n" << m.name << " (" << m.count << " messages after " << m.warmup
                << " warm-up per run, window " << ep.window << ", acknowledged every "
                << ep.ack_every << "; messages per second at the receiver, first to last)\n";
      std::printf("%-22s %-8s %6s %10s %21s %6s %6s %7s %7s %13s\n", "transport", "placement",
                  "bytes", "msgs/s", "range", "lost", "stalls", "/udp", "/dds", "allocs/msg c+s");
    } else {
      std::cout << "\n" << m.name << " (" << m.count << " round trips after " << m.warmup
                << " warm-up per run)\n";
      std::printf("%-22s %-8s %6s %9s %19s %9s %9s %9s %10s %9s\n", "transport", "placement",
                  "bytes", "p50", "p50 range", "p99", "min", "max",
                  m.kind == "inprocess" ? "p50/caf" : m.kind == "router" ? "p50/direct" : "p50/udp",
                  "p50/dds");
    }
    std::cout.flush();
    std::string counts_rows; // latency modes: printed below the times
    for (auto& c : results) {
      if (c.m != &m)
        continue;
      where_now = c.where->name;
      auto s = summarize(c);
      bool complete = c.errors.empty() && c.runs.size() == repeat;
      for (auto& r : c.runs)
        if (oneway ? !(r.msgs_per_s > 0 && r.received > 0)
                   : !(r.p50 > 0 && r.p99 > 0 && r.min > 0 && r.max > 0 && r.n == m.count))
          complete = false;
      if (!c.syscall_error.empty())
        complete = false;
      ok = ok && complete;
      auto size = c.size;
      double r_udp = 0, r_dds = 0, r_main = 0; // r_dds: rtt modes too
      if (oneway) {
        r_udp = ratio(s.msgs, ref("udp", m.name, size).msgs);
        r_dds = ratio(s.msgs, ref("dds", m.name, size).msgs);
      } else if (m.kind == "inprocess") {
        r_main = ratio(s.p50, ref("caf-local/" + c.v.policy, m.name, size).p50);
      } else if (m.kind == "router") {
        r_main = ratio(s.p50, ref(c.v.name, "back-to-back", size).p50);
      } else {
        r_main = ratio(s.p50, ref("udp", m.name, size).p50);
        r_dds = ratio(s.p50, ref("dds", m.name, size).p50);
      }
      auto x = [&](double v) { return v > 0 ? fmt(v) + "x" : std::string{"-"}; };
      if (c.runs.empty()) {
        std::printf("%-22s %-8s %6zu   FAILED: %s\n", c.v.name.c_str(), where_now.c_str(), size,
                    c.errors.empty() ? "" : c.errors.front().c_str());
      } else if (oneway) {
        auto range = fmt(s.msgs_min) + ".." + fmt(s.msgs_max);
        auto allocs = s.client_allocs >= 0 && s.server_allocs >= 0
                        ? fmt(s.client_allocs) + "+" + fmt(s.server_allocs)
                        : std::string{"-"};
        std::printf("%-22s %-8s %6zu %10s %21s %6s %6s %7s %7s %13s%s\n", c.v.name.c_str(),
                    where_now.c_str(), size, fmt(s.msgs).c_str(), range.c_str(), fmt(s.lost).c_str(),
                    fmt(s.stalls).c_str(), x(r_udp).c_str(), x(r_dds).c_str(), allocs.c_str(),
                    complete ? "" : "  (incomplete)");
      } else {
        auto range = fmt(s.p50_min) + ".." + fmt(s.p50_max);
        std::printf("%-22s %-8s %6zu %9s %19s %9s %9s %9s %10s %9s%s\n", c.v.name.c_str(),
                    where_now.c_str(), size, fmt(s.p50).c_str(), range.c_str(),
                    fmt(s.p99).c_str(), fmt(s.min).c_str(), fmt(s.max).c_str(),
                    x(r_main).c_str(), x(r_dds).c_str(), complete ? "" : "  (incomplete)");
        auto sum = [&](count_field f) {
          auto t = total(s.counts, f);
          return t < 0 ? std::string{"-"} : fmt(t);
        };
        char row[256];
        std::snprintf(row, sizeof(row), "%-22s %-8s %6zu %15s %15s %15s %6s %15s %6s%s\n",
                      c.v.name.c_str(), where_now.c_str(), size,
                      cells(s.counts, f_wakeups).c_str(), cells(s.counts, f_vcsw).c_str(),
                      cells(s.counts, f_syscalls).c_str(), sum(f_syscalls).c_str(),
                      cells(s.counts, f_allocs).c_str(), sum(f_allocs).c_str(),
                      c.syscall_error.empty() ? "" : "  (syscall pass failed)");
        counts_rows += row;
      }
      std::fflush(stdout);
      nlohmann::json runs = nlohmann::json::array();
      for (auto& r : c.runs) {
        if (oneway)
          runs.push_back({{"msgs_per_s", r.msgs_per_s}, {"sent", r.sent},
                          {"received", r.received}, {"lost", r.lost}, {"stalls", r.stalls},
                          {"client_allocs_per_msg", r.client_allocs},
                          {"server_allocs_per_msg", r.server_allocs}});
        else
          runs.push_back({{"p50_us", r.p50}, {"p99_us", r.p99}, {"min_us", r.min},
                          {"max_us", r.max}, {"mean_us", r.mean}, {"round_trips", r.n},
                          {"per_round_trip", to_json(r.counts)}});
      }
      nlohmann::json js{{"transport", c.v.name},
                        {"family", c.v.family},
                        {"policy", c.v.policy},
                        {"label", c.v.label},
                        {"mode", m.name},
                        {"placement", c.where->name},
                        {"cpus",
                         {{"client", c.where->client_cpu},
                          {"server", c.where->server_cpu},
                          {"router", c.where->router_cpu}}},
                        {"gap_us", m.gap.count()},
                        {"size", size},
                        {"complete", complete},
                        {"errors", c.errors},
                        {"runs", runs}};
      if (oneway) {
        js["msgs_per_s"] = s.msgs;
        js["msgs_per_s_min"] = s.msgs_min;
        js["msgs_per_s_max"] = s.msgs_max;
        js["lost"] = s.lost;
        js["stalls"] = s.stalls;
        js["client_allocs_per_msg"] = s.client_allocs;
        js["server_allocs_per_msg"] = s.server_allocs;
        js["ratio_to_udp"] = r_udp;
        js["ratio_to_dds"] = r_dds;
      } else {
        js["p50_us"] = s.p50;
        js["p50_min_us"] = s.p50_min;
        js["p50_max_us"] = s.p50_max;
        js["p99_us"] = s.p99;
        js["min_us"] = s.min;
        js["max_us"] = s.max;
        js[ratio_name] = r_main;
        if (m.kind == "rtt")
          js["ratio_to_dds"] = r_dds;
        // Per round trip, per process: wake-ups and allocations from the
        // timed runs (median), syscalls from the counting pass.
        auto or_null = [](double v) { return v < 0 ? nlohmann::json() : nlohmann::json(v); };
        js["per_round_trip"] = to_json(s.counts);
        js["wakeups_per_round_trip_most"] = or_null(most(s.counts, f_wakeups));
        js["syscalls_per_round_trip"] = or_null(total(s.counts, f_syscalls));
        js["allocs_per_round_trip"] = or_null(total(s.counts, f_allocs));
        js["syscall_pass_round_trips"] = c.syscall_round_trips;
        if (!c.syscall_error.empty())
          js["syscall_pass_error"] = c.syscall_error;
      }
      cases.push_back(std::move(js));
    }
    if (!counts_rows.empty()) {
      std::cout << "\n" << m.name << ", per round trip and process (client/server[/router]): "
                << "wake-ups (schedstat timeslices), voluntary switches, syscalls ("
                << (syscalls_why.empty() ? "separate pass of up to " + std::to_string(syscall_count)
                                             + " round trips"
                                         : "n/a: " + syscalls_why)
                << "), allocations (" << allocations_counted() << " calls)\n";
      std::printf("%-22s %-8s %6s %15s %15s %15s %6s %15s %6s\n", "transport", "placement",
                  "bytes", "wake-ups", "vol. switches", "syscalls", "sum", "allocs", "sum");
      std::cout << counts_rows;
    }
  }
  // herm against raw UDP and DDS within each placement (issue 16's targets).
  nlohmann::json placement_ratios = nlohmann::json::array();
  std::string ratio_rows;
  for (auto& m : modes) {
    if (m.kind != "rtt")
      continue;
    for (auto& c : results) {
      if (c.m != &m || c.v.family != "herm" || c.runs.empty())
        continue;
      where_now = c.where->name;
      auto herm = ref(c.v.name, m.name, c.size).p50;
      auto r_udp = ratio(herm, ref("udp", m.name, c.size).p50);
      auto r_dds = ratio(herm, ref("dds", m.name, c.size).p50);
      char row[160];
      std::snprintf(row, sizeof(row), "  %-8s %-14s %5zu B  %-16s herm/udp %6s  herm/dds %6s\n",
                    where_now.c_str(), m.name.c_str(), c.size, c.v.name.c_str(),
                    r_udp > 0 ? (fmt(r_udp) + "x").c_str() : "-",
                    r_dds > 0 ? (fmt(r_dds) + "x").c_str() : "-");
      ratio_rows += row;
      placement_ratios.push_back({{"placement", where_now}, {"mode", m.name}, {"size", c.size},
                                  {"transport", c.v.name}, {"herm_over_udp", r_udp},
                                  {"herm_over_dds", r_dds}});
    }
  }
  if (!ratio_rows.empty())
    std::cout << "\nRatios of p50 within each placement (same run):\n" << ratio_rows;
  // Every requested mode measured something: a mode left without a case
  // (--modes router --only udp) is an error, not a silent pass.
  for (auto& m : modes)
    if (!modes_arg.empty()
        && std::none_of(results.begin(), results.end(),
                        [&](const case_result& c) { return c.m == &m; })) {
      std::cout << "\nmode " << m.name << ": no transport selected measures it\n";
      ok = false;
    }
  std::map<std::pair<std::string, std::string>, std::vector<std::string>> labels;
  for (auto& c : results) {
    auto& ms = labels[{c.v.name, c.v.label}];
    if (!has(ms, c.m->name))
      ms.push_back(c.m->name);
  }
  std::cout << "\n";
  for (auto& [key, ms] : labels) {
    std::string joined;
    for (auto& x : ms)
      joined += (joined.empty() ? "" : ", ") + x;
    std::cout << "  " << key.first << " (" << joined << "): " << key.second << "\n";
  }
  std::cout << "  allocs/msg: allocations (" << allocations_counted()
            << " calls) per measured message in the sender (c) and the receiver (s)\n";
  std::cout << "  placements: one-cpu = every process of a case on vCPU 0; per-cpu = server "
               "and router on vCPU 0, client on vCPU 1; any = unpinned\n";
  std::cout << "  herm and caf clients: one event-based actor, next request from the "
               "reply's then-callback; oneway: as many sends as the window allows\n";
  std::cout << (ok ? "all cases complete" : "SOME CASES FAILED") << std::endl;

  if (!json_path.empty()) {
    utsname un{};
    ::uname(&un);
    nlohmann::json skipped_json = nlohmann::json::array();
    for (auto& [name, why] : skipped)
      skipped_json.push_back({{"transport", name}, {"reason", why}});
    nlohmann::json placements_json = nlohmann::json::array();
    for (auto& pl : placements)
      placements_json.push_back({{"name", pl.name}, {"client_cpu", pl.client_cpu},
                                 {"server_cpu", pl.server_cpu}, {"router_cpu", pl.router_cpu}});
    nlohmann::json skipped_placements_json = nlohmann::json::array();
    for (auto& [name, why] : skipped_placements)
      skipped_placements_json.push_back({{"placement", name}, {"reason", why}});
    nlohmann::json modes_json = nlohmann::json::array();
    for (auto& m : modes)
      modes_json.push_back({{"name", m.name}, {"kind", m.kind}, {"gap_us", m.gap.count()},
                            {"count", m.count}, {"warmup", m.warmup}});
    nlohmann::json doc{
      {"benchmark", "herm-bench-rtt"},
      {"command", command},
      {"machine",
       {{"cpus", std::thread::hardware_concurrency()},
        {"cpu", read_first_line("/proc/cpuinfo", "model name")},
        {"kernel", std::string{un.sysname} + " " + un.release + " " + un.machine},
        {"loadavg_before", load_before},
        {"loadavg_after", read_first_line("/proc/loadavg")}}},
      {"parameters",
       {{"sizes", sizes},
        {"oneway_sizes", oneway_sizes},
        {"policies", policies},
        {"repeat", repeat},
        {"hello_ms", ep.hello.count()},
        {"timeout_ms", timeout_ms},
        {"window", ep.window},
        {"ack_every", ep.ack_every},
        {"stall_ms", stall_ms},
        {"allocs_counted", allocations_counted()},
        {"allocs_note", std::string{"allocations are "} + allocations_counted()
                          + " calls (malloc: every heap allocation, C libraries' "
                            "included; operator new: sanitizer builds, C libraries' "
                            "malloc calls not seen)"},
        {"placements", placements_json},
        {"skipped_placements", skipped_placements_json},
        {"syscall_count", syscall_count},
        {"syscalls_unavailable", syscalls_why},
        {"counts_note", "per_round_trip: per process of the case; wakeups = sum over "
                        "/proc/PID/task/*/schedstat field 3 (times scheduled in), "
                        "voluntary_switches from /proc/PID/task/*/status, both over the "
                        "timed runs (median); syscalls: perf counters on "
                        "raw_syscalls:sys_enter in a separate pass of syscall_count "
                        "round trips"},
        {"modes", modes_json}}},
      {"units", "microseconds; oneway: messages per second"},
      {"skipped", skipped_json},
      {"cases", cases},
      {"placement_ratios", placement_ratios},
      {"ok", ok}};
    std::ofstream out{json_path};
    out << doc.dump(2) << "\n";
    if (!out) {
      std::cerr << "cannot write " << json_path << std::endl;
      return 1;
    }
  }
  return ok ? 0 : 1;
}
