// hermctl against real hermd processes, without telling it a socket: it
// finds the modules in the runtime directory (one is used and named, several
// need --name unless one is "hermd", a stale socket is ignored), lists them,
// and `watch` draws plain frames with link rates and a link taken down.
// Every wait is bounded; nothing asserts on timing.

#include <gtest/gtest.h>

#include <stdlib.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "channels/testing/loopback.hpp"
#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string hermd = HERMD_BIN;
const std::string hermctl = HERMCTL_BIN;

std::string lo(uint16_t port) {
  return "127.0.0.1:" + std::to_string(port);
}

class hermctl_live_test : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-live-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
    runtime_ = dir_ + "/herm";
    fs::create_directory(runtime_);
  }

  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::string sock(const std::string& name) const {
    return runtime_ + "/" + name + ".sock";
  }

  /// A module whose control socket is NAME.sock in the runtime directory,
  /// with one UDP channel per (device, local port, peer port).
  std::string module(const std::string& name, const std::string& id,
                     const std::vector<std::tuple<std::string, uint16_t, uint16_t>>& links) {
    std::string text = "module:\n  name: " + name + "\n  id: " + id
                       + "\n  hello_interval_ms: 100\ncontrol:\n  socket: "
                       + sock(name) + "\n  allow_unsigned_remote: true\nchannels:\n";
    for (auto& [device, port, peer] : links)
      text += "  - name: " + device + "\n    kind: udp\n    interface: " + lo(port)
              + "\n    peers: " + lo(peer) + "\n";
    auto path = dir_ + "/" + name + ".yaml";
    std::ofstream{path} << text;
    return path;
  }

  /// Waits until hermd says it runs (its socket is then listening).
  static void started(child_process& p, const std::string& id) {
    ASSERT_TRUE(p.wait_for_line_containing("running as " + id, 10s)) << p.output();
  }

  /// A socket file nobody listens at: what a module that died leaves.
  void stale(const std::string& name) {
    int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    auto path = sock(name);
    std::memcpy(addr.sun_path, path.data(), path.size());
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ::close(fd);
  }

  /// hermctl with ARGS and no socket named: the runtime directory is ours.
  std::string ctl(const std::string& args) const {
    return "env -u HERM_CONTROL HERM_RUNTIME_DIR=" + runtime_ + " " + hermctl + " "
           + args;
  }

  /// Waits (bounded) until module `from` reaches `mid`'s control service:
  /// a route and the discovery of its control APO.
  void reachable(const std::string& from, const std::string& mid) const {
    for (int i = 0; i < 40; ++i) {
      if (run(ctl("--name " + from + " --module " + mid + " info")).first == 0)
        return;
      std::this_thread::sleep_for(250ms);
    }
    FAIL() << from << " never reached " << mid;
  }

  /// Runs a command to its end; stdout and stderr together.
  static std::pair<int, std::string> run(const std::string& cmd) {
    child_process p{{"/bin/sh", "-c", cmd + " 2>&1"}};
    auto status = p.wait(30s);
    return {status, p.output()};
  }

  std::string dir_;
  std::string runtime_;
};

/// The lines of `text` starting with `prefix`.
std::vector<std::string> lines_starting(const std::string& text,
                                        const std::string& prefix) {
  std::vector<std::string> out;
  size_t pos = 0;
  while (pos < text.size()) {
    auto nl = text.find('\n', pos);
    auto line = text.substr(pos, nl == std::string::npos ? std::string::npos : nl - pos);
    if (line.rfind(prefix, 0) == 0)
      out.push_back(line);
    if (nl == std::string::npos)
      break;
    pos = nl + 1;
  }
  return out;
}

} // namespace

TEST_F(hermctl_live_test, the_one_live_module_is_used_and_named_and_a_stale_socket_ignored) {
  stale("old");
  child_process a{{hermd, module("a", "0x21", {{"eth0", free_udp_port(), free_udp_port()}})}};
  started(a, "0x21");
  auto [status, out] = run(ctl("info"));
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("hermctl: using module 'a' (" + sock("a") + ")\n"), std::string::npos)
    << out;
  EXPECT_NE(out.find("module    a (0x21)"), std::string::npos) << out;
  // Quiet with --json and --quiet.
  auto [js, jout] = run(ctl("info --json"));
  EXPECT_EQ(js, 0) << jout;
  EXPECT_EQ(jout.find("using module"), std::string::npos) << jout;
  auto [qs, qout] = run(ctl("--quiet info"));
  EXPECT_EQ(qs, 0) << qout;
  EXPECT_EQ(qout.find("using module"), std::string::npos) << qout;
  // The listing has the live module only.
  auto [ls, list] = run(ctl("modules"));
  EXPECT_EQ(ls, 0) << list;
  EXPECT_EQ(list, "NAME  MODULE  SOCKET\na     0x21    " + sock("a") + "\n");
  a.terminate();
  EXPECT_EQ(a.wait(10s), 0) << a.output();
  // Nothing live: the usual error for hermd's socket there, status 3.
  auto [ns, none] = run(ctl("info"));
  EXPECT_EQ(ns, 3) << none;
  EXPECT_EQ(none, "hermctl: no module listening at " + sock("hermd")
                    + " (is hermd running?)\n");
  auto [es, empty] = run(ctl("ls"));
  EXPECT_EQ(es, 0) << empty;
  EXPECT_EQ(empty, "no modules running (no live control socket in " + runtime_ + ")\n");
}

TEST_F(hermctl_live_test, several_modules_need_a_name_unless_one_is_hermd) {
  auto pa = free_udp_port(), pb = free_udp_port();
  child_process a{{hermd, module("a", "0x21", {{"eth0", pa, pb}})}};
  child_process b{{hermd, module("b", "0x22", {{"eth0", pb, pa}})}};
  started(a, "0x21");
  started(b, "0x22");
  auto [status, out] = run(ctl("info"));
  EXPECT_EQ(status, 2) << out;
  EXPECT_EQ(out, "hermctl: 2 modules run here (a, b; in " + runtime_
                   + "): choose one with --name NAME or -s PATH (hermctl "
                     "modules lists them)\n");
  auto [ns, named] = run(ctl("--name b info"));
  EXPECT_EQ(ns, 0) << named;
  EXPECT_EQ(named.find("using module"), std::string::npos) << named;
  EXPECT_NE(named.find("module    b (0x22)"), std::string::npos) << named;
  auto [ls, list] = run(ctl("modules"));
  EXPECT_EQ(ls, 0) << list;
  EXPECT_EQ(list, "NAME  MODULE  SOCKET\n"
                  "a     0x21    " + sock("a") + "\n"
                  "b     0x22    " + sock("b") + "\n");
  auto [js, json_list] = run(ctl("modules --json"));
  EXPECT_EQ(js, 0) << json_list;
  EXPECT_NE(json_list.find("\"module\": \"0x22\""), std::string::npos) << json_list;
  // A third module named hermd is the one taken.
  child_process h{{hermd, module("hermd", "0x23", {{"eth0", free_udp_port(),
                                                   free_udp_port()}})}};
  started(h, "0x23");
  auto [hs, hout] = run(ctl("info"));
  EXPECT_EQ(hs, 0) << hout;
  EXPECT_NE(hout.find("hermctl: using module 'hermd' (" + sock("hermd") + ")"),
            std::string::npos)
    << hout;
  EXPECT_NE(hout.find("module    hermd (0x23)"), std::string::npos) << hout;
  // --module reaches another module through the one found.
  reachable("a", "0x22");
  auto [rs, remote] = run(ctl("--name a --module 0x22 info"));
  EXPECT_EQ(rs, 0) << remote;
  EXPECT_NE(remote.find("module    b (0x22)"), std::string::npos) << remote;
}

// a and b are joined twice (eth0 and eth1). watch draws two plain frames;
// between them eth1 is taken down: the second frame has eth0's rates and
// eth1 down.
TEST_F(hermctl_live_test, watch_draws_plain_frames_with_rates_and_a_link_taken_down) {
  auto pa0 = free_udp_port(), pb0 = free_udp_port();
  auto pa1 = free_udp_port(), pb1 = free_udp_port();
  child_process a{{hermd, module("a", "0x21", {{"eth0", pa0, pb0}, {"eth1", pa1, pb1}})}};
  child_process b{{hermd, module("b", "0x22", {{"eth0", pb0, pa0}, {"eth1", pb1, pa1}})}};
  reachable("a", "0x22");
  // b publishes a topic nobody on a subscribes to: a's dashboard shows it
  // (every module's topics) with the rate b publishes it at.
  child_process pub{{"/bin/sh", "-c",
                     "exec " + ctl("--name b topic pub live.ticks 1 --rate 10")
                       + " > /dev/null 2>&1"}};
  child_process w{{"/bin/sh", "-c", ctl("--name a watch --count 2 --interval 2") + " 2>&1"}};
  // A frame is one write: complete once its last section shows.
  ASSERT_TRUE(w.wait_for_line_containing("route changes", 15s)) << w.output();
  ASSERT_TRUE(w.wait_for_line_containing("topics", 5s)) << w.output();
  auto [ds, down] = run(ctl("--name a link eth1 down"));
  ASSERT_EQ(ds, 0) << down;
  ASSERT_EQ(w.wait(30s), 0) << w.output();
  auto out = w.output();
  EXPECT_EQ(out.find('\x1b'), std::string::npos) << "no escape codes off a terminal";
  EXPECT_EQ(out.rfind("a (0x21)  frame 1, every 2s", 0), 0u) << out;
  auto second = out.find("a (0x21)  frame 2, every 2s");
  ASSERT_NE(second, std::string::npos) << out;
  auto first = out.substr(0, second);
  auto last = out.substr(second);
  // Frame 1: both links up, module b by name, no rates yet.
  EXPECT_EQ(lines_starting(first, "0x22    b ").size(), 1u) << first;
  auto eth0_first = lines_starting(first, "eth0 ");
  ASSERT_EQ(eth0_first.size(), 1u) << first;
  EXPECT_NE(eth0_first[0].find(" up "), std::string::npos) << eth0_first[0];
  EXPECT_EQ(eth0_first[0].find("B/s"), std::string::npos) << eth0_first[0];
  EXPECT_EQ(lines_starting(first, "eth1 ").size(), 1u) << first;
  // Frame 2: eth0 with byte rates (hellos every 100 ms), eth1 down.
  auto eth0 = lines_starting(last, "eth0 ");
  ASSERT_EQ(eth0.size(), 1u) << last;
  EXPECT_NE(eth0[0].find(" up "), std::string::npos) << eth0[0];
  EXPECT_NE(eth0[0].find(" B/s"), std::string::npos) << eth0[0];
  auto eth1 = lines_starting(last, "eth1 ");
  ASSERT_EQ(eth1.size(), 1u) << last;
  EXPECT_NE(eth1[0].find(" down "), std::string::npos) << eth1[0];
  // The topics section: both modules answered; b's topic with a rate.
  EXPECT_NE(last.find("\ntopics (1, from 2 modules)\n"), std::string::npos) << last;
  auto ticks = lines_starting(last, "live.ticks ");
  ASSERT_EQ(ticks.size(), 1u) << last;
  std::istringstream row{ticks[0]};
  std::string topic, type, rate, publishers, subscribers;
  row >> topic >> type >> rate >> publishers >> subscribers;
  EXPECT_EQ(type, "@i64") << ticks[0];
  EXPECT_GT(std::atof(rate.c_str()), 0.0) << ticks[0];
  EXPECT_EQ(publishers, "0x22") << ticks[0];
  EXPECT_EQ(subscribers, "-") << ticks[0];
}
