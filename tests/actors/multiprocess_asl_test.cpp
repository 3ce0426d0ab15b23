// Multi-process tests of the Application Support Layer: every module is a
// real process (apps/herm-apo-peer, or the calculator example) with its own
// actor system and all three layers, joined by UDP on loopback and by
// emulated media in temporary directories. Requests cross a router module
// and an 8-byte-MTU CAN bus, a proxy ends when its serving module is killed,
// and a topic reaches a late subscriber and survives the death of another.
// Every wait is bounded; nothing asserts on timing.

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <thread>

#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

namespace {

const std::string apo_peer = HERM_APO_PEER_BIN;
const std::string calculator = HERM_CALCULATOR_BIN;
const std::string hermd = HERMD_BIN;

/// A UDP port on loopback of its own per test process: 10 per process id,
/// handed out in order.
uint16_t next_port() {
  static uint16_t next = static_cast<uint16_t>(40000 + ::getpid() % 1000 * 10);
  return next++;
}

std::string addr(uint16_t port) {
  return "127.0.0.1:" + std::to_string(port);
}


/// The lines of `out` that start with `prefix`.
std::vector<std::string> lines_with(const std::string& out,
                                    const std::string& prefix) {
  std::vector<std::string> result;
  std::istringstream in{out};
  for (std::string line; std::getline(in, line);)
    if (line.rfind(prefix, 0) == 0)
      result.push_back(line);
  return result;
}

/// Reads `p`'s output until it printed `n` lines starting with `prefix`;
/// false on timeout.
bool wait_for_lines(child_process& p, const std::string& prefix, size_t n,
                    std::chrono::milliseconds timeout) {
  auto deadline = std::chrono::steady_clock::now() + timeout;
  while (lines_with(p.output(), prefix).size() < n) {
    if (std::chrono::steady_clock::now() >= deadline)
      return false;
    // Matches nothing: just reads for a while (returns at once at EOF).
    if (!p.wait_for_line("\x01", 100ms))
      std::this_thread::sleep_for(10ms);
  }
  return true;
}

/// The integers of "value N" lines, in order.
std::vector<int> values_of(const std::string& out) {
  std::vector<int> result;
  for (auto& line : lines_with(out, "value "))
    result.push_back(std::stoi(line.substr(6)));
  return result;
}

} // namespace

// A (0x31) --udp-- R (0x32, router, no APOs) --emu can2.0-- S (0x33, echo
// APO). Discovery floods through R; each 200-byte request and its reply are
// routed by R and cut into 8-byte CAN frames on the second hop.
TEST(multiprocess_asl, requests_cross_a_router_module_and_an_8_byte_mtu_link) {
  temp_dir can;
  ASSERT_FALSE(can.path().empty());
  auto pa = next_port();
  auto pr = next_port();
  auto can_bus = can.path() + ":can2.0:";
  child_process s{{apo_peer, "--id", "0x33", "--emu", can_bus + "2", "serve",
                   "--name", "echo"}};
  ASSERT_TRUE(s.wait_for_line("ready", 10s)) << s.output();
  child_process r{{apo_peer, "--id", "0x32", "--udp", addr(pr) + "=" + addr(pa),
                   "--emu", can_bus + "1", "route"}};
  ASSERT_TRUE(r.wait_for_line("ready", 10s)) << r.output();
  child_process a{{apo_peer, "--id", "0x31", "--udp", addr(pa) + "=" + addr(pr),
                   "--timeout", "30", "call", "--name", "echo", "--count", "20",
                   "--size", "200"}};
  EXPECT_EQ(a.wait(60s), 0) << a.output();
  EXPECT_EQ(lines_with(a.output(), "done").size(), 1u) << a.output();
  EXPECT_TRUE(a.output().find("done ok=20 failed=0") != std::string::npos)
    << a.output();
  for (int i = 0; i < 20; ++i)
    EXPECT_EQ(lines_with(a.output(), "reply " + std::to_string(i) + " ok").size(),
              1u)
      << a.output();
  s.terminate();
  EXPECT_EQ(s.wait(10s), 0) << s.output();
  EXPECT_EQ(lines_with(s.output(), "served 20").size(), 1u) << s.output();
  r.terminate();
  EXPECT_EQ(r.wait(10s), 0) << r.output();
}

// hermd's built-in `echo` APO answers whatever it is asked: here the text
// requests of herm-apo-peer (it used to answer a string with CAF's
// unexpected_message). herm-apo-peer expects its own `serve` APO, which
// answers "echo:" + text, so it counts the unchanged text as a bad reply of
// the request's size: exactly what an echo gives back.
TEST(multiprocess_asl, hermds_echo_apo_answers_a_string_request) {
  temp_dir dir;
  ASSERT_FALSE(dir.path().empty());
  auto ph = next_port();
  auto pa = next_port();
  auto cfg = dir.path() + "/echo.yaml";
  std::ofstream{cfg} << "module:\n  name: e\n  id: 0x36\n"
                        "  hello_interval_ms: 100\ncontrol:\n  socket: "
                     << dir.path() << "/e.sock\n"
                     << "channels:\n  - name: eth0\n    kind: udp\n"
                        "    interface: " << addr(ph) << "\n    peers: ["
                     << addr(pa) << "]\napos:\n  - name: echo\n"
                        "    kind: echo\n";
  child_process e{{hermd, cfg}};
  child_process a{{apo_peer, "--id", "0x37", "--udp", addr(pa) + "=" + addr(ph),
                   "--timeout", "30", "call", "--name", "echo", "--count", "5",
                   "--size", "40"}};
  a.wait(60s);
  for (int i = 0; i < 5; ++i)
    EXPECT_EQ(lines_with(a.output(), "reply " + std::to_string(i)
                                       + " bad size=40")
                .size(),
              1u)
      << a.output();
  EXPECT_EQ(lines_with(a.output(), "bad replies 5").size(), 1u) << a.output();
  EXPECT_EQ(e.output().find("unexpected"), std::string::npos) << e.output();
  e.terminate();
  EXPECT_EQ(e.wait(10s), 0) << e.output();
}

// A (0x34) --udp-- S (0x35). Once A's requests are answered it watches its
// proxy; S is killed (no goodbye on the wire): A's routes to S time out,
// and after the unreachable grace the proxy ends with routing_ec::no_route.
TEST(multiprocess_asl, a_proxy_ends_when_the_serving_module_is_killed) {
  auto pa = next_port();
  auto ps = next_port();
  std::optional<child_process> s;
  s.emplace(std::vector<std::string>{apo_peer, "--id", "0x35", "--udp",
                                     addr(ps) + "=" + addr(pa), "serve",
                                     "--name", "echo"});
  ASSERT_TRUE(s->wait_for_line("ready", 10s)) << s->output();
  child_process a{{apo_peer, "--id", "0x34", "--udp", addr(pa) + "=" + addr(ps),
                   "--timeout", "20", "call", "--name", "echo", "--count", "3",
                   "--watch"}};
  auto done = a.wait_for_line("done", 30s);
  ASSERT_TRUE(done) << a.output();
  EXPECT_EQ(*done, "done ok=3 failed=0") << a.output();
  s.reset(); // SIGKILL
  auto down = a.wait_for_line("down", 20s);
  ASSERT_TRUE(down) << a.output();
  EXPECT_NE(down->find("no_route"), std::string::npos) << *down;
  EXPECT_EQ(a.wait(10s), 0) << a.output();
}

// P (0x40, station 1), X (0x41, station 2) and Y (0x42, station 3) share one
// emulated Ethernet bus (100 Mbit/s, MTU 1500). P publishes 1, 2, 3, ...
// every 200 ms. X subscribes at once; Y only after P published 5 values, so
// its first value is the publisher's last one (not 1), and then every value
// in order. X is killed while Y listens; Y keeps receiving without a gap.
TEST(multiprocess_asl, topics_reach_a_late_subscriber_and_survive_a_dying_one) {
  temp_dir eth;
  ASSERT_FALSE(eth.path().empty());
  auto bus = eth.path() + ":ethernet:";
  child_process p{{apo_peer, "--id", "0x40", "--emu", bus + "1", "publish",
                   "--topic", "odometry", "--period-ms", "200", "--count",
                   "150"}};
  ASSERT_TRUE(p.wait_for_line("ready", 10s)) << p.output();
  std::optional<child_process> x;
  x.emplace(std::vector<std::string>{apo_peer, "--id", "0x41", "--emu",
                                     bus + "2", "--timeout", "60", "subscribe",
                                     "--topic", "odometry", "--count", "1000"});
  ASSERT_TRUE(wait_for_lines(*x, "value ", 1, 15s)) << x->output();
  ASSERT_TRUE(wait_for_lines(p, "published ", 5, 15s)) << p.output();
  child_process y{{apo_peer, "--id", "0x42", "--emu", bus + "3", "--timeout",
                   "60", "subscribe", "--topic", "odometry", "--count", "15"}};
  ASSERT_TRUE(wait_for_lines(y, "value ", 3, 15s)) << y.output();
  ASSERT_TRUE(wait_for_lines(*x, "value ", 3, 15s)) << x->output();
  auto x_values = values_of(x->output());
  x.reset(); // SIGKILL, midway through the stream
  auto before = values_of(y.output()).size();
  EXPECT_EQ(y.wait(30s), 0) << y.output();
  auto ys = values_of(y.output());
  ASSERT_EQ(ys.size(), 15u) << y.output();
  EXPECT_GE(ys.size() - before, 5u) << "values after X died\n" << y.output();
  EXPECT_NE(ys.front(), 1) << "the late joiner got the first value\n"
                           << y.output();
  for (size_t i = 1; i < ys.size(); ++i)
    EXPECT_EQ(ys[i], ys[i - 1] + 1) << "value " << i << "\n" << y.output();
  for (size_t i = 1; i < x_values.size(); ++i)
    EXPECT_EQ(x_values[i], x_values[i - 1] + 1) << "X's value " << i;
  p.terminate();
  EXPECT_EQ(p.wait(10s), 0) << p.output();
}

// The user example (apps/examples/remote_calculator) as a user runs it.
TEST(multiprocess_asl, the_calculator_example_runs) {
  auto ps = next_port();
  auto pc = next_port();
  // No control sockets: tests running at once must not share the default
  // ones (hermctl_topics_test covers them).
  child_process serve{{calculator, "--control", "-", "serve", "--port",
                       std::to_string(ps), "--peer", addr(pc), "--seconds",
                       "60"}};
  ASSERT_TRUE(serve.wait_for_line("registered", 10s)) << serve.output();
  child_process call{{calculator, "--control", "-", "call", "--port",
                      std::to_string(pc), "--peer", addr(ps)}};
  EXPECT_EQ(call.wait(30s), 0) << call.output();
  EXPECT_EQ(lines_with(call.output(), "result ").size(), 4u) << call.output();
  EXPECT_EQ(lines_with(call.output(), "result 40 + 2 = 42").size(), 1u)
    << call.output();
  EXPECT_EQ(lines_with(call.output(), "refused 7 / 0").size(), 1u)
    << call.output();
  // The results, published by the APO on its module, reached the
  // subscriber on the calling module.
  EXPECT_GE(lines_with(call.output(), "published by 0x20: ").size(), 1u) << call.output();
  serve.terminate();
  EXPECT_EQ(serve.wait(10s), 0) << serve.output();
}

// The same example, with the calling module started from a configuration
// file (herm::load_config, the file format hermd reads).
TEST(multiprocess_asl, the_calculator_example_starts_from_a_config_file) {
  temp_dir dir{"herm-calc"};
  ASSERT_FALSE(dir.path().empty());
  auto ps = next_port();
  auto pc = next_port();
  auto cfg = dir.path() + "/caller.yaml";
  {
    std::ofstream f{cfg};
    f << "module:\n  name: caller\n  id: 0x21\n  hello_interval_ms: 100\n"
         "control:\n  socket: off\n"
         "channels:\n  - name: eth0\n    kind: udp\n    interface: "
      << addr(pc) << "\n    peers: " << addr(ps) << "\n";
  }
  child_process serve{{calculator, "--control", "-", "serve", "--port",
                       std::to_string(ps), "--peer", addr(pc), "--seconds",
                       "60"}};
  ASSERT_TRUE(serve.wait_for_line("registered", 10s)) << serve.output();
  child_process call{{calculator, "call", "--config", cfg}};
  EXPECT_EQ(call.wait(30s), 0) << call.output();
  EXPECT_EQ(lines_with(call.output(), "result 40 + 2 = 42").size(), 1u)
    << call.output();
  // A broken file is refused with its line and field.
  {
    std::ofstream f{cfg};
    f << "module:\n  name: caller\n  id: 0x21\nchannels:\n  - name: eth0\n"
         "    kind: udpp\n    interface: x\n";
  }
  child_process bad{{calculator, "call", "--config", cfg}};
  EXPECT_EQ(bad.wait(30s), 1) << bad.output();
  EXPECT_NE(bad.output().find(cfg + ":6: channels[0].kind"), std::string::npos)
    << bad.output();
  serve.terminate();
  EXPECT_EQ(serve.wait(10s), 0) << serve.output();
}
