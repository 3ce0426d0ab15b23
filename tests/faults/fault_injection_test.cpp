// Fault injection across real processes (issue 8). Every module is a
// herm-apo-peer process with its own actor system and all three layers;
// modules meet on emulated media (channels/drivers/emu.cpp) in temporary
// directories, whose options inject the faults: loss, corruption, jitter
// (reordering), duplication; `--flap` drops everything on a channel for a
// while (a link flap, or with two sides a partition); SIGKILL ends a module
// without a goodbye.
//
// The caller sends numbered request strings that carry a CRC-32 of
// themselves through a proxy in reliable mode; the echo APO counts how often
// it ran for each number and how many strings failed their CRC; the caller
// compares every reply with what it sent. So "exactly once" and "never
// corrupted" are checked end to end. Every wait is bounded; nothing asserts
// on timing. Each test prints a "[measured]" line, the source of the table
// in docs/reliability.md.

#include <gtest/gtest.h>

#include <unistd.h>

#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <thread>
#include <string>
#include <vector>

#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

namespace {

const std::string peer = HERM_APO_PEER_BIN;

/// Options every module of these tests runs with: fast hellos and ticks, a
/// short largest retransmission timeout.
std::vector<std::string> base(const std::string& id) {
  return {peer, "--id", id, "--hello-ms", "50", "--tick-ms", "20",
          "--rto-max-ms", "400"};
}

std::vector<std::string> operator+(std::vector<std::string> a,
                                   const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

std::vector<std::string> lines_with(const std::string& out,
                                    const std::string& prefix) {
  std::vector<std::string> result;
  std::istringstream in{out};
  for (std::string line; std::getline(in, line);)
    if (line.rfind(prefix, 0) == 0)
      result.push_back(line);
  return result;
}

/// The number after "key=" in `line`; -1 if absent. The first match after
/// `after` (e.g. " nil " for the channel counters).
long long field(const std::string& line, const std::string& key,
                const std::string& after = "") {
  auto from = after.empty() ? 0 : line.find(after);
  if (from == std::string::npos)
    return -1;
  auto pos = line.find(" " + key + "=", from);
  if (pos == std::string::npos)
    return -1;
  return std::stoll(line.substr(pos + key.size() + 2));
}

/// "reply I ..." lines per request number.
std::map<int, std::vector<std::string>> replies(const std::string& out) {
  std::map<int, std::vector<std::string>> result;
  for (auto& line : lines_with(out, "reply ")) {
    auto i = std::stoi(line.substr(6));
    result[i].push_back(line.substr(line.find(' ', 6) + 1));
  }
  return result;
}

/// What the echo server printed when it stopped.
struct served_line {
  long long served = -1, distinct = -1, repeats = -1, corrupt = -1;
};

served_line served_of(const std::string& out) {
  served_line r;
  auto lines = lines_with(out, "served ");
  if (lines.empty())
    return r;
  auto& l = lines.back();
  r.served = std::stoll(l.substr(7));
  r.distinct = field(l, "distinct");
  r.repeats = field(l, "repeats");
  r.corrupt = field(l, "corrupt");
  return r;
}

std::string stats_of(const std::string& out) {
  auto lines = lines_with(out, "stats ");
  return lines.empty() ? std::string{} : lines.back();
}

/// Stops `p` with SIGTERM and returns its output once it exited.
std::string stop(child_process& p) {
  p.terminate();
  EXPECT_EQ(p.wait(15s), 0) << p.output();
  return p.output();
}

/// One caller and one echo server on a point-to-point emulated medium of
/// `profile` with `opts` on both stations; `n` reliable requests of
/// `size` bytes, `window` at a time. Checks exactly-once end to end.
void exchange_over(const std::string& profile,
                   const std::vector<std::string>& opts, int n,
                   const std::string& size, const std::string& window,
                   const std::string& what) {
  temp_dir dir{"herm-faults"};
  ASSERT_FALSE(dir.path().empty());
  auto medium = dir.path() + ":" + profile + ":";
  std::vector<std::string> emu_opts;
  for (auto& o : opts)
    emu_opts = emu_opts + std::vector<std::string>{"--emu-opt", o};
  child_process s{base("0x51") + std::vector<std::string>{"--emu", medium + "2"}
                  + emu_opts
                  + std::vector<std::string>{"serve", "--name", "echo"}};
  ASSERT_TRUE(s.wait_for_line("ready", 10s)) << s.output();
  child_process c{base("0x50") + std::vector<std::string>{"--emu", medium + "1"}
                  + emu_opts
                  + std::vector<std::string>{"--timeout", "40", "call",
                                             "--name", "echo", "--count",
                                             std::to_string(n), "--size", size,
                                             "--reliable", "--window", window}};
  EXPECT_EQ(c.wait(60s), 0) << c.output();
  auto out = stop(s);
  auto done = lines_with(c.output(), "done ");
  ASSERT_EQ(done.size(), 1u) << c.output();
  EXPECT_EQ(done[0], "done ok=" + std::to_string(n) + " failed=0");
  EXPECT_EQ(lines_with(c.output(), "bad replies ").at(0), "bad replies 0");
  auto rs = replies(c.output());
  EXPECT_EQ(rs.size(), static_cast<size_t>(n));
  for (auto& [i, r] : rs)
    EXPECT_EQ(r, std::vector<std::string>{"ok"}) << "request " << i;
  // The APO ran exactly once per request and never saw a corrupted one.
  auto sv = served_of(out);
  EXPECT_EQ(sv.served, n) << out;
  EXPECT_EQ(sv.distinct, n) << out;
  EXPECT_EQ(sv.repeats, 0) << out;
  EXPECT_EQ(sv.corrupt, 0) << out;
  auto cs = stats_of(c.output()), ss = stats_of(out);
  std::cout << "[measured] " << what << ": " << rs.size() << "/" << n
            << " answered once, APO runs " << sv.served << ", retransmissions "
            << field(cs, "retransmissions") << ", duplicates suppressed "
            << field(ss, "duplicates_suppressed") << ", late duplicates "
            << field(cs, "late_duplicates") << ", packets dropped below the "
            << "ASL (reassembly/CRC) "
            << field(cs, "rx_reassembly_dropped", " nil ")
                 + field(ss, "rx_reassembly_dropped", " nil ")
            << ", malformed frames "
            << field(cs, "rx_malformed", " nil ") + field(ss, "rx_malformed", " nil ")
            << std::endl;
  std::cout << "[client] " << cs << "\n[server] " << ss << std::endl;
}

} // namespace

// -- loss ---------------------------------------------------------------------------

TEST(faults, reliable_requests_survive_1_percent_loss) {
  exchange_over("ethernet", {"loss=0.01"}, 300, "64", "8",
                "1 % loss both ways");
}

TEST(faults, reliable_requests_survive_10_percent_loss) {
  exchange_over("ethernet", {"loss=0.1"}, 300, "64", "8",
                "10 % loss both ways");
}

TEST(faults, reliable_requests_survive_30_percent_loss) {
  exchange_over("ethernet", {"loss=0.3"}, 100, "64", "8",
                "30 % loss both ways");
}

// -- corruption, reordering, duplication ---------------------------------------------

// On CAN 2.0 (MTU 8) every ASL message is fragmented, so the fragments'
// CRC-32 guards it even without the medium's frame check: 2 % of frames get
// a flipped bit; the packets they belong to are dropped below the ASL and
// counted, and reliable mode retransmits.
TEST(faults, corrupted_frames_are_dropped_below_the_asl_and_never_delivered) {
  exchange_over("can2.0", {"corrupt=0.02", "frame_check=false"}, 150, "32",
                "4", "2 % of CAN frames corrupted both ways, no frame check");
}

// On Ethernet a packet fits one frame: the medium's frame check (the FCS)
// drops the corrupted frames, as a real interface does, and reliable mode
// retransmits.
TEST(faults, corrupted_ethernet_frames_fail_the_frame_check_and_are_resent) {
  exchange_over("ethernet", {"corrupt=0.05"}, 300, "64", "8",
                "5 % of Ethernet frames corrupted both ways, frame check on");
}

// Jitter of up to 20 ms on a link that sends a packet in microseconds
// reorders packets freely; 10 % of frames arrive twice. Replies come back in
// any order (the window keeps 8 requests in flight), each exactly once.
TEST(faults, reliable_requests_survive_reordering_and_duplication) {
  exchange_over("ethernet", {"jitter_us=20000", "duplicate=0.1"}, 300, "64",
                "8", "jitter 0-20 ms and 10 % duplicated frames both ways");
}

// -- a link flap ----------------------------------------------------------------------

// The caller's station loses everything it sends for 3 s, starting 1 s
// after its first reply (however long start-up took: a sanitizer build is
// slow), while requests go out every 60 ms: those sent during the flap wait
// (routes time out; reliable bindings ride it out) and complete once it is
// over.
TEST(faults, reliable_requests_in_flight_complete_after_a_link_flap) {
  temp_dir dir{"herm-faults"};
  ASSERT_FALSE(dir.path().empty());
  auto medium = dir.path() + ":ethernet:";
  child_process s{base("0x53") + std::vector<std::string>{
                    "--emu", medium + "2", "serve", "--name", "echo"}};
  ASSERT_TRUE(s.wait_for_line("ready", 10s)) << s.output();
  child_process c{base("0x52") + std::vector<std::string>{
                    "--emu", medium + "1", "--flap", "1:3", "--timeout", "40",
                    "--request-timeout", "10", "call", "--name", "echo",
                    "--count", "100", "--reliable", "--window", "4",
                    "--gap-ms", "60"}};
  EXPECT_EQ(c.wait(60s), 0) << c.output();
  auto out = stop(s);
  EXPECT_EQ(lines_with(c.output(), "flap up").size(), 1u) << c.output();
  EXPECT_EQ(lines_with(c.output(), "done ").at(0), "done ok=100 failed=0");
  // Requests were answered both before the flap and after it.
  auto text = c.output();
  auto down = text.find("flap down"), up = text.find("flap up");
  ASSERT_NE(down, std::string::npos);
  EXPECT_NE(text.find("reply ", up), std::string::npos) << text;
  EXPECT_NE(text.rfind("reply ", down), std::string::npos) << text;
  auto sv = served_of(out);
  EXPECT_EQ(sv.served, 100) << out;
  EXPECT_EQ(sv.repeats, 0) << out;
  auto cs = stats_of(c.output());
  EXPECT_GT(field(cs, "retransmissions"), 0) << cs;
  std::cout << "[measured] 3 s link flap: 100/100 answered once, APO runs "
            << sv.served << ", retransmissions " << field(cs, "retransmissions")
            << ", requests that waited for the route "
            << field(cs, "reliable_waited") << std::endl;
}

// -- a module killed and restarted ---------------------------------------------------

// The server is killed with SIGKILL while requests are in flight and
// restarted 1 s later under the same id and name. The caller's rebinding
// reliable proxy finds the new APO; every request ends exactly once: with
// its reply, or (a request the old server ran whose reply died with it is
// run again by the new one: at-least-once across a crash) -- never hangs,
// never a wrong reply; errors only typed, past the 4 s deadline.
TEST(faults, reliable_requests_survive_a_module_killed_and_restarted) {
  temp_dir dir{"herm-faults"};
  ASSERT_FALSE(dir.path().empty());
  auto medium = dir.path() + ":ethernet:";
  auto server = base("0x55") + std::vector<std::string>{
                  "--emu", medium + "2", "serve", "--name", "echo"};
  std::optional<child_process> s;
  s.emplace(server);
  ASSERT_TRUE(s->wait_for_line("ready", 10s)) << s->output();
  child_process c{base("0x54") + std::vector<std::string>{
                    "--emu", medium + "1", "--timeout", "40",
                    "--request-timeout", "4", "call", "--name", "echo",
                    "--count", "80", "--reliable", "--rebind", "--window", "4",
                    "--gap-ms", "50"}};
  ASSERT_TRUE(c.wait_for_line("reply 20 ", 20s)) << c.output();
  s.reset(); // SIGKILL
  std::this_thread::sleep_for(1s);
  s.emplace(server);
  ASSERT_TRUE(s->wait_for_line("ready", 10s)) << s->output();
  auto status = c.wait(60s);
  EXPECT_NE(status, -1) << "the caller hung\n" << c.output();
  auto out = stop(*s);
  auto rs = replies(c.output());
  EXPECT_EQ(rs.size(), 80u) << c.output();
  size_t ok = 0, errors = 0;
  for (auto& [i, r] : rs) {
    ASSERT_EQ(r.size(), 1u) << "request " << i;
    if (r[0] == "ok") {
      ++ok;
      continue;
    }
    ++errors;
    EXPECT_EQ(r[0].rfind("error herm.", 0), 0u) << r[0];
    EXPECT_TRUE(r[0].find("timeout") != std::string::npos
                || r[0].find("no_route") != std::string::npos
                || r[0].find("apo_gone") != std::string::npos)
      << r[0];
  }
  EXPECT_EQ(lines_with(c.output(), "reply ").size(), 80u);
  EXPECT_EQ(lines_with(c.output(), "bad replies ").at(0), "bad replies 0");
  // Most of them completed; the new server ran each at most once.
  EXPECT_GE(ok, 60u) << c.output();
  auto sv = served_of(out);
  EXPECT_EQ(sv.repeats, 0) << out;
  EXPECT_EQ(sv.corrupt, 0) << out;
  auto cs = stats_of(c.output());
  std::cout << "[measured] server SIGKILLed and restarted after 1 s: " << ok
            << "/80 answered, " << errors << " typed errors, the restarted "
            << "APO ran " << sv.served << " (repeats " << sv.repeats
            << "), retransmissions " << field(cs, "retransmissions")
            << std::endl;
}

// -- a partition that heals ---------------------------------------------------------

// A (0x61) -bus L- B (0x62) -bridge- C (0x63) -bus R- D (0x64, echo). B and C
// drop everything on the bridge for 3 s, 2.5 s after they start: the
// network splits into {A, B} and {C, D}. Requests from A, one every 80 ms,
// wait during the partition; routes and the binding come back when it
// heals, and every request is answered once.
TEST(faults, a_healed_partition_brings_routes_bindings_and_requests_back) {
  temp_dir left{"herm-faults"}, bridge{"herm-faults"}, right{"herm-faults"};
  ASSERT_FALSE(left.path().empty() || bridge.path().empty()
               || right.path().empty());
  auto l = left.path() + ":ethernet:", b = bridge.path() + ":ethernet:",
       r = right.path() + ":ethernet:";
  child_process d{base("0x64") + std::vector<std::string>{
                    "--emu", r + "2", "serve", "--name", "echo"}};
  ASSERT_TRUE(d.wait_for_line("ready", 10s)) << d.output();
  // Device names count from emu0 in the order given: C's bridge is emu0,
  // B's is emu1.
  child_process cc{base("0x63") + std::vector<std::string>{
                     "--emu", b + "2", "--emu", r + "1", "--flap", "2.5:3:emu0",
                     "route"}};
  child_process bb{base("0x62") + std::vector<std::string>{
                     "--emu", l + "2", "--emu", b + "1", "--flap", "2.5:3:emu1",
                     "route"}};
  ASSERT_TRUE(cc.wait_for_line("ready", 10s)) << cc.output();
  ASSERT_TRUE(bb.wait_for_line("ready", 10s)) << bb.output();
  child_process a{base("0x61") + std::vector<std::string>{
                    "--emu", l + "1", "--timeout", "40", "--request-timeout",
                    "10", "call", "--name", "echo", "--count", "90",
                    "--reliable", "--window", "2", "--gap-ms", "80"}};
  EXPECT_EQ(a.wait(60s), 0) << a.output();
  EXPECT_TRUE(bb.wait_for_line("flap up", 10s)) << bb.output();
  auto out = stop(d);
  stop(cc);
  stop(bb);
  EXPECT_EQ(lines_with(a.output(), "done ").at(0), "done ok=90 failed=0");
  auto sv = served_of(out);
  EXPECT_EQ(sv.served, 90) << out;
  EXPECT_EQ(sv.repeats, 0) << out;
  // The partition was felt: requests were retransmitted or waited for the
  // route to D to come back.
  auto cs = stats_of(a.output());
  EXPECT_GT(field(cs, "retransmissions") + field(cs, "reliable_waited"), 0)
    << cs;
  std::cout << "[measured] 4 modules split in two for 3 s: 90/90 answered "
            << "once, APO runs " << sv.served << ", retransmissions "
            << field(cs, "retransmissions") << ", requests that waited for "
            << "the route " << field(cs, "reliable_waited") << std::endl;
}
