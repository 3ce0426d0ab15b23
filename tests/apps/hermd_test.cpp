// hermd as an integrator runs it: --check, start-up errors that name file,
// line and field, a clean stop that tells the neighbours at once, and reload
// by SIGHUP and by hermctl. Every module is a real hermd process on UDP
// loopback; every wait is bounded; nothing asserts on timing.

#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <netinet/in.h>
#include <arpa/inet.h>
#include <unistd.h>

#include <algorithm>
#include <sstream>

#include <nlohmann/json.hpp>
#include <filesystem>
#include <fstream>
#include <thread>

#include "channels/testing/loopback.hpp"
#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string hermd = HERMD_BIN;
const std::string hermctl = HERMCTL_BIN;

/// JSON without white space, for plain substring checks.
std::string squeeze(std::string s) {
  s.erase(std::remove_if(s.begin(), s.end(),
                         [](char c) { return c == ' ' || c == '\n'; }),
          s.end());
  return s;
}

std::string lo(uint16_t port) {
  return "127.0.0.1:" + std::to_string(port);
}

class hermd_test : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-hermd-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
  }

  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::string write(const std::string& name, const std::string& text) {
    auto path = dir_ + "/" + name;
    std::ofstream{path} << text;
    return path;
  }

  std::string sock(const std::string& name) const {
    return dir_ + "/" + name + ".sock";
  }

  /// A module with one UDP channel to `peer`.
  std::string module(const std::string& name, const std::string& id,
                     uint16_t port, uint16_t peer,
                     const std::string& extra = "") {
    return write(name + ".yaml", "module:\n  name: " + name + "\n  id: " + id
                                   + "\n  hello_interval_ms: 100\n"
                                     "control:\n  socket: "
                                   + sock(name)
                                   + "\nchannels:\n  - name: eth0\n    kind: udp\n"
                                     "    interface: "
                                   + lo(port) + "\n    peers: " + lo(peer) + "\n"
                                   + extra);
  }

  /// Runs a command to its end; stdout and stderr together.
  static std::pair<int, std::string> run(const std::string& cmd) {
    child_process p{{"/bin/sh", "-c", cmd + " 2>&1"}};
    auto status = p.wait(30s);
    return {status, p.output()};
  }

  std::string dir_;
};

} // namespace

TEST_F(hermd_test, check_accepts_a_valid_config_and_says_what_it_holds) {
  auto cfg = module("a", "0x21", free_udp_port(), free_udp_port(),
                    "apos:\n  - name: echo\n    kind: echo\n");
  auto [status, out] = run(hermd + " --check " + cfg);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("valid: module 'a' (0x21), 1 channels, 1 APOs"),
            std::string::npos)
    << out;
}

TEST_F(hermd_test, check_refuses_a_bad_field_naming_file_line_and_field) {
  auto cfg = write("bad.yaml", "module:\n  name: a\n  id: 0x21\n"
                               "channels:\n  - name: eth0\n    kind: udp\n"
                               "    interface: 127.0.0.1:0\n    mtu: big\n");
  auto [status, out] = run(hermd + " --check " + cfg);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find(cfg + ":8: channels[0].mtu"), std::string::npos) << out;
}

TEST_F(hermd_test, check_refuses_an_unknown_apo_kind_and_lists_the_known_ones) {
  auto cfg = module("a", "0x21", free_udp_port(), free_udp_port(),
                    "apos:\n  - name: x\n    kind: teleporter\n");
  auto [status, out] = run(hermd + " --check " + cfg);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find(":13: apos[0].kind: unknown APO kind 'teleporter' (known: "
                     "collector"),
            std::string::npos)
    << out;
}

TEST_F(hermd_test, check_refuses_a_bad_apo_option) {
  auto cfg = module("a", "0x21", free_udp_port(), free_udp_port(),
                    "apos:\n  - name: cam\n    kind: vision_source\n"
                    "    options:\n      period_ms: soon\n");
  auto [status, out] = run(hermd + " --check " + cfg);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("option 'period_ms' expects an integer"), std::string::npos)
    << out;
}

TEST_F(hermd_test, a_device_that_cannot_open_stops_start_up_and_names_its_line) {
  auto cfg = write("rs.yaml", "module:\n  name: a\n  id: 0x21\n"
                              "control:\n  socket: off\n"
                              "channels:\n  - name: rs0\n    kind: serial\n"
                              "    interface: /dev/herm-no-such-tty\n");
  auto [status, out] = run(hermd + " " + cfg);
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find(cfg + ":7: channels[0] 'rs0': "), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(sock("a")));
}

// Two modules; b stops with SIGTERM: a drops b's route on b's goodbye and
// counts it (without the goodbye, it would drop it only after hellos stop).
TEST_F(hermd_test, sigterm_says_goodbye_and_neighbours_withdraw_at_once) {
  auto pa = free_udp_port(), pb = free_udp_port();
  child_process a{{hermd, module("a", "0x21", pa, pb)}};
  child_process b{{hermd, module("b", "0x22", pb, pa)}};
  auto learned = a.wait_for_line_containing("route to 0x22:", 10s);
  ASSERT_TRUE(learned) << a.output();
  b.signal(SIGTERM);
  EXPECT_EQ(b.wait(10s), 0) << b.output();
  EXPECT_TRUE(b.output().find("leaving the network") != std::string::npos)
    << b.output();
  auto gone = a.wait_for_line_containing("route to 0x22 withdrawn", 10s);
  ASSERT_TRUE(gone) << a.output();
  auto [status, stats] = run(hermctl + " -s " + sock("a") + " stats --json");
  EXPECT_EQ(status, 0) << stats;
  EXPECT_NE(squeeze(stats).find("\"rx_goodbyes\":1"), std::string::npos) << stats;
}

// SIGHUP re-reads the file: a new channel opens, the old one stays up; a
// broken file is refused and the module keeps running as it was.
TEST_F(hermd_test, sighup_reload_adds_channels_and_refuses_a_broken_file) {
  auto pa = free_udp_port(), pb = free_udp_port(), pc = free_udp_port();
  auto cfg = module("a", "0x21", pa, pb);
  child_process a{{hermd, cfg}};
  ASSERT_TRUE(a.wait_for_line_containing("running as 0x21", 10s)) << a.output();
  module("a", "0x21", pa, pb,
         "  - name: eth1\n    kind: udp\n    interface: " + lo(pc) + "\n");
  a.signal(SIGHUP);
  auto done = a.wait_for_line_containing("reloaded", 10s);
  ASSERT_TRUE(done) << a.output();
  EXPECT_NE(done->find("1 added, 0 removed, 0 changed, 0 failed"),
            std::string::npos)
    << *done;
  auto [status, channels] = run(hermctl + " -s " + sock("a") + " channels --json");
  EXPECT_EQ(status, 0) << channels;
  EXPECT_NE(channels.find("eth0"), std::string::npos) << channels;
  EXPECT_NE(channels.find("eth1"), std::string::npos) << channels;
  write("a.yaml", "module: [\n");
  a.signal(SIGHUP);
  auto refused = a.wait_for_line_containing("reload refused", 10s);
  ASSERT_TRUE(refused) << a.output();
  EXPECT_NE(refused->find("a.yaml:"), std::string::npos) << *refused;
  auto [status2, again] = run(hermctl + " -s " + sock("a") + " channels --json");
  EXPECT_EQ(status2, 0) << again;
  EXPECT_NE(again.find("eth1"), std::string::npos) << again;
  a.signal(SIGTERM);
  EXPECT_EQ(a.wait(10s), 0) << a.output();
}

// hermctl reload does the same as SIGHUP and answers with what changed; a
// removed channel closes.
TEST_F(hermd_test, hermctl_reload_removes_a_channel_and_reports_it) {
  auto pa = free_udp_port(), pb = free_udp_port(), pc = free_udp_port();
  auto cfg = module("a", "0x21", pa, pb,
                    "  - name: eth1\n    kind: udp\n    interface: " + lo(pc) + "\n");
  child_process a{{hermd, cfg}};
  ASSERT_TRUE(a.wait_for_line_containing("running as 0x21", 10s)) << a.output();
  module("a", "0x21", pa, pb);
  auto [status, out] = run(hermctl + " -s " + sock("a") + " reload --json");
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(squeeze(out).find("\"removed\":[\"eth1\"]"), std::string::npos) << out;
  auto [status2, channels] = run(hermctl + " -s " + sock("a") + " channels --json");
  EXPECT_EQ(channels.find("eth1"), std::string::npos) << channels;
  EXPECT_NE(channels.find("eth0"), std::string::npos) << channels;
}

// The example configurations installed with hermd stay valid.
TEST_F(hermd_test, the_shipped_example_configs_are_valid) {
  size_t n = 0;
  for (auto& entry : fs::directory_iterator{HERMD_EXAMPLES_DIR}) {
    if (entry.path().extension() != ".yaml")
      continue;
    ++n;
    auto [status, out] = run(hermd + " --check " + entry.path().string());
    EXPECT_EQ(status, 0) << out;
  }
  EXPECT_EQ(n, 4u);
}

// A channel that fails to open on reload is not taken as running: once its
// device works, reloading the same file opens it.
TEST_F(hermd_test, a_channel_that_failed_on_reload_is_retried_by_the_next) {
  auto pa = free_udp_port(), pb = free_udp_port();
  auto cfg = module("a", "0x21", pa, pb);
  child_process a{{hermd, cfg}};
  ASSERT_TRUE(a.wait_for_line_containing("running as 0x21", 10s)) << a.output();
  // A serial line whose device does not exist yet.
  auto tty = dir_ + "/tty";
  module("a", "0x21", pa, pb,
         "  - name: rs0\n    kind: serial\n    interface: " + tty + "\n");
  auto [s1, out1] = run(hermctl + " -s " + sock("a") + " reload --json");
  EXPECT_NE(squeeze(out1).find("\"failed\":[\"rs0:"), std::string::npos) << out1;
  // The device appears: a symlink to a pseudo-terminal.
  int master = ::posix_openpt(O_RDWR | O_NOCTTY);
  ASSERT_GE(master, 0);
  ASSERT_EQ(::grantpt(master), 0);
  ASSERT_EQ(::unlockpt(master), 0);
  fs::create_symlink(::ptsname(master), tty);
  auto [s2, out2] = run(hermctl + " -s " + sock("a") + " reload --json");
  EXPECT_NE(squeeze(out2).find("\"added\":[\"rs0\"]"), std::string::npos) << out2;
  ::close(master);
}

// log.format json: one JSON object per line, the message escaped.
TEST_F(hermd_test, json_logs_are_one_valid_object_per_line) {
  auto cfg = module("a", "0x21", free_udp_port(), free_udp_port(),
                    "log:\n  format: json\napos:\n  - name: 'say \"hi\"'\n"
                    "    kind: echo\n");
  child_process a{{hermd, cfg}};
  ASSERT_TRUE(a.wait_for_line_containing("running as 0x21", 10s)) << a.output();
  a.signal(SIGTERM);
  EXPECT_EQ(a.wait(10s), 0) << a.output();
  std::istringstream in{a.output()};
  size_t lines = 0;
  bool quoted = false;
  for (std::string line; std::getline(in, line);) {
    ++lines;
    auto j = nlohmann::json::parse(line, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << line;
    EXPECT_EQ(j.value("module", ""), "a") << line;
    quoted = quoted || j.value("msg", "").find("say \"hi\"") != std::string::npos;
  }
  EXPECT_GE(lines, 3u);
  EXPECT_TRUE(quoted) << a.output();
}
