// The gateway with a real DDS peer: a C program with nothing of HERM in it
// (dds_peer.c) on its own DDS domain, restricted to loopback, and HERM
// modules as separate processes over UDP on loopback:
//
//   herm_sonar_node (0x63) -- hermd "relay" (0x62) -- hermd "robot" (0x61,
//   gateway APO)  ~~DDS domain D~~  dds_peer
//
// The peer receives as sensor_msgs::msg::dds_::Range_ on rt/sonar the
// readings the node publishes two hops away; the node receives the
// geometry_msgs::msg::dds_::Twist_ the peer publishes on rt/cmd_vel; Range
// samples with a NaN range on rt/sonar_in are dropped and counted by the
// gateway, never forwarded. The peer calls the node's APO as a ROS 2
// service, and the node calls the peer's service through the gateway's
// proxy APO, with HERM's typed errors for a silent and a missing server. Every wait is bounded; nothing asserts on
// timing.

#include <gtest/gtest.h>

#include <stdlib.h>
#include <unistd.h>

#include <fstream>
#include <sstream>

#include "channels/testing/loopback.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

namespace {

std::string lo(uint16_t port) {
  return "127.0.0.1:" + std::to_string(port);
}

/// Cyclone on loopback only, unicast discovery: the test's DDS traffic
/// stays on this machine and on its own domain.
const char* loopback_only
  = "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name=\"lo\"/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<Peers><Peer address=\"127.0.0.1\"/></Peers><ParticipantIndex>auto"
    "</ParticipantIndex><MaxAutoParticipantIndex>60</MaxAutoParticipantIndex>"
    "</Discovery></Domain></CycloneDDS>";

class gateway_process_test : public ::testing::Test {
protected:
  void SetUp() override {
    ::setenv("CYCLONEDDS_URI", loopback_only, 1);
    // A domain of its own per run (0..232), so that runs side by side do
    // not see each other.
    domain_ = 1 + static_cast<int>(::getpid() % 200);
  }

  std::string write(const std::string& name, const std::string& text) {
    auto path = dir_.path() + "/" + name;
    std::ofstream{path} << text;
    return path;
  }

  std::string module(const std::string& name, const std::string& id,
                     uint16_t port, const std::string& peers,
                     const std::string& extra = "") {
    return write(name + ".yaml",
                 "module:\n  name: " + name + "\n  id: " + id
                   + "\n  hello_interval_ms: 100\ncontrol:\n  socket: "
                   + dir_.path() + "/" + name
                   + ".sock\nchannels:\n  - name: eth0\n    kind: udp\n"
                     "    interface: "
                   + lo(port) + "\n    peers: [" + peers + "]\n" + extra);
  }

  /// Waits for the node's stats line saying it sent `n` sonar readings or
  /// more to other modules; remembers the count in first_sent_.
  bool sent_at_least(child_process& node, long n,
                     std::chrono::milliseconds timeout) {
    auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      auto line = node.wait_for_line_containing("stats published", 5s);
      if (!line)
        continue;
      auto at = line->find(" sent ");
      auto sent = std::stol(line->substr(at + 6));
      if (sent >= n) {
        first_sent_ = sent;
        return true;
      }
    }
    return false;
  }

  temp_dir dir_{"herm-gateway"};
  long first_sent_ = 0;
  int domain_ = 0;
};

} // namespace

TEST_F(gateway_process_test,
       a_dds_peer_sees_sonar_two_hops_away_commands_the_robot_and_calls_services) {
  auto p_robot = free_udp_port();
  auto p_relay = free_udp_port();
  auto p_node = free_udp_port();
  auto robot_cfg = module(
    "robot", "0x61", p_robot, lo(p_relay),
    "log:\n  level: info\napos:\n  - name: gateway\n    kind: dds_gateway\n"
    "    options:\n      domain: "
      + std::to_string(domain_)
      + "\n      sonar.type: sensor_msgs/msg/Range\n"
        "      sonar.frame_id: sonar_front\n"
        "      sonar.field_of_view: 0.5\n"
        "      cmd_vel.type: geometry_msgs/msg/Twist\n"
        "      cmd_vel.direction: from_dds\n"
        "      sonar_in.type: sensor_msgs/msg/Range\n"
        "      sonar_in.direction: from_dds\n"
        // The node's APO adder as the DDS service add_two_ints; DDS
        // services as the APOs dds_adder, dds_silent and dds_nobody.
        "      add_two_ints.service: example_interfaces/srv/AddTwoInts\n"
        "      add_two_ints.apo: adder\n"
        "      dds_adder.service: example_interfaces/srv/AddTwoInts\n"
        "      dds_adder.role: client\n"
        "      dds_silent.service: example_interfaces/srv/AddTwoInts\n"
        "      dds_silent.role: client\n"
        "      dds_silent.timeout_ms: 1000\n"
        "      dds_nobody.service: example_interfaces/srv/AddTwoInts\n"
        "      dds_nobody.role: client\n");
  // The relay has a channel towards each side: a flood is relayed on the
  // channels it did not come in on.
  auto p_relay2 = free_udp_port();
  auto relay_cfg = module("relay", "0x62", p_relay, lo(p_robot),
                          "  - name: eth1\n    kind: udp\n    interface: "
                            + lo(p_relay2) + "\n    peers: [" + lo(p_node)
                            + "]\n");
  child_process robot{{HERMD_BIN, robot_cfg}};
  child_process relay{{HERMD_BIN, relay_cfg}};
  child_process node{{HERM_SONAR_NODE_BIN, std::to_string(p_node),
                      std::to_string(p_relay2), "60"}};
  ASSERT_TRUE(robot.wait_for_line_containing("module 'robot' running", 20s))
    << robot.output();
  ASSERT_TRUE(node.wait_for_line("started", 20s)) << node.output();
  // HERM topics are volatile: a twist published before the node's
  // subscription reached the robot is not kept (but the last). Start the
  // peer once the node sends sonar readings (the robot's subscription came
  // through), plus 20 more (two renewals of the node's own subscriptions,
  // one per second).
  ASSERT_TRUE(sent_at_least(node, 1, 30s)) << node.output();
  ASSERT_TRUE(sent_at_least(node, first_sent_ + 20, 30s)) << node.output();
  // 8 readings, 5 twists, 3 bad samples, 3 service calls; within 40 s.
  child_process peer{{DDS_PEER_BIN, std::to_string(domain_), "8", "5", "3",
                      "40000", "3"}};
  auto status = peer.wait(60s);
  auto out = peer.output();
  ASSERT_EQ(status, 0) << out << "\n--- robot:\n" << robot.output()
                       << "\n--- node:\n" << node.output();

  // Readings arrive in metres, with the mapping's frame and cone, as
  // ULTRASOUND (0); out of range (every fifth) as +Inf; XCDR1 LE.
  EXPECT_NE(out.find("encoding 00 01"), std::string::npos) << out;
  std::istringstream lines{out};
  int ranges = 0;
  int inf = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("range ", 0) != 0)
      continue;
    ++ranges;
    EXPECT_NE(line.find(" frame sonar_front radiation 0 fov 0.50"),
              std::string::npos)
      << line;
    auto metres = std::stod(line.substr(6));
    if (line.find("range inf") == 0) {
      ++inf;
      continue;
    }
    // 1000 + 10 seq mm, seq < 1000 within the test's minute.
    EXPECT_GE(metres, 1.0) << line;
    EXPECT_LT(metres, 11.0) << line;
  }
  EXPECT_GE(ranges, 8) << out;

  // The node two hops away gets every twist, in order (reliable).
  size_t prev = 0;
  for (int i = 0; i < 5; ++i) {
    char want[64];
    std::snprintf(want, sizeof want, "twist %.2f %.2f", 0.1 * i,
                  i == 0 ? 0.0 : -1.0 * i);
    EXPECT_TRUE(node.wait_for_line(want, 20s)) << want << "\n" << node.output();
    auto at = node.output().find(want);
    EXPECT_TRUE(at != std::string::npos && (i == 0 || at > prev))
      << want << " out of order\n" << node.output();
    prev = at;
  }
  // The bad samples were dropped and counted at the gateway...
  EXPECT_TRUE(robot.wait_for_line_containing(
    "rt/sonar_in -> 'sonar_in': dropped a sample (3 so far): "
    "herm.invalid_parameter",
    20s))
    << robot.output();
  // ... and nothing half-built reached HERM.
  EXPECT_EQ(node.output().find("sonar_in"), std::string::npos) << node.output();

  // The peer called the node's APO adder, two hops away, as the ROS 2
  // service add_two_ints, and got each reply with its own request header.
  for (auto want : {"sum 1 11\n", "sum 2 22\n", "sum 3 33\n"})
    EXPECT_NE(out.find(want), std::string::npos) << want << out;
  // The node called the peer's DDS service through the proxy APO
  // dds_adder; a server that never answers is HERM's timeout, a service
  // nobody serves HERM's not_found.
  EXPECT_TRUE(node.wait_for_line("call dds_adder 15", 20s)) << node.output();
  EXPECT_TRUE(node.wait_for_line(
    "call dds_silent error herm.timeout: DDS service 'dds_silent' did not "
    "answer in 1000 ms",
    20s))
    << node.output();
  EXPECT_TRUE(node.wait_for_line("call dds_nobody error herm.not_found: DDS "
                                 "service 'dds_nobody' (domain "
                                   + std::to_string(domain_) + "): no server",
                                 20s))
    << node.output();
}

TEST_F(gateway_process_test, hermd_check_names_file_line_and_option_of_a_bad_mapping) {
  auto cfg = module("robot", "0x61", free_udp_port(), lo(free_udp_port()),
                    "apos:\n  - name: gateway\n    kind: dds_gateway\n"
                    "    options:\n      sonar.type: sensor_msgs/msg/Range\n"
                    "      sonar.durability: forever\n");
  // hermd says it on stderr.
  child_process check{
    {"/bin/sh", "-c", std::string{HERMD_BIN} + " --check " + cfg + " 2>&1"}};
  EXPECT_EQ(check.wait(30s), 2) << check.output();
  // The entry is on line 13 of the file.
  EXPECT_NE(check.output().find(cfg + ":13: apos[0]: options.sonar.durability: "
                                      "expected volatile or transient_local, "
                                      "got 'forever'"),
            std::string::npos)
    << check.output();
  auto good = module("robot2", "0x61", free_udp_port(), lo(free_udp_port()),
                     "apos:\n  - name: gateway\n    kind: dds_gateway\n"
                     "    options:\n      sonar.type: sensor_msgs/msg/Range\n");
  child_process ok{{HERMD_BIN, "--check", good}};
  EXPECT_EQ(ok.wait(30s), 0) << ok.output();
}
