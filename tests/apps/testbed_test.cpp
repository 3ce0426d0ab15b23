// The paper's testbed (herm-testbed) end to end: four hermd processes, the
// emulated SRF04 board, the kill of the router module, the Ethernet link
// going down and up, a clean stop. The runner checks each event itself;
// this test names every event it must have seen, so that a runner that
// skipped one fails too.

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>

#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

TEST(testbed, every_event_of_the_paper_scenario_happens) {
  char tmpl[] = "/tmp/herm-testbed-test-XXXXXX";
  std::string dir = ::mkdtemp(tmpl);
  child_process tb{{HERM_TESTBED_BIN, "--quiet", "--out", dir}};
  auto status = tb.wait(240s);
  EXPECT_TRUE(std::filesystem::exists(dir + "/topology.dot"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/main.yaml"));
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  auto& out = tb.output();
  for (auto name :
       {"routes_converged", "topology_written", "sonar_batch_received",
        "first_sonar_batch_not_lost",
        "sonar_batch_fragmented_on_rs232c", "vision_routed_through_mobile",
        "vision_frame_received", "routes_withdrawn",
        "vision_fails_without_mobile", "vision_resumes", "traffic_moves_to_can",
        "vision_over_can_received", "traffic_returns_to_ethernet",
        "clean_shutdown_withdraws_at_once"})
    EXPECT_NE(out.find(std::string{"EVENT ok "} + name + ":"), std::string::npos)
      << "event " << name << " not seen";
  EXPECT_EQ(out.find("EVENT FAILED"), std::string::npos);
  EXPECT_EQ(status, 0) << out;
}
