// The paper's testbed (herm-testbed) end to end: four hermd processes, the
// AVR board as a fifth module (its firmware in simavr, or herm-mcu-board
// where that was not built) and its reboot, the kill of the router module,
// the Ethernet link going down and up, a clean stop. The runner checks each event itself;
// this test names every event it must have seen, so that a runner that
// skipped one fails too.

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

namespace {

/// Runs herm-testbed with `args` and checks every event it must have seen,
/// `extra` too; returns its output.
std::string run_every_event(const std::vector<std::string>& args,
                            const std::vector<std::string>& extra = {}) {
  char tmpl[] = "/tmp/herm-testbed-test-XXXXXX";
  std::string dir = ::mkdtemp(tmpl);
  std::vector<std::string> argv{HERM_TESTBED_BIN, "--quiet", "--out", dir};
  argv.insert(argv.end(), args.begin(), args.end());
  child_process tb{argv};
  auto status = tb.wait(240s);
  EXPECT_TRUE(std::filesystem::exists(dir + "/topology.dot"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/main.yaml"));
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  auto out = tb.output();
  for (auto name :
       {"routes_converged", "avr_board_is_a_module", "topology_written",
        "avr_board_in_topology", "avr_board_apo_in_apps", "sonar_batch_received",
        "avr_readings_reach_collector", "first_sonar_batch_not_lost",
        "sonar_batch_fragmented_on_rs232c", "vision_routed_through_mobile",
        "vision_frame_received", "avr_board_reboots_as_a_new_instance",
        "routes_withdrawn", "vision_fails_without_mobile", "vision_resumes",
        "traffic_moves_to_can", "vision_over_can_received",
        "traffic_returns_to_ethernet", "clean_shutdown_withdraws_at_once"})
    EXPECT_NE(out.find(std::string{"EVENT ok "} + name + ":"), std::string::npos)
      << "event " << name << " not seen";
  for (auto& name : extra)
    EXPECT_NE(out.find("EVENT ok " + name + ":"), std::string::npos)
      << "event " << name << " not seen";
  EXPECT_EQ(out.find("EVENT FAILED"), std::string::npos);
  EXPECT_EQ(status, 0) << out;
  return out;
}

} // namespace

// The board as built here: the firmware in simavr when avr-gcc and
// libsimavr were found, else herm-mcu-board (the runner says which).
TEST(testbed, every_event_of_the_paper_scenario_happens) {
  auto out = run_every_event({});
  EXPECT_NE(out.find("AVR board 0xA04: "), std::string::npos) << out;
}

// The stand-in for machines without the AVR toolchain, asked for here so
// that it is tested where the firmware is built too.
TEST(testbed, the_host_build_of_the_client_stands_in_for_the_avr_board) {
  auto out = run_every_event({"--board", "host"});
  EXPECT_NE(out.find("AVR board 0xA04: herm-mcu-board"), std::string::npos) << out;
}

// --dds-gateway: the main controller's gateway writes the sensor's
// readings to DDS on rt/sonar and the vision frames on rt/vision, and a DDS
// reader with no HERM code in it
// (tests/gateway/dds_peer.c) reads them (docs/testbed.md, "The robot on
// DDS").
TEST(testbed, a_dds_reader_sees_the_sonar_readings_through_the_gateway) {
#ifndef HERM_TESTBED_DDS
  GTEST_SKIP() << "hermd was built without the DDS gateway (Cyclone DDS or idlc "
                  "not found at configure time)";
#else
  auto out = run_every_event({"--dds-gateway"},
                             {"dds_reader_sees_sonar", "dds_reader_sees_vision"});
  EXPECT_NE(out.find("sensor_msgs::msg::dds_::Range_ in XCDR1"), std::string::npos) << out;
  EXPECT_NE(out.find("on rt/vision as sensor_msgs::msg::dds_::Image_"), std::string::npos)
    << out;
#endif
}

// --dds-domain without --dds-gateway is a usage error.
TEST(testbed, a_dds_domain_without_the_gateway_is_a_usage_error) {
  char tmpl[] = "/tmp/herm-testbed-test-XXXXXX";
  std::string dir = ::mkdtemp(tmpl);
  child_process tb{{HERM_TESTBED_BIN, "--quiet", "--out", dir, "--dds-domain", "7"}};
  auto status = tb.wait(30s);
  EXPECT_FALSE(std::filesystem::exists(dir + "/main.yaml"));
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  // A usage error (exit 2, said on standard error) before anything starts:
  // no configuration was written.
  EXPECT_EQ(status, 2);
  EXPECT_EQ(tb.output().find("EVENT"), std::string::npos) << tb.output();
}
