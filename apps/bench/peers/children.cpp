// herm-bench-rtt's child processes (see children.hpp): spawning, reading
// their lines with a deadline, stopping them, free UDP ports, and the
// client's result line.

#include "apps/bench/peers/children.hpp"

#include "apps/bench/peers/probes.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <variant>
#include <vector>

namespace herm::bench {

using namespace std::chrono_literals;

std::string self_exe() {
  char buf[4096];
  auto n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0)
    return "herm-bench-rtt";
  return std::string(buf, static_cast<size_t>(n));
}

namespace {

/// A child with its stdout on a pipe; stderr is ours.
struct child {
  pid_t pid = -1;
  int out = -1;
  std::string buffer;
};

/// Starts `args` with its stdout on a pipe, pinned to `cpu` (-1: not
/// pinned); a child that cannot be pinned says so on that pipe and exits.
std::optional<child> spawn(const std::vector<std::string>& args, int cpu) {
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
    if (cpu >= 0 && !pin_to_cpu(cpu)) {
      static const char msg[] = "error cannot pin the process to its vCPU\n";
      [[maybe_unused]] auto n = ::write(STDOUT_FILENO, msg, sizeof(msg) - 1);
      ::_exit(127);
    }
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
          "--mode", p.mode,
          "--policy", p.policy.empty() ? std::string{"loop"} : p.policy,
          "--port", std::to_string(p.port),
          "--port2", std::to_string(p.port2),
          "--port3", std::to_string(p.port3),
          "--port4", std::to_string(p.port4),
          "--hello-ms", std::to_string(p.hello.count()),
          "--size", std::to_string(p.size),
          "--count", std::to_string(p.count),
          "--warmup", std::to_string(p.warmup),
          "--gap-us", std::to_string(p.gap.count()),
          "--timeout-ms", std::to_string(p.timeout.count()),
          "--window", std::to_string(p.window),
          "--ack-every", std::to_string(p.ack_every),
          "--stall-ms", std::to_string(p.stall.count()),
          "--batch", p.batch ? "1" : "0",
          "--tag", p.tag,
          "--counter-fd", std::to_string(p.counter_fd),
          "--server-pid", std::to_string(p.server_pid),
          "--router-pid", std::to_string(p.router_pid),
          "--count-syscalls", p.count_syscalls ? "1" : "0"};
}

/// Distinct free UDP ports.
std::vector<uint16_t> free_udp_ports(size_t n) {
  std::vector<uint16_t> ports;
  while (ports.size() < n) {
    auto x = free_udp_port();
    if (x != 0 && std::find(ports.begin(), ports.end(), x) == ports.end())
      ports.push_back(x);
  }
  return ports;
}

} // namespace

std::string format_counts(const case_counts& c) {
  std::string out = "counts";
  for (auto& x : c)
    for (auto v : {x.wakeups, x.voluntary_switches, x.allocs, x.syscalls})
      out += " " + std::to_string(v);
  return out;
}

std::variant<client_result, std::string> parse_result(const std::string& out) {
  client_result res;
  if (out.rfind("rtt ", 0) == 0) {
    std::istringstream in{out.substr(4)};
    size_t n = 0;
    in >> n;
    if (!in || n > 100'000'000)
      return std::string{"client: malformed result"};
    res.rtt_ns.resize(n);
    for (auto& x : res.rtt_ns)
      in >> x;
    if (!in)
      return std::string{"client: truncated result"};
    std::string word;
    if (in >> word) {
      if (word != "counts")
        return "client: unexpected '" + word + "' after the round trips";
      for (auto& x : res.counts)
        in >> x.wakeups >> x.voluntary_switches >> x.allocs >> x.syscalls;
      if (!in)
        return std::string{"client: truncated counts"};
    }
    return res;
  }
  if (out.rfind("oneway ", 0) == 0) {
    std::istringstream in{out.substr(7)};
    in >> res.sent >> res.received >> res.elapsed_ns >> res.stalls >> res.client_allocs
      >> res.server_allocs;
    if (!in)
      return std::string{"client: truncated result"};
    return res;
  }
  return "client: " + out;
}

/// One repetition of one case: fresh processes (a router, a server, a client
/// as the mode needs).
std::variant<client_result, std::string> run_pair(const std::string& exe, endpoint_params p,
                                                  const placement& where) {
  static int serial = 0;
  ++serial;
  if (p.transport == "herm" || p.mode == "inprocess") {
    auto ports = free_udp_ports(4);
    p.port = ports[0];
    p.port2 = ports[1];
    p.port3 = ports[2];
    p.port4 = ports[3];
  } else if (p.transport == "dds") {
    // A domain and topic names of our own: other DDS programs on this
    // machine neither see nor disturb this run.
    p.port = static_cast<uint16_t>(1 + ::getpid() % 200);
    p.tag = std::to_string(::getpid()) + "_" + std::to_string(serial);
  } else {
    p.port = 0;
  }
  // The children inherit the page; this process needs it no longer once the
  // last of them has started.
  p.counter_fd = make_counter_page();
  std::vector<child> helpers; // router, server
  auto stop_all = [&] {
    for (auto i = helpers.rbegin(); i != helpers.rend(); ++i)
      stop(*i);
    if (p.counter_fd >= 0)
      ::close(p.counter_fd);
    p.counter_fd = -1;
  };
  auto start_helper = [&](const std::string& role) -> std::string {
    auto c = spawn(endpoint_args(exe, role, p), role == "router" ? where.router_cpu
                                                                 : where.server_cpu);
    if (!c)
      return "cannot start the " + role;
    helpers.push_back(*c);
    (role == "router" ? p.router_pid : p.server_pid) = c->pid;
    auto line = read_line(helpers.back(), std::chrono::steady_clock::now() + 30s);
    if (!line || line->rfind("ready ", 0) != 0)
      return role + ": " + (line ? *line : std::string{"no ready line within 30 s"});
    if (role == "server") {
      // "ready PORT [PORT2]": the second port is zmq's acknowledgement port.
      std::istringstream in{line->substr(6)};
      unsigned a = 0, b = 0;
      in >> a;
      p.port = static_cast<uint16_t>(a);
      if (in >> b)
        p.port2 = static_cast<uint16_t>(b);
    }
    return {};
  };
  if (p.mode == "router")
    if (auto err = start_helper("router"); !err.empty()) {
      stop_all();
      return err;
    }
  if (p.mode != "inprocess")
    if (auto err = start_helper("server"); !err.empty()) {
      stop_all();
      return err;
    }
  auto client = spawn(endpoint_args(exe, "client", p), where.client_cpu);
  if (!client) {
    stop_all();
    return std::string{"cannot start the client"};
  }
  auto budget = 60s + (p.warmup + p.count)
                        * std::chrono::duration_cast<std::chrono::milliseconds>(
                          p.gap + std::chrono::milliseconds(p.mode == "oneway" ? 1 : 5));
  auto out = read_line(*client, std::chrono::steady_clock::now() + budget);
  stop(*client);
  stop_all();
  if (!out)
    return std::string{"client: no result within the time budget"};
  return parse_result(*out);
}

} // namespace herm::bench
