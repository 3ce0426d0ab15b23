// herm-bench-rtt's measurement pipeline (never its figures): the /proc
// parsers, the shared allocation counter page, the client's snapshots of
// itself, the counts per round trip and the result line that carries them
// from the client to the orchestrator.

#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include <gtest/gtest.h>

#include "apps/bench/peers/children.hpp"
#include "apps/bench/peers/per_round_trip.hpp"
#include "apps/bench/peers/probes.hpp"

using namespace herm::bench;

namespace {

// -- /proc parsers ---------------------------------------------------------------------

TEST(probes, schedstat_third_field_is_the_timeslice_count) {
  EXPECT_EQ(parse_schedstat_timeslices("123456 7890 42\n"), 42);
  EXPECT_EQ(parse_schedstat_timeslices("1 2"), -1);
  EXPECT_EQ(parse_schedstat_timeslices(""), -1);
  EXPECT_EQ(parse_schedstat_timeslices("a b c"), -1);
}

TEST(probes, voluntary_switches_are_not_confused_with_nonvoluntary_ones) {
  EXPECT_EQ(parse_voluntary_switches("Name:\tx\nnonvoluntary_ctxt_switches:\t7\n"), -1);
  EXPECT_EQ(parse_voluntary_switches("Name:\tx\nvoluntary_ctxt_switches:\t12\n"
                                     "nonvoluntary_ctxt_switches:\t7\n"),
            12);
  EXPECT_EQ(parse_voluntary_switches("nonvoluntary_ctxt_switches:\t7\n"
                                     "voluntary_ctxt_switches:\t5\n"),
            5);
}

// -- the counter page and the snapshots ---------------------------------------------------

TEST(probes, allocations_in_the_timed_part_land_in_this_process_slot) {
  int fd = make_counter_page();
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(attach_counter_page(fd, slot_client));
  // A second mapping, as the orchestrator's other children would see it.
  auto* view = static_cast<std::atomic<uint64_t>*>(
    ::mmap(nullptr, 4096, PROT_READ, MAP_SHARED, fd, 0));
  ASSERT_NE(view, MAP_FAILED);
  set_case_processes(0, 0, false);
  timed_part_begins();
  auto before = view[0].load();
  std::vector<std::unique_ptr<int>> xs;
  for (int i = 0; i < 100; ++i)
    xs.push_back(std::make_unique<int>(i)); // 100 news and the vector's growth
  void* c = std::malloc(64);               // C allocations are seen as well
  std::free(c);
  auto after = view[0].load();
  timed_part_ends();
  auto counts = timed_part_counts();
  EXPECT_GE(after - before, 100u);
  EXPECT_GE(counts[slot_client].allocs, 100);
  if (std::string{allocations_counted()} == "malloc") {
    EXPECT_GE(counts[slot_client].allocs, 101 + 7); // the malloc and the vector's growth
  }
  EXPECT_GE(counts[slot_client].wakeups, 0);
  EXPECT_GE(counts[slot_client].voluntary_switches, 0);
  EXPECT_EQ(counts[slot_client].syscalls, -1) << "not asked for";
  EXPECT_EQ(counts[slot_server].allocs, -1) << "no server process";
  EXPECT_EQ(counts[slot_router].wakeups, -1) << "no router process";
  ::munmap(view, 4096);
  ::close(fd);
}

TEST(probes, a_process_that_blocks_is_woken_and_counted) {
  set_case_processes(0, 0, false);
  timed_part_begins();
  for (int i = 0; i < 5; ++i)
    ::usleep(1000); // each sleep ends with this thread scheduled in again
  timed_part_ends();
  auto counts = timed_part_counts();
  EXPECT_GE(counts[slot_client].wakeups, 5);
  EXPECT_GE(counts[slot_client].voluntary_switches, 5);
}

TEST(probes, syscalls_are_counted_when_perf_allows_it) {
  if (!syscall_counting_unavailable().empty())
    GTEST_SKIP() << syscall_counting_unavailable();
  set_case_processes(0, 0, true);
  timed_part_begins();
  for (int i = 0; i < 50; ++i)
    (void) ::getppid();
  timed_part_ends();
  auto counts = timed_part_counts();
  EXPECT_GE(counts[slot_client].syscalls, 50);
  EXPECT_LT(counts[slot_client].syscalls, 80) << "the snapshots' own syscalls are left out";
}

TEST(probes, pinning_to_an_allowed_cpu_is_what_the_affinity_then_allows) {
  if (!cpu_allowed(0))
    GTEST_SKIP() << "vCPU 0 is not available";
  ASSERT_FALSE(cpu_allowed(-1));
  // In a child, so the test runner's affinity stays as it was.
  auto pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0)
    ::_exit(pin_to_cpu(0) && cpu_allowed(0) && !cpu_allowed(1) ? 0 : 1);
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

// -- counts per round trip ------------------------------------------------------------------

case_counts sample() {
  case_counts c;
  c[slot_client] = {200, 100, 3000, 400};
  c[slot_server] = {100, 100, 2500, -1};
  return c;
}

TEST(per_round_trip, totals_are_divided_by_the_round_trips_per_process) {
  auto x = per_round_trip(sample(), 100);
  EXPECT_DOUBLE_EQ(x[slot_client][f_wakeups], 2.0);
  EXPECT_DOUBLE_EQ(x[slot_server][f_allocs], 25.0);
  EXPECT_DOUBLE_EQ(x[slot_server][f_syscalls], -1);
  EXPECT_DOUBLE_EQ(x[slot_router][f_wakeups], -1);
  EXPECT_DOUBLE_EQ(total(x, f_allocs), 55.0);
  EXPECT_DOUBLE_EQ(total(x, f_syscalls), 4.0);
  EXPECT_DOUBLE_EQ(most(x, f_wakeups), 2.0);
  EXPECT_DOUBLE_EQ(total(unmeasured(), f_allocs), -1);
  EXPECT_DOUBLE_EQ(per_round_trip(sample(), 0)[slot_client][f_wakeups], -1);
}

TEST(per_round_trip, median_over_runs_skips_unmeasured_runs) {
  auto a = per_round_trip(sample(), 100);
  auto b = a, c = a;
  b[slot_client][f_wakeups] = 4;
  c[slot_client][f_wakeups] = -1;
  auto m = median_of({a, b, c});
  EXPECT_DOUBLE_EQ(m[slot_client][f_wakeups], 3.0); // of 2 and 4
  auto d = a;
  d[slot_client][f_wakeups] = 10;
  EXPECT_DOUBLE_EQ(median_of({a, b, d})[slot_client][f_wakeups], 4.0);
  EXPECT_DOUBLE_EQ(median_of({})[slot_client][f_wakeups], -1);
}

TEST(per_round_trip, syscalls_come_from_the_counting_pass) {
  auto timed = per_round_trip(sample(), 100);
  auto pass = unmeasured();
  pass[slot_server][f_syscalls] = 3;
  auto x = with_syscalls(timed, pass);
  EXPECT_DOUBLE_EQ(x[slot_client][f_syscalls], -1);
  EXPECT_DOUBLE_EQ(x[slot_server][f_syscalls], 3);
  EXPECT_DOUBLE_EQ(x[slot_client][f_allocs], 30);
}

TEST(per_round_trip, cells_and_json_show_each_process_and_leave_out_absent_ones) {
  auto x = per_round_trip(sample(), 100);
  EXPECT_EQ(cells(x, f_wakeups), "2.0/1.0");
  EXPECT_EQ(cells(x, f_syscalls), "4.0/-");
  x[slot_router][f_wakeups] = 2;
  EXPECT_EQ(cells(x, f_wakeups), "2.0/1.0/2.0");
  auto js = to_json(per_round_trip(sample(), 100));
  EXPECT_EQ(js["client"]["allocs"], 30.0);
  EXPECT_TRUE(js["server"]["syscalls"].is_null());
  EXPECT_FALSE(js.contains("router"));
}

// -- the result line --------------------------------------------------------------------------

TEST(result_line, counts_travel_from_client_to_orchestrator) {
  auto line = "rtt 2 1000 2000 " + format_counts(sample());
  auto out = parse_result(line);
  ASSERT_TRUE(std::holds_alternative<client_result>(out)) << std::get<std::string>(out);
  auto& res = std::get<client_result>(out);
  EXPECT_EQ(res.rtt_ns, (std::vector<int64_t>{1000, 2000}));
  EXPECT_EQ(res.counts[slot_client].allocs, 3000);
  EXPECT_EQ(res.counts[slot_server].syscalls, -1);
  EXPECT_EQ(res.counts[slot_router].wakeups, -1);
}

TEST(result_line, a_line_without_counts_leaves_them_unmeasured) {
  auto out = parse_result("rtt 1 5");
  ASSERT_TRUE(std::holds_alternative<client_result>(out));
  EXPECT_EQ(std::get<client_result>(out).counts[slot_client].wakeups, -1);
}

TEST(result_line, malformed_lines_are_errors_not_figures) {
  EXPECT_TRUE(std::holds_alternative<std::string>(parse_result("rtt 3 1 2")));
  EXPECT_TRUE(std::holds_alternative<std::string>(parse_result("rtt 1 5 counts 1 2")));
  EXPECT_TRUE(std::holds_alternative<std::string>(parse_result("rtt 1 5 junk")));
  EXPECT_TRUE(std::holds_alternative<std::string>(parse_result("rtt 999999999999 1")));
  auto err = parse_result("error udp bind: Address in use");
  ASSERT_TRUE(std::holds_alternative<std::string>(err));
  EXPECT_EQ(std::get<std::string>(err), "client: error udp bind: Address in use");
}

} // namespace
