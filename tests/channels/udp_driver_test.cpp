// Specification of the "udp" link kind (channels/drivers/udp.cpp).
//
// Three groups:
//  - udp_driver: drivers on loopback (127.0.0.1, ephemeral ports) in this
//    process;
//  - udp_driver_processes: a child process (this binary re-executed in
//    "agent mode", see agent_main) runs its own driver and echoes every frame;
//  - udp_driver_segment: a real Ethernet segment. As root, the test creates
//    four network namespaces (herm-<pid>-a/b/c and herm-<pid>-br), joins the
//    three stations to a Linux bridge inside the fourth with veth pairs
//    (nothing is added to the host's own namespace), runs one driver per
//    station in an agent process that entered the namespace with setns(), and
//    deletes every namespace afterwards, also on failure. It skips, saying
//    why, when not root or when namespaces, veth pairs or bridges cannot be
//    created. Set HERM_NO_NETNS=1 to skip it on purpose.
//
// Every wait is bounded (wait_limit); no test asserts speed. All traffic goes
// to loopback or to addresses inside the namespaces the test creates.

#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "channels/error.hpp"
#include "channels/drivers/udp_addr.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"
#include "tests/channels/recorder.hpp"

extern char** environ;

namespace herm {
namespace {

using namespace std::chrono_literals;
using clock_type = std::chrono::steady_clock;
using test::recorder;

/// Upper bound for anything the tests wait for.
constexpr auto wait_limit = 5s;

constexpr uint32_t loopback_ip = 0x7F000001;

// -- helpers -------------------------------------------------------------------

byte_buffer bytes_of(const std::string& text) {
  return byte_buffer(text.begin(), text.end());
}

byte_buffer pattern(size_t size, uint8_t seed) {
  byte_buffer result(size);
  for (size_t i = 0; i < size; ++i)
    result[i] = static_cast<uint8_t>(seed + i * 7);
  return result;
}

std::string to_hex(const uint8_t* data, size_t size) {
  static const char digits[] = "0123456789abcdef";
  std::string result;
  for (size_t i = 0; i < size; ++i) {
    result += digits[data[i] >> 4];
    result += digits[data[i] & 0xF];
  }
  return result;
}

std::string to_hex(const byte_buffer& buf) {
  return to_hex(buf.data(), buf.size());
}

byte_buffer from_hex(const std::string& hex) {
  byte_buffer result;
  for (size_t i = 0; i + 1 < hex.size(); i += 2)
    result.push_back(
      static_cast<uint8_t>(std::stoi(hex.substr(i, 2), nullptr, 16)));
  return result;
}

device_config udp_config(std::string name, std::string interface,
                         option_map options = {}) {
  device_config cfg;
  cfg.name = std::move(name);
  cfg.kind = "udp";
  cfg.interface = std::move(interface);
  cfg.options = std::move(options);
  return cfg;
}

caf::expected<link_driver_ptr> open_udp(const device_config& cfg) {
  auto* kind = find_link_kind("udp");
  if (kind == nullptr)
    return make_error(ec::unknown_link_kind, "udp is not registered");
  return kind->open(cfg);
}

caf::error send_bytes(link_driver& drv, link_addr dst, const byte_buffer& buf) {
  return drv.send(dst, buf.data(), buf.size(), prio_normal);
}

/// A started driver and what it heard.
struct station {
  std::shared_ptr<recorder> rec = std::make_shared<recorder>();
  link_driver_ptr drv;

  ~station() {
    if (drv)
      drv->stop();
  }
};

/// Opens and starts a driver on `loop` (default: the process's shared
/// loop); the error text on failure, "" on success.
std::string start_station(station& st, const device_config& cfg,
                          event_loop* loop = nullptr) {
  auto drv = open_udp(cfg);
  if (!drv)
    return "open failed: " + render(drv.error());
  if (auto err = loop != nullptr ? (*drv)->start(st.rec, *loop)
                                 : (*drv)->start(st.rec))
    return "start failed: " + render(err);
  st.drv = std::move(*drv);
  return "";
}

/// A plain UDP socket on 127.0.0.1 that sends whatever a test wants.
class raw_socket {
public:
  raw_socket() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    auto sa = udp::to_sockaddr(udp::make_addr(loopback_ip, 0));
    if (fd_ >= 0
        && ::bind(fd_, reinterpret_cast<const sockaddr*>(&sa), sizeof(sa)) == 0) {
      socklen_t len = sizeof(sa);
      ::getsockname(fd_, reinterpret_cast<sockaddr*>(&sa), &len);
      local_ = udp::from_sockaddr(sa);
    }
  }

  raw_socket(const raw_socket&) = delete;
  raw_socket& operator=(const raw_socket&) = delete;

  ~raw_socket() {
    if (fd_ >= 0)
      ::close(fd_);
  }

  bool ok() const {
    return fd_ >= 0 && local_ != 0;
  }

  link_addr local() const {
    return local_;
  }

  bool send_to(link_addr dst, const byte_buffer& buf) {
    auto sa = udp::to_sockaddr(dst);
    auto res = ::sendto(fd_, buf.data(), buf.size(), 0,
                        reinterpret_cast<const sockaddr*>(&sa), sizeof(sa));
    return res == static_cast<ssize_t>(buf.size());
  }

private:
  int fd_ = -1;
  link_addr local_ = 0;
};

// -- agent processes -------------------------------------------------------------

// An agent is a child process that runs one udp driver (optionally inside a
// network namespace) and talks to the test over a SOCK_SEQPACKET socket pair:
//   test -> agent: "config ..." (first, see agent_setup), "send DST HEX"
//                  (DST is A.B.C.D:PORT or *), "quit"
//   agent -> test: "ready LOCAL", "sent ok" / "sent ERROR", "frame SRC HEX",
//                  "malformed SRC WHY", "failure TEXT", "bye"
// In echo mode the agent also sends every frame back to its source.

bool send_msg(int fd, const std::string& msg) {
  return ::send(fd, msg.data(), msg.size(), MSG_NOSIGNAL)
         == static_cast<ssize_t>(msg.size());
}

class agent_handler : public frame_handler {
public:
  agent_handler(int ctl, bool echo) : ctl_(ctl), echo_(echo) {
  }

  void set_driver(link_driver* drv) {
    drv_ = drv;
  }

  void on_frame(link_addr src, const uint8_t* data, size_t size) override {
    send_msg(ctl_, "frame " + udp::format_addr(src) + " " + to_hex(data, size));
    if (echo_ && drv_ != nullptr)
      if (auto err = drv_->send(src, data, size, prio_normal))
        send_msg(ctl_, "failure echo: " + render(err));
  }

  void on_malformed(link_addr src, const char* why) override {
    send_msg(ctl_, "malformed " + udp::format_addr(src) + " " + why);
  }

  void on_event(link_event_kind, link_addr, std::string) override {
  }

  void on_failure(caf::error reason) override {
    send_msg(ctl_, "failure " + render(reason));
  }

private:
  int ctl_;
  bool echo_;
  link_driver* drv_ = nullptr;
};

/// What an agent runs: sent by the test as the first control message,
/// "config" followed by lines "name=", "interface=", "netns=", "echo=0|1"
/// and one "option=KEY=VALUE" per option.
struct agent_setup {
  std::string netns;
  device_config cfg;
  bool echo = false;
};

std::string encode(const agent_setup& setup) {
  std::string result = "config\nname=" + setup.cfg.name + "\ninterface="
                       + setup.cfg.interface + "\nnetns=" + setup.netns
                       + "\necho=" + (setup.echo ? "1" : "0") + "\n";
  for (auto& [key, value] : setup.cfg.options)
    result += "option=" + key + "=" + value + "\n";
  return result;
}

agent_setup decode(const std::string& text) {
  agent_setup result;
  result.cfg.kind = "udp";
  size_t pos = 0;
  while (pos < text.size()) {
    auto eol = text.find('\n', pos);
    auto line = text.substr(pos, eol - pos);
    pos = eol == std::string::npos ? text.size() : eol + 1;
    auto eq = line.find('=');
    if (eq == std::string::npos)
      continue;
    auto key = line.substr(0, eq);
    auto value = line.substr(eq + 1);
    if (key == "name")
      result.cfg.name = value;
    else if (key == "interface")
      result.cfg.interface = value;
    else if (key == "netns")
      result.netns = value;
    else if (key == "echo")
      result.echo = value == "1";
    else if (key == "option" && value.find('=') != std::string::npos)
      result.cfg.options[value.substr(0, value.find('='))]
        = value.substr(value.find('=') + 1);
  }
  return result;
}

/// Body of an agent process; never returns. Exit codes: 0 after "quit",
/// 2 orphaned, 3 setns failed, 4 driver failed, 5 test gone or time out.
[[noreturn]] void agent_main(int ctl, pid_t parent) {
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (::getppid() != parent)
    ::_exit(2);
  // Keep no other descriptor of the test.
  if (ctl > 3)
    ::close_range(3, static_cast<unsigned>(ctl) - 1, 0);
  ::close_range(static_cast<unsigned>(ctl) + 1, ~0u, 0);
  std::vector<char> buf(200'000);
  pollfd first{ctl, POLLIN, 0};
  if (::poll(&first, 1, 5000) <= 0)
    ::_exit(5);
  auto len = ::recv(ctl, buf.data(), buf.size(), 0);
  if (len <= 0)
    ::_exit(5);
  auto setup = decode(std::string(buf.data(), static_cast<size_t>(len)));
  if (!setup.netns.empty()) {
    auto path = "/var/run/netns/" + setup.netns;
    auto nfd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (nfd < 0 || ::setns(nfd, CLONE_NEWNET) != 0) {
      send_msg(ctl, "failure setns " + path + ": " + std::strerror(errno));
      ::_exit(3);
    }
    ::close(nfd);
  }
  auto drv = open_udp(setup.cfg);
  if (!drv) {
    send_msg(ctl, "failure " + render(drv.error()));
    ::_exit(4);
  }
  auto handler = std::make_shared<agent_handler>(ctl, setup.echo);
  handler->set_driver(drv->get());
  if (auto err = (*drv)->start(handler)) {
    send_msg(ctl, "failure " + render(err));
    ::_exit(4);
  }
  send_msg(ctl, "ready " + udp::format_addr((*drv)->local_addr()));
  // An orphaned agent never outlives this bound.
  auto deadline = clock_type::now() + 120s;
  while (clock_type::now() < deadline) {
    pollfd pfd{ctl, POLLIN, 0};
    if (::poll(&pfd, 1, 500) <= 0)
      continue;
    auto n = ::recv(ctl, buf.data(), buf.size(), 0);
    if (n <= 0)
      break; // The test is gone.
    std::string cmd(buf.data(), static_cast<size_t>(n));
    if (cmd == "quit") {
      (*drv)->stop();
      send_msg(ctl, "bye");
      ::_exit(0);
    }
    if (cmd.rfind("send ", 0) == 0) {
      auto space = cmd.find(' ', 5);
      auto dst_text = cmd.substr(5, space - 5);
      auto payload = from_hex(space == std::string::npos ? ""
                                                         : cmd.substr(space + 1));
      link_addr dst = broadcast_addr;
      if (dst_text != "*") {
        auto parsed = (*drv)->parse_addr(dst_text);
        if (!parsed) {
          send_msg(ctl, "sent " + render(parsed.error()));
          continue;
        }
        dst = *parsed;
      }
      auto err = send_bytes(**drv, dst, payload);
      send_msg(ctl, err ? "sent " + render(err) : "sent ok");
      continue;
    }
    send_msg(ctl, "failure unknown command: " + cmd);
  }
  (*drv)->stop();
  ::_exit(5);
}

// Agent mode: agent::spawn re-executes this test binary with HERM_UDP_AGENT
// set to the control socket's descriptor (and HERM_UDP_AGENT_PARENT to the
// test's pid). Such a process runs one agent, before GoogleTest's main, and
// never returns. Re-executing (instead of a bare fork) keeps the child safe
// whatever threads the test process has (sanitizers add their own).
[[maybe_unused]] const bool agent_mode_checked = [] {
  auto* fd = std::getenv("HERM_UDP_AGENT");
  auto* parent = std::getenv("HERM_UDP_AGENT_PARENT");
  if (fd != nullptr && parent != nullptr)
    agent_main(std::atoi(fd), static_cast<pid_t>(std::atol(parent)));
  return true;
}();

/// The test's handle on an agent. Kills and reaps the child when destroyed.
class agent {
public:
  agent() = default;
  agent(const agent&) = delete;
  agent& operator=(const agent&) = delete;

  ~agent() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (ctl_ >= 0)
      ::close(ctl_);
  }

  /// Starts the agent (this binary in agent mode) with a driver for `cfg`,
  /// inside network namespace `netns` unless empty; "" or what failed.
  std::string spawn(const std::string& netns, const device_config& cfg,
                    bool echo) {
    int fds[2];
    if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, fds) != 0)
      return std::string{"socketpair: "} + std::strerror(errno);
    // dup2 onto another number clears close-on-exec in the child.
    int child_fd = fds[1] == 3 ? 4 : 3;
    std::vector<std::string> env;
    for (auto** e = environ; *e != nullptr; ++e)
      if (std::strncmp(*e, "HERM_UDP_AGENT", 14) != 0)
        env.emplace_back(*e);
    env.push_back("HERM_UDP_AGENT=" + std::to_string(child_fd));
    env.push_back("HERM_UDP_AGENT_PARENT=" + std::to_string(::getpid()));
    std::vector<char*> envp;
    for (auto& e : env)
      envp.push_back(e.data());
    envp.push_back(nullptr);
    std::string arg0 = "udp_driver_test-agent";
    char* argv[] = {arg0.data(), nullptr};
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], child_fd);
    pid_t pid = 0;
    auto rc = ::posix_spawn(&pid, "/proc/self/exe", &actions, nullptr, argv,
                            envp.data());
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[1]);
    if (rc != 0) {
      ::close(fds[0]);
      return std::string{"posix_spawn /proc/self/exe: "} + std::strerror(rc);
    }
    pid_ = pid;
    ctl_ = fds[0];
    if (!send_msg(ctl_, encode(agent_setup{netns, cfg, echo})))
      return std::string{"cannot configure the agent: "} + std::strerror(errno);
    return "";
  }

  /// Waits for "ready ADDR"; the agent's local address text, or nullopt.
  std::optional<std::string> wait_ready() {
    auto msg = wait_for("ready ", "failure ", wait_limit);
    if (!msg || msg->rfind("ready ", 0) != 0)
      return std::nullopt;
    return msg->substr(6);
  }

  /// Sends "send DST HEX" and returns the agent's reply ("sent ok" on
  /// success), or "no reply" after wait_limit.
  std::string send(const std::string& dst, const byte_buffer& payload) {
    if (!send_msg(ctl_, "send " + dst + " " + to_hex(payload)))
      return "control socket closed";
    auto msg = wait_for("sent ", "", wait_limit);
    return msg ? *msg : "no reply";
  }

  /// Reads messages for at most `limit` or until `pred` holds.
  template <class Pred>
  bool pump_until(Pred pred, clock_type::duration limit) {
    auto deadline = clock_type::now() + limit;
    while (!pred()) {
      if (!read_one(deadline))
        return pred();
    }
    return true;
  }

  /// Frames this agent's driver heard so far, as (source, payload).
  std::vector<std::pair<std::string, byte_buffer>> frames() const {
    std::vector<std::pair<std::string, byte_buffer>> result;
    for (auto& msg : log_)
      if (msg.rfind("frame ", 0) == 0) {
        auto space = msg.find(' ', 6);
        result.emplace_back(msg.substr(6, space - 6),
                            from_hex(space == std::string::npos
                                       ? ""
                                       : msg.substr(space + 1)));
      }
    return result;
  }

  /// Whether the agent heard `payload` from `src`.
  bool heard(const std::string& src, const byte_buffer& payload) const {
    for (auto& [from, bytes] : frames())
      if (from == src && bytes == payload)
        return true;
    return false;
  }

  /// Every "failure" or "malformed" message so far.
  std::vector<std::string> problems() const {
    std::vector<std::string> result;
    for (auto& msg : log_)
      if (msg.rfind("failure ", 0) == 0 || msg.rfind("malformed ", 0) == 0)
        result.push_back(msg);
    return result;
  }

  /// Asks the agent to quit and reaps it; its exit status (0 is success) or
  /// -1 if it had to be killed after wait_limit.
  int quit() {
    if (pid_ <= 0)
      return -1;
    send_msg(ctl_, "quit");
    auto deadline = clock_type::now() + wait_limit;
    while (clock_type::now() < deadline) {
      int status = 0;
      auto res = ::waitpid(pid_, &status, WNOHANG);
      if (res == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      read_one(clock_type::now() + 10ms);
    }
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
    return -1;
  }

private:
  /// Reads one message into log_; false on timeout or a closed socket.
  bool read_one(clock_type::time_point deadline) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      deadline - clock_type::now());
    if (left.count() < 0)
      return false;
    pollfd pfd{ctl_, POLLIN, 0};
    if (::poll(&pfd, 1, static_cast<int>(left.count())) <= 0)
      return false;
    std::vector<char> buf(200'000);
    auto n = ::recv(ctl_, buf.data(), buf.size(), MSG_DONTWAIT);
    if (n <= 0)
      return false;
    log_.emplace_back(buf.data(), static_cast<size_t>(n));
    return true;
  }

  /// Waits for a new message starting with `prefix` (or `alt`, if not empty).
  std::optional<std::string> wait_for(const std::string& prefix,
                                      const std::string& alt,
                                      clock_type::duration limit) {
    auto deadline = clock_type::now() + limit;
    for (;;) {
      for (; seen_ < log_.size(); ++seen_) {
        auto& msg = log_[seen_];
        if (msg.rfind(prefix, 0) == 0 || (!alt.empty() && msg.rfind(alt, 0) == 0))
          return log_[seen_++];
      }
      if (!read_one(deadline))
        return std::nullopt;
    }
  }

  pid_t pid_ = -1;
  int ctl_ = -1;
  std::vector<std::string> log_;
  size_t seen_ = 0; ///< Messages already matched by wait_for.
};

// -- network namespaces ----------------------------------------------------------

/// Runs a command without a shell; its exit status (-1 if it could not run or
/// did not finish within wait_limit) and its combined output in `out`.
int run_command(const std::vector<std::string>& args, std::string& out) {
  out.clear();
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0) {
    out = std::string{"pipe: "} + std::strerror(errno);
    return -1;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], 1);
  posix_spawn_file_actions_adddup2(&actions, pipe_fds[1], 2);
  std::vector<char*> argv;
  for (auto& arg : args)
    argv.push_back(const_cast<char*>(arg.c_str()));
  argv.push_back(nullptr);
  pid_t pid = 0;
  auto rc = ::posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(),
                           environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(pipe_fds[1]);
  if (rc != 0) {
    ::close(pipe_fds[0]);
    out = "cannot run '" + args[0] + "': " + std::strerror(rc);
    return -1;
  }
  auto deadline = clock_type::now() + wait_limit;
  char buf[512];
  for (;;) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      deadline - clock_type::now());
    pollfd pfd{pipe_fds[0], POLLIN, 0};
    if (left.count() <= 0 || ::poll(&pfd, 1, static_cast<int>(left.count())) <= 0) {
      ::kill(pid, SIGKILL);
      out += " (timed out)";
      break;
    }
    auto n = ::read(pipe_fds[0], buf, sizeof(buf));
    if (n <= 0)
      break;
    out.append(buf, static_cast<size_t>(n));
  }
  ::close(pipe_fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  while (!out.empty() && (out.back() == '\n' || out.back() == ' '))
    out.pop_back();
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// Three stations (namespaces herm-<pid>-a/b/c, interface eth0 with
/// 10.77.X.1..3/24) on a Linux bridge br0 inside namespace herm-<pid>-br.
/// Deletes every namespace it created when destroyed.
class netns_segment {
public:
  enum class outcome { ok, skip, fail };

  static constexpr const char* stations[] = {"a", "b", "c"};

  netns_segment() {
    auto pid = static_cast<unsigned>(::getpid());
    prefix_ = "herm-" + std::to_string(pid) + "-";
    subnet_ = 1 + pid % 254;
  }

  netns_segment(const netns_segment&) = delete;
  netns_segment& operator=(const netns_segment&) = delete;

  ~netns_segment() {
    std::string out;
    for (auto i = created_.rbegin(); i != created_.rend(); ++i)
      run_command({"ip", "netns", "delete", *i}, out);
  }

  std::string ns(const std::string& station) const {
    return prefix_ + station;
  }

  /// "10.77.X.N" for station index 0..2.
  std::string ip(size_t index) const {
    return "10.77." + std::to_string(subnet_) + "." + std::to_string(index + 1);
  }

  std::string broadcast_ip() const {
    return "10.77." + std::to_string(subnet_) + ".255";
  }

  /// Builds the segment. On skip or fail, `why` says what did not work.
  outcome create(std::string& why) {
    std::string out;
    auto bridge_ns = ns("br");
    if (!add_namespace(bridge_ns, why))
      return outcome::skip;
    if (ip_in(bridge_ns, {"link", "add", "br0", "type", "bridge",
                          "forward_delay", "0"},
              out)
        != 0) {
      why = "cannot create a Linux bridge (ip link add br0 type bridge): "
            + out;
      return outcome::skip;
    }
    if (ip_in(bridge_ns, {"link", "set", "br0", "up"}, out) != 0)
      return failed("ip link set br0 up", out, why);
    for (size_t i = 0; i < 3; ++i) {
      auto name = ns(stations[i]);
      auto port = std::string{"v"} + stations[i];
      if (!add_namespace(name, why))
        return outcome::skip;
      if (ip_in(bridge_ns, {"link", "add", port, "type", "veth", "peer",
                            "name", "eth0", "netns", name},
                out)
          != 0) {
        why = "cannot create a veth pair (ip link add type veth): " + out;
        return outcome::skip;
      }
      if (ip_in(bridge_ns, {"link", "set", port, "master", "br0", "up"}, out)
          != 0)
        return failed("ip link set " + port + " master br0 up", out, why);
      if (ip_in(name, {"addr", "add", ip(i) + "/24", "broadcast",
                       broadcast_ip(), "dev", "eth0"},
                out)
          != 0)
        return failed("ip addr add " + ip(i) + "/24 in " + name, out, why);
      if (ip_in(name, {"link", "set", "eth0", "up"}, out) != 0)
        return failed("ip link set eth0 up in " + name, out, why);
      if (ip_in(name, {"link", "set", "lo", "up"}, out) != 0)
        return failed("ip link set lo up in " + name, out, why);
    }
    return outcome::ok;
  }

private:
  bool add_namespace(const std::string& name, std::string& why) {
    std::string out;
    if (run_command({"ip", "netns", "add", name}, out) != 0) {
      why = "cannot create network namespace " + name + " (ip netns add): "
            + out;
      return false;
    }
    created_.push_back(name);
    return true;
  }

  static int ip_in(const std::string& ns_name, std::vector<std::string> args,
                   std::string& out) {
    args.insert(args.begin(), {"ip", "-n", ns_name});
    return run_command(args, out);
  }

  static outcome failed(const std::string& what, const std::string& out,
                        std::string& why) {
    why = what + " failed: " + out;
    return outcome::fail;
  }

  std::string prefix_;
  unsigned subnet_ = 0;
  std::vector<std::string> created_;
};

// -- registration and addresses ----------------------------------------------------

TEST(udp_driver, formats_and_parses_addresses_round_trip) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  struct {
    const char* text;
    link_addr addr;
  } cases[] = {
    {"10.0.0.2:47000", udp::make_addr(0x0A000002, 47000)},
    {"127.0.0.1:1", udp::make_addr(loopback_ip, 1)},
    {"0.0.0.0:65535", udp::make_addr(0, 65535)},
    {"255.255.255.255:47000", udp::make_addr(0xFFFFFFFF, 47000)},
    {"192.168.1.20:80", (link_addr{0xC0A80114} << 16) | 80},
  };
  for (auto& c : cases) {
    EXPECT_EQ(st.drv->format_addr(c.addr), c.text);
    auto parsed = st.drv->parse_addr(c.text);
    ASSERT_TRUE(parsed) << c.text << ": " << render(parsed.error());
    EXPECT_EQ(*parsed, c.addr) << c.text;
  }
}

TEST(udp_driver, refuses_to_parse_text_that_is_not_an_ipv4_address_and_port) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  const char* cases[] = {
    "",           "10.0.0.2",      "10.0.0.2:",       ":47000",
    "10.0.0.256:1", "10.0.0.2:65536", "10.0.0.2:0",   "10.0.0.2:-1",
    "10.0.0.2:+1", "robot.local:1", "[::1]:47000",     " 10.0.0.2:1",
    "10.0.0.2:1 ", "10.0.0:1",      "010.0.0.2:1",     "10.0.0.2:1:2",
    "10.0.0.2:x",  "*",
  };
  for (auto text : cases) {
    auto parsed = st.drv->parse_addr(text);
    ASSERT_FALSE(parsed) << "'" << text << "' parsed as " << *parsed;
    EXPECT_TRUE(is(parsed.error(), ec::invalid_address)) << text;
    auto msg = render(parsed.error());
    EXPECT_NE(msg.find("'" + std::string{text} + "'"), std::string::npos)
      << msg;
    EXPECT_NE(msg.find("device 'eth0'"), std::string::npos) << msg;
  }
}

TEST(udp_driver, resolves_an_ephemeral_port_to_the_bound_address) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  auto local = st.drv->local_addr();
  EXPECT_EQ(udp::ip_of(local), loopback_ip);
  EXPECT_NE(udp::port_of(local), 0);
  auto param = st.drv->get_param("local");
  ASSERT_TRUE(param);
  EXPECT_EQ(*param, st.drv->format_addr(local));
}

// -- loopback traffic ------------------------------------------------------------

TEST(udp_driver, broadcast_without_peers_or_broadcast_address_sends_nothing_and_succeeds) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  EXPECT_EQ(render(send_bytes(*st.drv, broadcast_addr, bytes_of("anyone?"))),
            "none");
}

TEST(udp_driver, ignores_datagrams_from_its_own_address_and_port) {
  station a;
  ASSERT_EQ(start_station(a, udp_config("a", "127.0.0.1:0")), "");
  raw_socket other;
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(render(send_bytes(*a.drv, a.drv->local_addr(), bytes_of("to myself"))), "none");
  // Same IP, another port: a different module, delivered. It was sent after
  // the self-addressed datagram, which would have been queued first.
  ASSERT_TRUE(other.send_to(a.drv->local_addr(), bytes_of("from a neighbour")));
  ASSERT_TRUE(a.rec->wait_frames(1));
  auto heard = a.rec->frames();
  ASSERT_EQ(heard.size(), 1u);
  EXPECT_EQ(heard[0].src, other.local());
  EXPECT_EQ(heard[0].bytes, bytes_of("from a neighbour"));
}

TEST(udp_driver, reports_oversized_and_empty_datagrams_as_malformed_and_keeps_receiving) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0",
                                         {{"mtu", "100"}})),
            "");
  raw_socket raw;
  ASSERT_TRUE(raw.ok());
  auto dst = st.drv->local_addr();
  ASSERT_TRUE(raw.send_to(dst, pattern(101, 1)));
  ASSERT_TRUE(raw.send_to(dst, byte_buffer{}));
  ASSERT_TRUE(raw.send_to(dst, pattern(60'000, 2)));
  ASSERT_TRUE(raw.send_to(dst, pattern(100, 3)));
  ASSERT_TRUE(st.rec->wait_frames(1));
  ASSERT_TRUE(st.rec->wait_malformed(3));
  auto heard = st.rec->frames();
  ASSERT_EQ(heard.size(), 1u);
  EXPECT_EQ(heard[0].src, raw.local());
  EXPECT_EQ(heard[0].bytes, pattern(100, 3));
  auto bad = st.rec->malformed_frames();
  ASSERT_EQ(bad.size(), 3u);
  EXPECT_EQ(bad[0].why, "oversized");
  EXPECT_EQ(bad[1].why, "empty");
  EXPECT_EQ(bad[2].why, "oversized");
  for (auto& m : bad)
    EXPECT_EQ(m.src, raw.local());
  EXPECT_TRUE(st.rec->failures().empty());
}

TEST(udp_driver, delivers_bursts_longer_than_one_receive_batch_in_order) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0",
                                         {{"rcvbuf", "1048576"}})),
            "");
  raw_socket raw;
  ASSERT_TRUE(raw.ok());
  constexpr size_t n = 80; // more than two batches of 32
  for (size_t i = 0; i < n; ++i)
    ASSERT_TRUE(raw.send_to(st.drv->local_addr(),
                            pattern(10 + i, static_cast<uint8_t>(i))));
  ASSERT_TRUE(st.rec->wait_frames(n));
  auto heard = st.rec->frames();
  ASSERT_EQ(heard.size(), n);
  for (size_t i = 0; i < n; ++i)
    EXPECT_EQ(heard[i].bytes, pattern(10 + i, static_cast<uint8_t>(i))) << i;
}

// -- sending limits --------------------------------------------------------------

TEST(udp_driver, defaults_to_the_ethernet_profile_with_an_mtu_of_1472) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  auto& p = st.drv->profile();
  EXPECT_EQ(p.name, "ethernet");
  EXPECT_EQ(p.mtu, 1472u);
  EXPECT_EQ(p.bandwidth_bps, 100'000'000u);
  EXPECT_TRUE(p.multi_access);
  auto mtu = st.drv->get_param("mtu");
  ASSERT_TRUE(mtu);
  EXPECT_EQ(*mtu, "1472");
}

TEST(udp_driver, takes_the_mtu_and_profile_from_options) {
  struct {
    option_map options;
    std::string profile;
    uint32_t mtu;
  } cases[] = {
    {{{"mtu", "9000"}}, "ethernet", 9000},
    {{{"mtu", "65507"}}, "ethernet", 65507},
    {{{"profile", "can2.0"}}, "can2.0", 8},
    {{{"profile", "ieee1394b"}}, "ieee1394b", 1472},
    {{{"profile", "ieee1394b"}, {"mtu", "8192"}}, "ieee1394b", 8192},
  };
  for (auto& c : cases) {
    auto drv = open_udp(udp_config("eth0", "127.0.0.1:0", c.options));
    ASSERT_TRUE(drv) << render(drv.error());
    EXPECT_EQ((*drv)->profile().name, c.profile);
    EXPECT_EQ((*drv)->profile().mtu, c.mtu) << c.profile;
  }
}

TEST(udp_driver, carries_frames_up_to_the_largest_udp_payload_when_configured) {
  station a;
  station b;
  option_map big{{"mtu", "65507"}};
  ASSERT_EQ(start_station(a, udp_config("a", "127.0.0.1:0", big)), "");
  ASSERT_EQ(start_station(b, udp_config("b", "127.0.0.1:0", big)), "");
  EXPECT_EQ(render(send_bytes(*a.drv, b.drv->local_addr(), pattern(65507, 9))), "none");
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_EQ(b.rec->frames()[0].bytes, pattern(65507, 9));
}

TEST(udp_driver, refuses_empty_frames_and_destinations_that_are_not_udp_endpoints) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  auto err = st.drv->send(st.drv->local_addr(), nullptr, 0, prio_normal);
  EXPECT_TRUE(is(err, ec::invalid_parameter)) << render(err);
  err = send_bytes(*st.drv, udp::max_addr + 1, bytes_of("x"));
  EXPECT_TRUE(is(err, ec::invalid_address)) << render(err);
  err = send_bytes(*st.drv, udp::make_addr(loopback_ip, 0), bytes_of("x"));
  EXPECT_TRUE(is(err, ec::invalid_address)) << render(err);
  EXPECT_NE(render(err).find("127.0.0.1:0"), std::string::npos) << render(err);
}

// -- configuration errors --------------------------------------------------------

TEST(udp_driver, reports_a_busy_port_as_device_unavailable_naming_the_address) {
  station first;
  ASSERT_EQ(start_station(first, udp_config("first", "127.0.0.1:0")),
            "");
  auto taken = first.drv->format_addr(first.drv->local_addr());
  auto second = open_udp(udp_config("second", taken));
  ASSERT_FALSE(second);
  EXPECT_TRUE(is(second.error(), ec::device_unavailable))
    << render(second.error());
  auto msg = render(second.error());
  EXPECT_NE(msg.find("device 'second'"), std::string::npos) << msg;
  EXPECT_NE(msg.find(taken), std::string::npos) << msg;
  EXPECT_NE(msg.find(std::strerror(EADDRINUSE)), std::string::npos) << msg;
}

TEST(udp_driver, refuses_interface_strings_that_are_not_an_address_to_bind) {
  const char* cases[] = {"",          "47000",        "localhost:47000",
                         "0.0.0.0",   "0.0.0.0:70000", "eth0",
                         "0.0.0.0:-1", "1.2.3:47000"};
  for (auto text : cases) {
    auto drv = open_udp(udp_config("eth7", text));
    ASSERT_FALSE(drv) << "'" << text << "' was accepted";
    EXPECT_TRUE(is(drv.error(), ec::invalid_address)) << render(drv.error());
    auto msg = render(drv.error());
    EXPECT_NE(msg.find("device 'eth7'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("interface '" + std::string{text} + "'"),
              std::string::npos)
      << msg;
  }
}

TEST(udp_driver, refuses_bad_option_values_naming_the_device_option_and_text) {
  struct {
    const char* key;
    const char* value;
    ec code;
    const char* mentions;
  } cases[] = {
    {"peers", "127.0.0.1:5000,nonsense", ec::invalid_address, "nonsense"},
    {"peers", "127.0.0.1:5000,", ec::invalid_address, "127.0.0.1:5000,"},
    {"peers", "127.0.0.1:0", ec::invalid_address, "127.0.0.1:0"},
    {"broadcast", "10.77.0.255", ec::invalid_address, "10.77.0.255"},
    {"broadcast", "", ec::invalid_address, "broadcast"},
    {"rcvbuf", "lots", ec::invalid_parameter, "lots"},
    {"sndbuf", "10", ec::invalid_parameter, "10"},
    {"mtu", "0", ec::invalid_parameter, "0"},
    {"mtu", "65508", ec::invalid_parameter, "65508"},
    {"profile", "token-ring", ec::invalid_parameter, "token-ring"},
    {"bind_device", "an-interface-name-too-long", ec::invalid_parameter,
     "an-interface-name-too-long"},
    {"bind_device", "herm-nodev9", ec::device_unavailable, "herm-nodev9"},
  };
  for (auto& c : cases) {
    auto drv = open_udp(udp_config("eth7", "127.0.0.1:0", {{c.key, c.value}}));
    ASSERT_FALSE(drv) << c.key << "=" << c.value << " was accepted";
    auto msg = render(drv.error());
    EXPECT_TRUE(is(drv.error(), c.code)) << msg;
    EXPECT_NE(msg.find("device 'eth7'"), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.key), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.mentions), std::string::npos) << msg;
  }
}

TEST(udp_driver, refuses_unknown_options) {
  auto drv = open_udp(udp_config("eth7", "127.0.0.1:0",
                                 {{"peer", "127.0.0.1:5000"}}));
  ASSERT_FALSE(drv);
  EXPECT_TRUE(is(drv.error(), ec::invalid_parameter)) << render(drv.error());
  auto msg = render(drv.error());
  EXPECT_NE(msg.find("'peer'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("device 'eth7'"), std::string::npos) << msg;
}

TEST(udp_driver, accepts_every_documented_option) {
  auto drv = open_udp(udp_config("eth0", "127.0.0.1:0",
                                 {{"profile", "ethernet"},
                                  {"mtu", "1400"},
                                  {"peers", "127.0.0.1:47001"},
                                  {"broadcast", "127.255.255.255:47001"},
                                  {"bind_device", "lo"},
                                  {"rcvbuf", "65536"},
                                  {"sndbuf", "65536"}}));
  ASSERT_TRUE(drv) << render(drv.error());
}

TEST(udp_driver, reports_local_peers_and_broadcast_parameters) {
  auto drv = open_udp(udp_config("eth0", "127.0.0.1:0",
                                 {{"peers", "127.0.0.1:47001, 10.0.0.2:47000"},
                                  {"broadcast", "10.77.0.255:47000"}}));
  ASSERT_TRUE(drv) << render(drv.error());
  auto& d = **drv;
  EXPECT_EQ(d.get_param("local").value(), d.format_addr(d.local_addr()));
  EXPECT_EQ(d.get_param("peers").value(), "127.0.0.1:47001,10.0.0.2:47000");
  EXPECT_EQ(d.get_param("broadcast").value(), "10.77.0.255:47000");
  EXPECT_EQ(d.get_param("profile").value(), "ethernet");
  auto plain = open_udp(udp_config("eth1", "127.0.0.1:0"));
  ASSERT_TRUE(plain) << render(plain.error());
  EXPECT_EQ((*plain)->get_param("peers").value(), "");
  EXPECT_EQ((*plain)->get_param("broadcast").value(), "");
  EXPECT_TRUE(is((*plain)->get_param("colour").error(), ec::invalid_parameter));
}

// -- lifetime --------------------------------------------------------------------

TEST(udp_driver, stop_is_idempotent_and_releases_the_port) {
  station st;
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  auto local = st.drv->format_addr(st.drv->local_addr());
  st.drv->stop();
  st.drv->stop();
  auto err = send_bytes(*st.drv, st.drv->local_addr(), bytes_of("late"));
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
  EXPECT_TRUE(is(st.drv->start(std::make_shared<recorder>()),
                 ec::device_unavailable));
  // The socket is closed: the same address can be bound again.
  auto again = open_udp(udp_config("eth0", local));
  EXPECT_TRUE(again) << render(again.error());
}

TEST(udp_driver, destructor_stops_a_driver_that_was_never_started_or_stopped) {
  std::string local;
  {
    auto idle = open_udp(udp_config("idle", "127.0.0.1:0"));
    ASSERT_TRUE(idle) << render(idle.error());
    local = (*idle)->format_addr((*idle)->local_addr());
  }
  {
    auto running = open_udp(udp_config("running", local));
    ASSERT_TRUE(running) << render(running.error());
    ASSERT_EQ(render((*running)->start(std::make_shared<recorder>())), "none");
  }
  auto again = open_udp(udp_config("again", local));
  EXPECT_TRUE(again) << render(again.error());
}

TEST(udp_driver, refuses_a_second_start_and_a_missing_handler) {
  auto drv = open_udp(udp_config("eth0", "127.0.0.1:0"));
  ASSERT_TRUE(drv) << render(drv.error());
  EXPECT_TRUE(is((*drv)->start(nullptr), ec::invalid_parameter));
  ASSERT_EQ(render((*drv)->start(std::make_shared<recorder>())), "none");
  EXPECT_TRUE(is((*drv)->start(std::make_shared<recorder>()),
                 ec::device_unavailable));
  (*drv)->stop();
}

// -- the event loop ----------------------------------------------------------------

TEST(udp_driver, hands_frames_to_the_handler_on_the_loop_thread_only) {
  auto io = io_thread::make();
  ASSERT_TRUE(io) << render(io.error());
  auto& loop = (*io)->loop();
  station st;
  std::atomic<size_t> elsewhere{0};
  st.rec->on_each_frame([&](const recorder::frame&) {
    if (!loop.in_loop_thread())
      ++elsewhere;
  });
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0"), &loop), "");
  raw_socket raw;
  ASSERT_TRUE(raw.ok());
  for (uint8_t i = 0; i < 20; ++i)
    ASSERT_TRUE(raw.send_to(st.drv->local_addr(), pattern(8, i)));
  ASSERT_TRUE(st.rec->wait_frames(20));
  st.drv->stop();
  EXPECT_EQ(elsewhere.load(), 0u);
}

TEST(udp_driver, reads_one_batch_per_turn_so_a_busy_link_does_not_starve_another) {
  // No thread runs this loop: the test turns it, so a turn is observable.
  auto made = event_loop::make();
  ASSERT_TRUE(made) << render(made.error());
  auto& loop = **made;
  station busy;
  station quiet;
  ASSERT_EQ(start_station(busy, udp_config("busy", "127.0.0.1:0",
                                           {{"rcvbuf", "1048576"}}),
                          &loop),
            "");
  ASSERT_EQ(start_station(quiet, udp_config("quiet", "127.0.0.1:0"), &loop),
            "");
  raw_socket raw;
  ASSERT_TRUE(raw.ok());
  constexpr size_t n = 100; // above one batch (32 datagrams)
  for (size_t i = 0; i < n; ++i)
    ASSERT_TRUE(raw.send_to(busy.drv->local_addr(),
                            pattern(8, static_cast<uint8_t>(i))));
  ASSERT_TRUE(raw.send_to(quiet.drv->local_addr(), bytes_of("me too")));
  loop.run_once(0);
  EXPECT_EQ(quiet.rec->payloads(), std::vector<byte_buffer>{bytes_of("me too")});
  auto first_turn = busy.rec->frames().size();
  EXPECT_GE(first_turn, 1u);
  EXPECT_LT(first_turn, n) << "one callback drained the whole socket";
  // Later turns deliver the rest, in order.
  for (int turn = 0; turn < 100 && busy.rec->frames().size() < n; ++turn)
    loop.run_once(0);
  auto heard = busy.rec->payloads();
  ASSERT_EQ(heard.size(), n);
  for (size_t i = 0; i < n; ++i)
    EXPECT_EQ(heard[i], pattern(8, static_cast<uint8_t>(i))) << i;
}

TEST(udp_driver, stop_from_another_thread_while_frames_arrive_returns_after_the_last_handler_call) {
  station st;
  std::atomic<bool> returned{false};
  std::atomic<size_t> late{0};
  st.rec->on_each_frame([&](const recorder::frame&) {
    if (returned)
      ++late;
  });
  ASSERT_EQ(start_station(st, udp_config("eth0", "127.0.0.1:0")), "");
  auto dst = st.drv->local_addr();
  std::atomic<bool> done{false};
  std::thread flood{[&] {
    raw_socket raw;
    // Until the test is done, then 200 more after stop returned.
    for (size_t after = 0; raw.ok() && after < 200; after += done ? 1 : 0) {
      raw.send_to(dst, bytes_of("flood"));
      if (!done)
        std::this_thread::yield();
    }
  }};
  bool arrived = st.rec->wait_frames(10);
  st.drv->stop();
  returned = true;
  done = true;
  flood.join();
  ASSERT_TRUE(arrived);
  EXPECT_EQ(late.load(), 0u);
  EXPECT_TRUE(st.rec->failures().empty());
}

TEST(udp_driver, stop_from_a_handler_with_frames_queued_delivers_no_further_frame) {
  auto made = event_loop::make();
  ASSERT_TRUE(made) << render(made.error());
  auto& loop = **made;
  station st;
  st.rec->on_each_frame([&](const recorder::frame&) { st.drv->stop(); });
  auto drv = open_udp(udp_config("eth0", "127.0.0.1:0"));
  ASSERT_TRUE(drv) << render(drv.error());
  st.drv = *drv;
  raw_socket raw;
  ASSERT_TRUE(raw.ok());
  // Ten datagrams wait in the socket before the first callback: one batch.
  for (uint8_t i = 0; i < 10; ++i)
    ASSERT_TRUE(raw.send_to(st.drv->local_addr(), pattern(4, i)));
  ASSERT_FALSE(st.drv->start(st.rec, loop));
  for (int turn = 0; turn < 10; ++turn)
    loop.run_once(0);
  EXPECT_EQ(st.rec->payloads(), std::vector<byte_buffer>{pattern(4, 0)});
  EXPECT_EQ(loop.watched(), 0u);
  EXPECT_TRUE(is(send_bytes(*st.drv, raw.local(), bytes_of("late")),
                 ec::device_failed));
}

// -- several processes -----------------------------------------------------------

/// Holds its driver's receive thread in the first on_frame until opened,
/// so that the socket's receive buffer fills; counts frames and the drops
/// the driver reports.
class gated_handler : public frame_handler {
public:
  void on_frame(link_addr, const uint8_t* data, size_t size) override {
    std::unique_lock<std::mutex> guard{mtx_};
    payloads_.emplace_back(data, data + size);
    held_ = true;
    cv_.notify_all();
    cv_.wait_for(guard, wait_limit, [&] { return open_; });
  }

  void on_malformed(link_addr, const char*) override {
  }

  void on_kernel_drops(uint64_t count) override {
    std::lock_guard<std::mutex> guard{mtx_};
    drops_ += count;
  }

  void on_event(link_event_kind, link_addr, std::string) override {
  }

  void on_failure(caf::error) override {
  }

  /// Waits until the receive thread is held in on_frame.
  bool wait_held() {
    std::unique_lock<std::mutex> guard{mtx_};
    return cv_.wait_for(guard, wait_limit, [&] { return held_; });
  }

  void open() {
    std::lock_guard<std::mutex> guard{mtx_};
    open_ = true;
    cv_.notify_all();
  }

  /// Waits (at most `limit`) until a frame with these bytes arrived.
  bool wait_for(const byte_buffer& payload, std::chrono::milliseconds limit) {
    std::unique_lock<std::mutex> guard{mtx_};
    return cv_.wait_for(guard, limit, [&] {
      return std::find(payloads_.begin(), payloads_.end(), payload)
             != payloads_.end();
    });
  }

  size_t frames() {
    std::lock_guard<std::mutex> guard{mtx_};
    return payloads_.size();
  }

  uint64_t drops() {
    std::lock_guard<std::mutex> guard{mtx_};
    return drops_;
  }

private:
  std::mutex mtx_;
  std::condition_variable cv_;
  std::vector<byte_buffer> payloads_;
  uint64_t drops_ = 0;
  bool held_ = false;
  bool open_ = false;
};

TEST(udp_driver, counts_datagrams_the_kernel_dropped_for_a_full_receive_buffer) {
  station a;
  ASSERT_EQ(start_station(a, udp_config("a", "127.0.0.1:0")), "");
  auto drv = open_udp(udp_config("b", "127.0.0.1:0", {{"rcvbuf", "1024"}}));
  ASSERT_TRUE(drv) << render(drv.error());
  auto handler = std::make_shared<gated_handler>();
  ASSERT_FALSE((*drv)->start(handler));
  auto to = (*drv)->local_addr();
  size_t sent = 0;
  auto send = [&](const byte_buffer& x) {
    ASSERT_EQ(render(send_bytes(*a.drv, to, x)), "none");
    ++sent;
  };
  send(pattern(200, 1));
  ASSERT_TRUE(handler->wait_held());
  // The buffer (the kernel's minimum, a few datagrams) overflows.
  for (int i = 0; i < 200; ++i)
    send(pattern(200, 2));
  handler->open();
  // A later datagram carries the drop count; markers until one arrives
  // (one sent while the buffer is still full may be dropped itself).
  bool marked = false;
  for (uint8_t k = 0; k < 50 && !marked; ++k) {
    auto marker = bytes_of("marker");
    marker.push_back(k);
    send(marker);
    marked = handler->wait_for(marker, 200ms);
  }
  ASSERT_TRUE(marked);
  (*drv)->stop();
  EXPECT_GT(handler->drops(), 0u);
  EXPECT_EQ(handler->frames() + handler->drops(), sent);
  auto param = (*drv)->get_param("rx_kernel_dropped");
  ASSERT_TRUE(param);
  EXPECT_EQ(*param, std::to_string(handler->drops()));
}

TEST(udp_driver_processes, a_driver_in_a_child_process_echoes_every_frame) {
  agent child;
  ASSERT_EQ(child.spawn("", udp_config("echo0", "127.0.0.1:0"), true),
            "");
  auto child_text = child.wait_ready();
  ASSERT_TRUE(child_text) << "the child did not report ready";
  auto child_addr = udp::parse_addr(*child_text, false);
  ASSERT_TRUE(child_addr) << *child_text;
  station me;
  ASSERT_EQ(start_station(me, udp_config("me", "127.0.0.1:0")), "");
  std::vector<byte_buffer> sent;
  for (size_t i = 0; i < 20; ++i) {
    sent.push_back(pattern(1 + i * 73, static_cast<uint8_t>(i)));
    ASSERT_EQ(render(send_bytes(*me.drv, *child_addr, sent.back())), "none");
  }
  EXPECT_TRUE(me.rec->wait_frames(sent.size()));
  auto echoes = me.rec->frames();
  ASSERT_EQ(echoes.size(), sent.size());
  for (size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(echoes[i].src, *child_addr) << i;
    EXPECT_EQ(echoes[i].bytes, sent[i]) << i;
  }
  // The child saw our address as the source of every frame.
  auto my_text = me.drv->format_addr(me.drv->local_addr());
  child.pump_until([&] { return child.frames().size() >= sent.size(); },
                   wait_limit);
  auto at_child = child.frames();
  ASSERT_EQ(at_child.size(), sent.size());
  for (auto& [src, bytes] : at_child)
    EXPECT_EQ(src, my_text);
  EXPECT_EQ(child.quit(), 0) << "the child did not exit cleanly";
  EXPECT_TRUE(child.problems().empty()) << child.problems().front();
}

// -- a real Ethernet segment -----------------------------------------------------

TEST(udp_driver_segment, broadcasts_reach_the_other_stations_and_unicasts_cross_the_bridge) {
  auto* no_netns = std::getenv("HERM_NO_NETNS");
  if (no_netns != nullptr && std::string{no_netns} != ""
      && std::string{no_netns} != "0")
    GTEST_SKIP() << "HERM_NO_NETNS is set: skipping the network namespace "
                    "test on request";
  if (::geteuid() != 0)
    GTEST_SKIP() << "needs root to create network namespaces (running as uid "
                 << ::geteuid() << ")";
  netns_segment segment; // declared first: destroyed after the agents
  std::string why;
  auto built = segment.create(why);
  if (built == netns_segment::outcome::skip)
    GTEST_SKIP() << why;
  ASSERT_EQ(built, netns_segment::outcome::ok) << why;
  constexpr const char* port = "47000";
  auto bcast = segment.broadcast_ip() + ":" + port;
  agent stations[3];
  std::string addr[3];
  for (size_t i = 0; i < 3; ++i) {
    option_map options{{"broadcast", bcast}};
    if (i == 1)
      options["bind_device"] = "eth0";
    auto cfg = udp_config(std::string{"eth-"} + netns_segment::stations[i],
                          std::string{"0.0.0.0:"} + port, options);
    ASSERT_EQ(stations[i].spawn(segment.ns(netns_segment::stations[i]), cfg,
                                false),
              "");
    addr[i] = segment.ip(i) + ":" + port;
  }
  for (auto& st : stations)
    ASSERT_TRUE(st.wait_ready()) << (st.problems().empty()
                                       ? "no ready message"
                                       : st.problems().front());
  auto& a = stations[0];
  auto& b = stations[1];
  auto& c = stations[2];
  // Broadcast from a until b and c heard it (a fresh link may drop the first
  // frames while the bridge ports come up).
  auto hello = bytes_of("hello from a");
  auto heard_hello = [&] {
    return b.heard(addr[0], hello) && c.heard(addr[0], hello);
  };
  auto deadline = clock_type::now() + 2 * wait_limit;
  while (!heard_hello() && clock_type::now() < deadline) {
    ASSERT_EQ(a.send("*", hello), "sent ok");
    b.pump_until([&] { return b.heard(addr[0], hello); }, 200ms);
    c.pump_until([&] { return c.heard(addr[0], hello); }, 200ms);
  }
  EXPECT_TRUE(b.heard(addr[0], hello)) << "b did not hear a's broadcast";
  EXPECT_TRUE(c.heard(addr[0], hello)) << "c did not hear a's broadcast";
  // Unicast b -> a. The kernel loops a's broadcasts back to a's socket
  // before they leave; by the time b's reply arrives they would be there.
  auto marker = bytes_of("marker from b");
  deadline = clock_type::now() + 2 * wait_limit;
  while (!a.heard(addr[1], marker) && clock_type::now() < deadline) {
    ASSERT_EQ(b.send(addr[0], marker), "sent ok");
    a.pump_until([&] { return a.heard(addr[1], marker); }, 200ms);
  }
  ASSERT_TRUE(a.heard(addr[1], marker)) << "a did not hear b's unicast";
  for (auto& [src, bytes] : a.frames()) {
    EXPECT_NE(src, addr[0]) << "a heard its own frame";
    EXPECT_NE(bytes, hello) << "a heard its own broadcast from " << src;
  }
  // Unicast a -> c and back across the bridge; b must hear neither.
  auto direct = bytes_of("unicast a to c");
  auto reply = bytes_of("unicast c to a");
  deadline = clock_type::now() + 2 * wait_limit;
  while (!c.heard(addr[0], direct) && clock_type::now() < deadline) {
    ASSERT_EQ(a.send(addr[2], direct), "sent ok");
    c.pump_until([&] { return c.heard(addr[0], direct); }, 200ms);
  }
  EXPECT_TRUE(c.heard(addr[0], direct)) << "c did not hear a's unicast";
  deadline = clock_type::now() + 2 * wait_limit;
  while (!a.heard(addr[2], reply) && clock_type::now() < deadline) {
    ASSERT_EQ(c.send(addr[0], reply), "sent ok");
    a.pump_until([&] { return a.heard(addr[2], reply); }, 200ms);
  }
  EXPECT_TRUE(a.heard(addr[2], reply)) << "a did not hear c's unicast";
  b.pump_until([] { return false; }, 100ms); // collect what b got so far
  EXPECT_FALSE(b.heard(addr[0], direct)) << "b heard a unicast meant for c";
  EXPECT_FALSE(b.heard(addr[2], reply)) << "b heard a unicast meant for a";
  for (auto& st : stations) {
    EXPECT_EQ(st.quit(), 0) << "a station did not exit cleanly";
    EXPECT_TRUE(st.problems().empty()) << st.problems().front();
  }
}

} // namespace
} // namespace herm
