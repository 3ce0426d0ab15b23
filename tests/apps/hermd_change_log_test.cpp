// hermd's change log (apps/hermd/change_log.hpp): the line for a link
// coming up or going down and for each kind of route change, the token
// bucket that bounds them with time passed in, and the summary of what it
// held back. Then real hermd processes: one line per change, none per
// hello, in the order the changes happened.

#include <gtest/gtest.h>

#include <signal.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "apps/hermd/change_log.hpp"
#include "channels/testing/loopback.hpp"
#include "tests/support/process.hpp"

using namespace herm;
using namespace herm::hermd;
using namespace std::chrono_literals;

namespace {

neighbour_event link(bool up, const char* reason) {
  neighbour_event e;
  e.up = up;
  e.id = 0x22;
  e.instance = 7;
  e.channel = 1;
  e.device = "eth0";
  e.link_kind = "Ethernet";
  e.link_address = "127.0.0.1:47001";
  e.reason = reason;
  return e;
}

reachability route(uint32_t cost, module_id next, const char* device) {
  reachability r;
  r.id = 0x40;
  r.reachable = true;
  r.hops = 2;
  r.cost = cost;
  r.next = next;
  r.channel = 1;
  r.neighbour = 9;
  r.path = "Ethernet-CAN2.0";
  r.device = device;
  r.link_address = "127.0.0.1:47001";
  return r;
}

/// How many lines of `text` contain `what`.
size_t count_lines(const std::string& text, const std::string& what) {
  size_t n = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    auto end = text.find('\n', pos);
    if (end == std::string::npos)
      end = text.size();
    if (text.substr(pos, end - pos).find(what) != std::string::npos)
      ++n;
    pos = end + 1;
  }
  return n;
}

} // namespace

// -- lines -----------------------------------------------------------------------

TEST(change_log, a_link_coming_up_names_module_device_kind_and_peer_address) {
  EXPECT_EQ(link_line(link(true, "hello")),
            "link to 0x22 up on eth0 (Ethernet, peer 127.0.0.1:47001)");
  EXPECT_EQ(link_line(link(true, "restarted")),
            "link to 0x22 up on eth0 (Ethernet, peer 127.0.0.1:47001) after a "
            "restart");
}

TEST(change_log, a_link_going_down_says_why) {
  EXPECT_EQ(link_line(link(false, "hellos lost")),
            "link to 0x22 down on eth0 (Ethernet, peer 127.0.0.1:47001): "
            "hellos lost");
  EXPECT_EQ(link_line(link(false, "goodbye")),
            "link to 0x22 down on eth0 (Ethernet, peer 127.0.0.1:47001): "
            "goodbye");
}

TEST(change_log, a_new_route_says_cost_next_hop_device_hops_and_path) {
  EXPECT_EQ(route_line(route(12, 0x21, "eth0")),
            "route to 0x40: cost 12 via 0x21 on eth0, 2 hops, path "
            "Ethernet-CAN2.0 (new)");
}

TEST(change_log, a_changed_route_says_what_it_was) {
  auto r = route(12, 0x21, "eth0");
  r.was_reachable = true;
  r.old_cost = 20;
  r.old_next = 0x22;
  r.old_device = "eth1";
  EXPECT_EQ(route_line(r), "route to 0x40: cost 12 via 0x21 on eth0, 2 hops, "
                           "path Ethernet-CAN2.0 (was 20 via 0x22 on eth1)");
}

TEST(change_log, a_lost_route_says_what_it_was) {
  reachability r;
  r.id = 0x40;
  r.was_reachable = true;
  r.old_cost = 20;
  r.old_next = 0x22;
  r.old_device = "eth1";
  EXPECT_EQ(route_line(r),
            "route to 0x40 withdrawn: unreachable (was 20 via 0x22 on eth1)");
}

TEST(change_log, a_next_hop_without_module_id_shows_its_link_address) {
  auto r = route(3, no_module, "rs0");
  r.hops = 1;
  r.path = "RS232C";
  r.link_address = "peer";
  EXPECT_EQ(route_line(r),
            "route to 0x40: cost 3 via peer on rs0, 1 hop, path RS232C (new)");
}

// -- the bound -------------------------------------------------------------------

TEST(change_log, the_budget_lets_a_burst_through_then_its_rate) {
  auto t0 = std::chrono::steady_clock::time_point{} + 1h;
  line_budget b{3, 2, t0};
  EXPECT_TRUE(b.take(t0));
  EXPECT_TRUE(b.take(t0));
  EXPECT_TRUE(b.take(t0));
  EXPECT_FALSE(b.take(t0));
  EXPECT_FALSE(b.take(t0 + 100ms));
  // Two a second: one more after half a second.
  EXPECT_TRUE(b.take(t0 + 600ms));
  EXPECT_FALSE(b.take(t0 + 600ms));
  EXPECT_EQ(b.held_back(), 3u);
  EXPECT_EQ(b.held_back(), 0u);
  // Never more than the burst, however long it was quiet.
  auto later = t0 + 1h;
  for (int i = 0; i < 3; ++i)
    EXPECT_TRUE(b.take(later)) << i;
  EXPECT_FALSE(b.take(later));
}

TEST(change_log, a_flapping_link_is_bounded_and_what_was_held_back_is_counted) {
  auto t0 = std::chrono::steady_clock::time_point{} + 1h;
  line_budget b{200, 20, t0};
  size_t written = 0;
  // 10000 changes within one second: the burst and the rate, no more.
  for (int i = 0; i < 10000; ++i)
    written += b.take(t0 + std::chrono::microseconds(i * 100)) ? 1 : 0;
  EXPECT_LE(written, 200u + 20u);
  EXPECT_GE(written, 200u);
  EXPECT_EQ(b.held_back(), 10000u - written);
}

TEST(change_log, the_summary_counts_each_kind_held_back) {
  EXPECT_EQ(held_back_line(0, 0, 20), "");
  EXPECT_EQ(held_back_line(1, 0, 20),
            "1 route change not logged (at most 20 lines a second each; "
            "hermctl routes and hermctl neighbors show the tables)");
  EXPECT_EQ(held_back_line(3, 40, 20).substr(0, 46),
            "3 route changes and 40 link changes not logged");
  EXPECT_EQ(held_back_line(0, 2, 20).substr(0, 25), "2 link changes not logged");
}

// -- hermd -------------------------------------------------------------------------

namespace {

class hermd_change_log : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-changelog-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
  }

  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  /// A module with one UDP channel "eth0" to `peer`, hellos every 100 ms.
  std::string module(const std::string& name, const std::string& id,
                     uint16_t port, uint16_t peer) {
    auto path = dir_ + "/" + name + ".yaml";
    std::ofstream{path} << "module:\n  name: " << name << "\n  id: " << id
                        << "\n  hello_interval_ms: 100\ncontrol:\n  socket: "
                        << sock(name)
                        << "\nchannels:\n  - name: eth0\n    kind: udp\n"
                           "    interface: 127.0.0.1:"
                        << port << "\n    peers: 127.0.0.1:" << peer << "\n";
    return path;
  }

  std::string sock(const std::string& name) const {
    return dir_ + "/" + name + ".sock";
  }

  /// hermctl's output for `args` on module `name`.
  std::string hermctl(const std::string& name, const std::string& args) {
    test::child_process p{{"/bin/sh", "-c", std::string{HERMCTL_BIN} + " -s "
                                              + sock(name) + " " + args
                                              + " 2>&1"}};
    EXPECT_EQ(p.wait(30s), 0) << p.output();
    return p.output();
  }

  std::string dir_;
};

} // namespace

// a hears b come up, learns its route, then b is killed (no goodbye) and
// later says goodbye in a second life: one line per change, none per hello
// (b says about 20 hellos while a waits).
TEST_F(hermd_change_log, logs_each_link_and_route_change_once) {
  auto pa = test::free_udp_port(), pb = test::free_udp_port();
  auto a_cfg = module("a", "0x21", pa, pb);
  auto b_cfg = module("b", "0x22", pb, pa);
  test::child_process a{{HERMD_BIN, a_cfg}};
  {
    test::child_process b{{HERMD_BIN, b_cfg}};
    ASSERT_TRUE(a.wait_for_line_containing(
      "link to 0x22 up on eth0 (Ethernet, peer 127.0.0.1:" + std::to_string(pb)
        + ")",
      10s))
      << a.output();
    ASSERT_TRUE(a.wait_for_line_containing(
      "route to 0x22: cost", 10s))
      << a.output();
    // Neighbours and routes show b's link address as IP:port, not as the
    // packed number.
    auto peer = "127.0.0.1:" + std::to_string(pb);
    auto neighbours = hermctl("a", "neighbors");
    EXPECT_NE(neighbours.find("0x22    1        " + peer + "  Ethernet"),
              std::string::npos)
      << neighbours;
    auto routes = hermctl("a", "routes");
    EXPECT_NE(routes.find("0x22 (link " + peer + ")"), std::string::npos)
      << routes;
    // Hellos go on; nothing more is logged about 0x22 while nothing changes.
    ASSERT_TRUE(b.wait_for_line_containing("link to 0x21 up", 10s))
      << b.output();
    std::this_thread::sleep_for(1s);
    b.signal(SIGKILL);
    b.wait(10s);
  }
  ASSERT_TRUE(a.wait_for_line_containing("link to 0x22 down on eth0 "
                                         "(Ethernet, peer 127.0.0.1:"
                                           + std::to_string(pb)
                                           + "): hellos lost",
                                         10s))
    << a.output();
  ASSERT_TRUE(a.wait_for_line_containing("route to 0x22 withdrawn: "
                                         "unreachable (was ",
                                         10s))
    << a.output();
  test::child_process b2{{HERMD_BIN, b_cfg}};
  ASSERT_TRUE(a.wait_for_line_containing("route to 0x22: cost", 10s))
    << a.output();
  b2.signal(SIGTERM);
  EXPECT_EQ(b2.wait(10s), 0) << b2.output();
  ASSERT_TRUE(a.wait_for_line_containing("): goodbye", 10s)) << a.output();
  ASSERT_TRUE(a.wait_for_line_containing("route to 0x22 withdrawn", 10s))
    << a.output();
  a.signal(SIGTERM);
  EXPECT_EQ(a.wait(10s), 0) << a.output();
  auto out = a.output();
  EXPECT_EQ(count_lines(out, "link to 0x22 up on eth0"), 2u) << out;
  EXPECT_EQ(count_lines(out, "link to 0x22 down on eth0"), 2u) << out;
  EXPECT_EQ(count_lines(out, "route to 0x22: cost"), 2u) << out;
  EXPECT_EQ(count_lines(out, "via 0x22 on eth0, 1 hop, path Ethernet (new)"),
            2u)
    << out;
  EXPECT_EQ(count_lines(out, "route to 0x22 withdrawn"), 2u) << out;
  EXPECT_EQ(count_lines(out, "not logged"), 0u) << out;
}
