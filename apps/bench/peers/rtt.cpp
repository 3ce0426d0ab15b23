// herm-bench-rtt: request round-trip latency between two processes on
// 127.0.0.1, for HERM and for the systems a robot builder would pick
// instead, in one run (issue 7, "Benchmarks side by side with peers").
//
//   herm-bench-rtt                       the full default suite (minutes)
//   herm-bench-rtt --quick               a smoke run (seconds)
//   herm-bench-rtt --only herm,udp --sizes 16 --repeat 5 --json rtt.json
//
// For every case (transport, payload size, back to back or with a gap) and
// every repetition, this process starts a fresh server and a fresh client
// (itself, re-executed with --role server / --role client), so no state
// carries over between cases. The client times each round trip with the
// monotonic clock and hands the times back on its stdout. Transports:
// transport.hpp; the table and the JSON hold every figure. Exit status 0
// when every available transport completed every case with positive
// figures, 1 otherwise, 2 on bad arguments.

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/utsname.h>
#include <sys/wait.h>
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

#include "apps/bench/peers/transport.hpp"

using namespace herm::bench;
using namespace std::chrono_literals;

namespace {

// -- what is measured ---------------------------------------------------------------

/// One transport as measured: a family (the server and client functions)
/// and, for the actor transports, a scheduler policy.
struct variant {
  std::string name;   // "herm/sharing"
  std::string family; // "herm"
  std::string policy; // "sharing", "stealing" or empty
  std::string label;  // for people
};

struct mode {
  std::string name; // "back-to-back", "gap-10ms"
  std::chrono::microseconds gap;
  uint32_t count;
  uint32_t warmup;
};

struct run_figures {
  double p50 = 0, p99 = 0, min = 0, max = 0, mean = 0; // µs
  size_t n = 0;
};

struct case_result {
  const variant* v = nullptr;
  const mode* m = nullptr;
  size_t size = 0;
  std::vector<run_figures> runs;
  std::vector<std::string> errors;
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

// -- child processes ----------------------------------------------------------------

std::string self_exe() {
  char buf[4096];
  auto n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0)
    return "herm-bench-rtt";
  return std::string(buf, static_cast<size_t>(n));
}

/// A child with its stdout on a pipe; stderr is ours.
struct child {
  pid_t pid = -1;
  int out = -1;
  std::string buffer;
};

std::optional<child> spawn(const std::vector<std::string>& args) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return std::nullopt;
  std::vector<char*> argv;
  for (auto& a : args)
    argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  auto pid = ::fork();
  if (pid < 0)
    return std::nullopt;
  if (pid == 0) {
    ::dup2(fds[1], STDOUT_FILENO);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  return child{pid, fds[0], {}};
}

/// Reads until a full line is buffered (returns it) or EOF or the deadline.
std::optional<std::string> read_line(child& c, std::chrono::steady_clock::time_point until) {
  for (;;) {
    auto nl = c.buffer.find('\n');
    if (nl != std::string::npos) {
      auto line = c.buffer.substr(0, nl);
      c.buffer.erase(0, nl + 1);
      return line;
    }
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      until - std::chrono::steady_clock::now());
    if (left.count() <= 0)
      return std::nullopt;
    pollfd pfd{c.out, POLLIN, 0};
    if (::poll(&pfd, 1, static_cast<int>(left.count())) <= 0)
      continue;
    char buf[65536];
    auto n = ::read(c.out, buf, sizeof(buf));
    if (n <= 0) {
      if (c.buffer.empty())
        return std::nullopt;
      auto line = std::move(c.buffer);
      c.buffer.clear();
      return line;
    }
    c.buffer.append(buf, static_cast<size_t>(n));
  }
}

void stop(child& c) {
  if (c.pid > 0) {
    ::kill(c.pid, SIGTERM);
    int status = 0;
    for (int i = 0; i < 200; ++i) {
      if (::waitpid(c.pid, &status, WNOHANG) == c.pid) {
        c.pid = -1;
        break;
      }
      std::this_thread::sleep_for(10ms);
    }
    if (c.pid > 0) {
      ::kill(c.pid, SIGKILL);
      ::waitpid(c.pid, &status, 0);
      c.pid = -1;
    }
  }
  if (c.out >= 0)
    ::close(c.out);
  c.out = -1;
}

/// A free UDP port on 127.0.0.1 (the kernel's pick; released before use).
uint16_t free_udp_port() {
  int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(addr);
  uint16_t port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), len) == 0
      && ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0)
    port = ntohs(addr.sin_port);
  ::close(fd);
  return port;
}

std::vector<std::string> endpoint_args(const std::string& exe, const std::string& role,
                                       const endpoint_params& p) {
  return {exe,
          "--role", role,
          "--transport", p.transport,
          "--policy", p.policy.empty() ? std::string{"sharing"} : p.policy,
          "--port", std::to_string(p.port),
          "--port2", std::to_string(p.port2),
          "--hello-ms", std::to_string(p.hello.count()),
          "--size", std::to_string(p.size),
          "--count", std::to_string(p.count),
          "--warmup", std::to_string(p.warmup),
          "--gap-us", std::to_string(p.gap.count()),
          "--timeout-ms", std::to_string(p.timeout.count()),
          "--tag", p.tag};
}

/// One repetition of one case: a fresh server, a fresh client.
std::variant<std::vector<int64_t>, std::string>
run_pair(const std::string& exe, endpoint_params p) {
  static int serial = 0;
  ++serial;
  if (p.transport == "herm") {
    p.port = free_udp_port();
    do
      p.port2 = free_udp_port();
    while (p.port2 == p.port);
  } else if (p.transport == "dds") {
    // A domain and topic names of our own: other DDS programs on this
    // machine neither see nor disturb this run.
    p.port = static_cast<uint16_t>(1 + ::getpid() % 200);
    p.tag = std::to_string(::getpid()) + "_" + std::to_string(serial);
  } else {
    p.port = 0;
  }
  auto server = spawn(endpoint_args(exe, "server", p));
  if (!server)
    return std::string{"cannot start the server"};
  auto line = read_line(*server, std::chrono::steady_clock::now() + 30s);
  if (!line || line->rfind("ready ", 0) != 0) {
    stop(*server);
    return "server: " + (line ? *line : std::string{"no ready line within 30 s"});
  }
  p.port = static_cast<uint16_t>(std::stoul(line->substr(6)));
  auto client = spawn(endpoint_args(exe, "client", p));
  if (!client) {
    stop(*server);
    return std::string{"cannot start the client"};
  }
  auto budget = 60s + (p.warmup + p.count)
                        * std::chrono::duration_cast<std::chrono::milliseconds>(
                          p.gap + std::chrono::milliseconds(5));
  auto out = read_line(*client, std::chrono::steady_clock::now() + budget);
  stop(*client);
  stop(*server);
  if (!out)
    return std::string{"client: no result within the time budget"};
  if (out->rfind("rtt ", 0) != 0)
    return "client: " + *out;
  std::istringstream in{out->substr(4)};
  size_t n = 0;
  in >> n;
  std::vector<int64_t> ns(n);
  for (auto& x : ns)
    in >> x;
  if (!in)
    return std::string{"client: truncated result"};
  return ns;
}

// -- the child roles -----------------------------------------------------------------

int run_endpoint(const std::string& role, const endpoint_params& p) {
  static const std::map<std::string, std::pair<server_fn, client_fn>> fns{
    {"udp", {udp_server, udp_client}},   {"herm", {herm_server, herm_client}},
    {"caf", {caf_server, caf_client}},   {"zmq", {zmq_server, zmq_client}},
    {"dds", {dds_server, dds_client}},
  };
  auto i = fns.find(p.transport);
  if (i == fns.end()) {
    std::cout << "error unknown transport '" << p.transport << "'" << std::endl;
    return 2;
  }
  if (role == "server")
    return i->second.first(p);
  auto res = i->second.second(p);
  if (!res.error.empty()) {
    std::cout << "error " << res.error << std::endl;
    std::cout.flush();
    ::_exit(1); // some libraries' threads would outlive a normal exit
  }
  std::string line = "rtt " + std::to_string(res.rtt_ns.size());
  for (auto x : res.rtt_ns)
    line += " " + std::to_string(x);
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

struct summary {
  double p50 = 0, p50_min = 0, p50_max = 0, p99 = 0, min = 0, max = 0;
};

summary summarize(const case_result& c) {
  summary s;
  std::vector<double> p50s, p99s;
  s.min = 1e300;
  for (auto& r : c.runs) {
    p50s.push_back(r.p50);
    p99s.push_back(r.p99);
    s.min = std::min(s.min, r.min);
    s.max = std::max(s.max, r.max);
  }
  if (p50s.empty())
    return {};
  s.p50 = median(p50s);
  s.p50_min = *std::min_element(p50s.begin(), p50s.end());
  s.p50_max = *std::max_element(p50s.begin(), p50s.end());
  s.p99 = median(p99s);
  return s;
}

} // namespace

int main(int argc, char** argv) {
  CLI::App app{"herm-bench-rtt: request round trips between two processes on "
               "127.0.0.1, HERM and its peers side by side"};
  std::string role = "run";
  endpoint_params ep;
  uint32_t hello_ms = 1000, gap_us = 0, timeout_ms = 2000;
  std::string only, sizes_arg = "16,256,1400", policies_arg = "sharing,stealing";
  std::string json_path;
  uint32_t count = 2000, warmup = 200, gap_count = 300, gap_warmup = 20;
  uint32_t gap_ms = 10, repeat = 3;
  bool quick = false;
  app.add_option("--only", only, "transports to run, comma-separated: udp,herm,caf,zmq,dds (default: all)");
  app.add_option("--sizes", sizes_arg, "payload sizes in bytes (16,256,1400)");
  app.add_option("--policies", policies_arg, "CAF scheduler policies for herm and caf (sharing,stealing)");
  app.add_option("--count", count, "measured round trips back to back (2000)");
  app.add_option("--warmup", warmup, "unmeasured round trips before them (200)");
  app.add_option("--gap-count", gap_count, "measured round trips with a gap (300)");
  app.add_option("--gap-warmup", gap_warmup, "unmeasured ones before them (20)");
  app.add_option("--gap-ms", gap_ms, "the gap after each reply, ms (10)");
  app.add_option("--repeat", repeat, "repetitions of every case (3)");
  app.add_option("--json", json_path, "write every figure to this file");
  app.add_flag("--quick", quick, "a short smoke run: 256 bytes, 1 repetition, few round trips, 100 ms hellos");
  app.add_option("--hello-ms", hello_ms, "herm: routing hello interval, ms (1000, HERM's default)");
  app.add_option("--timeout-ms", timeout_ms, "a round trip slower than this fails the case (2000)");
  // The child roles (the orchestrator starts them).
  app.add_option("--role", role, "run (default), or server/client: one end of one case")->group("");
  app.add_option("--transport", ep.transport)->group("");
  app.add_option("--policy", ep.policy)->group("");
  app.add_option("--port", ep.port)->group("");
  app.add_option("--port2", ep.port2)->group("");
  app.add_option("--size", ep.size)->group("");
  app.add_option("--gap-us", gap_us)->group("");
  app.add_option("--tag", ep.tag)->group("");
  CLI11_PARSE(app, argc, argv);
  ep.hello = std::chrono::milliseconds(hello_ms);
  ep.timeout = std::chrono::milliseconds(timeout_ms);

  if (role == "server" || role == "client") {
    ep.count = count;
    ep.warmup = warmup;
    ep.gap = std::chrono::microseconds(gap_us);
    return run_endpoint(role, ep);
  }
  if (role != "run") {
    std::cerr << "--role must be run, server or client" << std::endl;
    return 2;
  }
  ::signal(SIGPIPE, SIG_IGN);

  if (quick) {
    if (app.count("--sizes") == 0)
      sizes_arg = "256";
    if (app.count("--count") == 0)
      count = 100;
    if (app.count("--warmup") == 0)
      warmup = 20;
    if (app.count("--gap-count") == 0)
      gap_count = 10;
    if (app.count("--gap-warmup") == 0)
      gap_warmup = 2;
    if (app.count("--repeat") == 0)
      repeat = 1;
    if (app.count("--hello-ms") == 0)
      ep.hello = 100ms; // the modules find each other sooner
  }
  std::vector<size_t> sizes;
  for (auto& s : split(sizes_arg)) {
    auto n = std::stoul(s);
    if (n < 4 || n > 1400) {
      std::cerr << "--sizes: " << s << " is not in 4..1400 (one datagram)" << std::endl;
      return 2;
    }
    sizes.push_back(n);
  }
  auto families = only.empty() ? std::vector<std::string>{"udp", "herm", "caf", "zmq", "dds"}
                               : split(only);
  auto policies = split(policies_arg);
  std::vector<variant> variants;
  std::vector<std::pair<std::string, std::string>> skipped;
  for (auto& f : families) {
    if (f == "udp") {
      variants.push_back({"udp", "udp", "", "raw UDP, blocking sockets (the floor)"});
    } else if (f == "herm" || f == "caf") {
      for (auto& pol : policies)
        variants.push_back(
          {f + "/" + pol, f, pol,
           f == "herm" ? "HERM APO request through a proxy, udp link, " + pol + " scheduler"
                       : "CAF 0.17 io::middleman remote actor (TCP), " + pol + " scheduler"});
    } else if (f == "zmq") {
      if (auto why = zmq_unavailable(); !why.empty())
        skipped.emplace_back("zmq", why);
      else
        variants.push_back({"zmq", "zmq", "", "ZeroMQ REQ/REP (TCP)"});
    } else if (f == "dds") {
      if (auto why = dds_unavailable(); !why.empty())
        skipped.emplace_back("dds", why);
      else
        variants.push_back({"dds", "dds", "", "Cyclone DDS, reliable, keep-last 1"});
    } else {
      std::cerr << "--only: unknown transport '" << f << "'" << std::endl;
      return 2;
    }
  }
  std::vector<mode> modes{
    {"back-to-back", 0us, count, warmup},
    {"gap-" + std::to_string(gap_ms) + "ms",
     std::chrono::microseconds(gap_ms * 1000), gap_count, gap_warmup},
  };

  std::string command;
  for (int i = 0; i < argc; ++i)
    command += (i > 0 ? " " : "") + std::string{i == 0 ? "herm-bench-rtt" : argv[i]};
  auto load_before = read_first_line("/proc/loadavg");
  for (auto& [name, why] : skipped)
    std::cout << "skipped " << name << ": " << why << std::endl;

  // Repetitions outermost, so slow drifts of the machine's load spread over
  // every transport alike.
  std::vector<case_result> results;
  for (auto& m : modes)
    for (auto size : sizes)
      for (auto& v : variants)
        results.push_back({&v, &m, size, {}, {}});
  auto exe = self_exe();
  size_t total = results.size() * repeat, done = 0;
  for (uint32_t r = 0; r < repeat; ++r) {
    for (auto& c : results) {
      endpoint_params p = ep;
      p.transport = c.v->family;
      p.policy = c.v->policy;
      p.size = c.size;
      p.count = c.m->count;
      p.warmup = c.m->warmup;
      p.gap = c.m->gap;
      auto out = run_pair(exe, p);
      ++done;
      std::cerr << "[" << done << "/" << total << "] " << c.v->name << " "
                << c.m->name << " " << c.size << " B run " << (r + 1) << ": ";
      if (auto* err = std::get_if<std::string>(&out)) {
        c.errors.push_back(*err);
        std::cerr << "FAILED " << *err << std::endl;
        continue;
      }
      auto f = summarize(std::get<std::vector<int64_t>>(out));
      std::cerr << "p50 " << fmt(f.p50) << " us, p99 " << fmt(f.p99) << " us" << std::endl;
      c.runs.push_back(f);
    }
  }

  // -- the table and the JSON ------------------------------------------------------------
  std::map<std::pair<std::string, size_t>, double> udp_p50;
  for (auto& c : results)
    if (c.v->family == "udp" && !c.runs.empty())
      udp_p50[{c.m->name, c.size}] = summarize(c).p50;
  nlohmann::json cases = nlohmann::json::array();
  bool ok = true;
  std::cout << "\nRequest round trip between two processes on 127.0.0.1, microseconds.\n"
            << "p50: median over " << repeat << " run(s) of each run's p50 [min..max over runs]; "
            << "p99: median of the runs' p99; min/max: over all round trips of all runs.\n";
  for (auto& m : modes) {
    std::cout << "\n" << m.name << " (" << m.count << " round trips after " << m.warmup
              << " warm-up per run, " << repeat << " run(s))\n";
    std::printf("%-15s %6s %9s %19s %9s %9s %9s %8s\n", "transport", "bytes", "p50",
                "p50 range", "p99", "min", "max", "p50/udp");
    std::cout.flush();
    for (auto size : sizes)
      for (auto& c : results) {
        if (c.m != &m || c.size != size)
          continue;
        auto s = summarize(c);
        bool complete = c.errors.empty() && c.runs.size() == repeat;
        for (auto& r : c.runs)
          if (!(r.p50 > 0 && r.p99 > 0 && r.min > 0 && r.max > 0 && r.n == m.count))
            complete = false;
        ok = ok && complete;
        auto u = udp_p50.find({m.name, size});
        double ratio = u != udp_p50.end() && u->second > 0 && s.p50 > 0 ? s.p50 / u->second : 0;
        if (c.runs.empty()) {
          std::printf("%-15s %6zu   FAILED: %s\n", c.v->name.c_str(), size,
                      c.errors.empty() ? "" : c.errors.front().c_str());
        } else {
          auto range = fmt(s.p50_min) + ".." + fmt(s.p50_max);
          std::printf("%-15s %6zu %9s %19s %9s %9s %9s %8s%s\n", c.v->name.c_str(), size,
                      fmt(s.p50).c_str(), range.c_str(), fmt(s.p99).c_str(),
                      fmt(s.min).c_str(), fmt(s.max).c_str(),
                      ratio > 0 ? (fmt(ratio) + "x").c_str() : "-",
                      complete ? "" : "  (incomplete)");
        }
        std::fflush(stdout);
        nlohmann::json runs = nlohmann::json::array();
        for (auto& r : c.runs)
          runs.push_back({{"p50_us", r.p50}, {"p99_us", r.p99}, {"min_us", r.min},
                          {"max_us", r.max}, {"mean_us", r.mean}, {"round_trips", r.n}});
        cases.push_back({{"transport", c.v->name},
                         {"family", c.v->family},
                         {"policy", c.v->policy},
                         {"label", c.v->label},
                         {"mode", m.name},
                         {"gap_us", m.gap.count()},
                         {"size", size},
                         {"complete", complete},
                         {"errors", c.errors},
                         {"runs", runs},
                         {"p50_us", s.p50},
                         {"p50_min_us", s.p50_min},
                         {"p50_max_us", s.p50_max},
                         {"p99_us", s.p99},
                         {"min_us", s.min},
                         {"max_us", s.max},
                         {"ratio_to_udp", ratio}});
      }
  }
  for (auto& v : variants)
    std::cout << "\n  " << v.name << ": " << v.label;
  std::cout << "\n  herm and caf clients: one event-based actor, next request from the "
               "reply's then-callback\n";
  std::cout << (ok ? "all cases complete" : "SOME CASES FAILED") << std::endl;

  if (!json_path.empty()) {
    utsname un{};
    ::uname(&un);
    nlohmann::json skipped_json = nlohmann::json::array();
    for (auto& [name, why] : skipped)
      skipped_json.push_back({{"transport", name}, {"reason", why}});
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
        {"repeat", repeat},
        {"hello_ms", ep.hello.count()},
        {"timeout_ms", timeout_ms},
        {"modes",
         {{{"name", modes[0].name}, {"gap_us", 0}, {"count", count}, {"warmup", warmup}},
          {{"name", modes[1].name}, {"gap_us", modes[1].gap.count()},
           {"count", gap_count}, {"warmup", gap_warmup}}}}}},
      {"units", "microseconds"},
      {"skipped", skipped_json},
      {"cases", cases},
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
