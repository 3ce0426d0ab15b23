// A program that returns from main without stop_module exits (finding 8 of
// issue 14: it used to hang for ever in the actor system's destructor).
// The program runs as a child process; the wait is bounded.

#include <gtest/gtest.h>

#include "channels/testing/loopback.hpp"
#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

TEST(embed_exit, a_program_returning_from_main_without_stop_module_exits) {
  child_process p{{EMBED_RETURNS_BIN, std::to_string(free_udp_port())}};
  ASSERT_TRUE(p.started());
  ASSERT_TRUE(p.wait_for_line("started", 10s)) << p.output();
  EXPECT_EQ(p.wait(10s), 0) << p.output();
}
