// The neighbour table: hellos make neighbours, goodbyes, lost channels and
// silence drop them, and the bounds (in total, per channel) refuse new ones
// past them, counted, while neighbours already held keep being refreshed.
// Pure, so time is passed in.

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <vector>

#include "routing/neighbour_table.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = neighbour_table::time_point;
using result = neighbour_table::hello_result;

const time_point t0{std::chrono::seconds{100}};

neighbour_table::limits bounds(size_t total, size_t per_channel) {
  neighbour_table::limits lim;
  lim.total = total;
  lim.per_channel = per_channel;
  return lim;
}

/// A hello from link address `addr` on channel `ch` (id and instance derived
/// from the address).
result hello_from(neighbour_table& t, channel_id ch, link_addr addr,
                  time_point now = t0, uint64_t instance = 0) {
  return t.heard(next_hop{ch, addr}, static_cast<module_id>(0x100 + addr),
                 instance != 0 ? instance : 1000 + addr, 1000ms, now);
}

} // namespace

TEST(neighbour_table, new_neighbours_past_a_bound_are_refused_and_counted) {
  struct {
    const char* name;
    size_t total;
    size_t per_channel;
    /// Distinct new neighbours saying hello on channels 1 and 2.
    size_t on1;
    size_t on2;
    size_t held;
    uint64_t refused;
  } cases[] = {
    {"within both bounds", 10, 5, 3, 2, 5, 0},
    {"exactly at the channel bound", 10, 3, 3, 3, 6, 0},
    {"past the channel bound on one channel", 10, 3, 5, 1, 4, 2},
    {"past the channel bound on both", 10, 3, 4, 6, 6, 4},
    {"past the total", 4, 10, 3, 3, 4, 2},
    {"past both bounds", 2, 1, 3, 3, 2, 4},
    {"512 and 128 (the defaults), 200 on one channel", 512, 128, 200, 0, 128,
     72},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    neighbour_table t{bounds(c.total, c.per_channel)};
    for (link_addr a = 1; a <= c.on1; ++a)
      hello_from(t, 1, a);
    for (link_addr a = 1; a <= c.on2; ++a)
      hello_from(t, 2, a);
    EXPECT_EQ(t.size(), c.held);
    EXPECT_EQ(t.entries().size(), c.held);
    EXPECT_EQ(t.refused(), c.refused);
  }
}

TEST(neighbour_table, neighbours_held_at_a_bound_keep_being_refreshed) {
  neighbour_table t{bounds(2, 2)};
  EXPECT_EQ(hello_from(t, 1, 1), result::added);
  EXPECT_EQ(hello_from(t, 1, 2), result::added);
  EXPECT_EQ(hello_from(t, 1, 3), result::refused);
  EXPECT_EQ(hello_from(t, 1, 1, t0 + 1s), result::refreshed);
  EXPECT_EQ(hello_from(t, 1, 2, t0 + 1s, 77), result::restarted);
  EXPECT_EQ(t.refused(), 1u);
  ASSERT_NE(t.find({1, 2}), nullptr);
  EXPECT_EQ(t.find({1, 2})->instance, 77u);
  EXPECT_EQ(t.find({1, 2})->last_hello, t0 + 1s);
  EXPECT_EQ(t.find({1, 3}), nullptr);
}

TEST(neighbour_table, room_comes_back_when_a_neighbour_leaves_by_any_way) {
  struct {
    const char* name;
    std::function<void(neighbour_table&)> leave;
  } cases[] = {
    {"goodbye", [](neighbour_table& t) { EXPECT_TRUE(t.goodbye({1, 1}, 1001)); }},
    {"channel ended", [](neighbour_table& t) { t.remove_channel(1); }},
    {"silence", [](neighbour_table& t) { EXPECT_EQ(t.expire(t0 + 2s).size(), 2u); }},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    neighbour_table t{bounds(2, 2)};
    hello_from(t, 1, 1);
    hello_from(t, 1, 2);
    EXPECT_EQ(hello_from(t, 1, 3, t0 + 2s), result::refused);
    c.leave(t);
    EXPECT_EQ(hello_from(t, 1, 3, t0 + 2s), result::added);
    EXPECT_EQ(t.refused(), 1u);
  }
}

TEST(neighbour_table, a_goodbye_of_another_instance_or_a_stranger_changes_nothing) {
  neighbour_table t;
  hello_from(t, 1, 1);
  EXPECT_FALSE(t.goodbye({1, 1}, 999));
  EXPECT_FALSE(t.goodbye({1, 2}, 1002));
  EXPECT_FALSE(t.goodbye({2, 1}, 1001));
  EXPECT_EQ(t.size(), 1u);
  EXPECT_TRUE(t.goodbye({1, 1}, 1001));
  EXPECT_EQ(t.size(), 0u);
}

TEST(neighbour_table, a_goodbye_is_remembered_until_a_hello_of_that_hop) {
  neighbour_table t;
  hello_from(t, 1, 1);
  EXPECT_FALSE(t.departed({1, 1}, 1001)) << "still here";
  ASSERT_TRUE(t.goodbye({1, 1}, 1001));
  EXPECT_TRUE(t.departed({1, 1}, 1001));
  EXPECT_FALSE(t.departed({1, 1}, 2001)) << "a later life has not left";
  EXPECT_FALSE(t.departed({1, 2}, 1001));
  // A goodbye of a stranger or of another life is not a departure.
  EXPECT_FALSE(t.goodbye({1, 2}, 1002));
  EXPECT_FALSE(t.departed({1, 2}, 1002));
  // Back (a restart): no longer departed.
  EXPECT_EQ(hello_from(t, 1, 1, t0 + 1s, 2001), result::added);
  EXPECT_FALSE(t.departed({1, 1}, 1001));
}

TEST(neighbour_table, departures_are_bounded_oldest_forgotten_first) {
  neighbour_table t{bounds(3, 3)};
  // Eight neighbours come and go one after the other on channel 1; the
  // last three goodbyes are remembered.
  for (link_addr a = 1; a <= 8; ++a) {
    hello_from(t, 1, a);
    ASSERT_TRUE(t.goodbye({1, a}, 1000 + a));
  }
  for (link_addr a = 1; a <= 8; ++a)
    EXPECT_EQ(t.departed({1, a}, 1000 + a), a >= 6) << "address " << a;
  // The same hop leaving again and again takes one place, not many.
  for (int i = 0; i < 10; ++i) {
    hello_from(t, 1, 8);
    ASSERT_TRUE(t.goodbye({1, 8}, 1008));
  }
  EXPECT_TRUE(t.departed({1, 8}, 1008));
  EXPECT_TRUE(t.departed({1, 7}, 1007));
  EXPECT_TRUE(t.departed({1, 6}, 1006));
}

TEST(neighbour_table, removing_a_channel_drops_its_neighbours_only) {
  neighbour_table t{bounds(10, 2)};
  for (channel_id ch : {1, 2, 3})
    for (link_addr a : {1, 2})
      hello_from(t, ch, a);
  t.remove_channel(2);
  EXPECT_EQ(t.size(), 4u);
  EXPECT_EQ(t.find({2, 1}), nullptr);
  EXPECT_NE(t.find({1, 2}), nullptr);
  EXPECT_NE(t.find({3, 1}), nullptr);
  // Channel 2's share is free again, the others' are still full.
  EXPECT_EQ(hello_from(t, 2, 5), result::added);
  EXPECT_EQ(hello_from(t, 3, 5), result::refused);
}

TEST(neighbour_table, silence_past_hello_loss_intervals_loses_a_neighbour) {
  struct {
    const char* name;
    /// The neighbour's hello interval, and time since its hello.
    std::chrono::milliseconds said;
    std::chrono::milliseconds silent;
    double loss;
    bool lost;
  } cases[] = {
    // Ours is 1 s.
    {"1.5 intervals exactly: kept", 1000ms, 1500ms, 1.5, false},
    {"just past 1.5 intervals: lost", 1000ms, 1501ms, 1.5, true},
    {"a shorter interval than ours counts as ours", 100ms, 1400ms, 1.5, false},
    {"a longer interval than ours is its own", 4000ms, 5000ms, 1.5, false},
    {"past its own longer interval", 4000ms, 6001ms, 1.5, true},
    {"lossy links: 3 intervals", 1000ms, 2900ms, 3, false},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    neighbour_table::limits lim;
    lim.hello_loss = c.loss;
    neighbour_table t{lim};
    t.heard({1, 7}, 0x107, 1, c.said, t0);
    t.heard({1, 8}, 0x108, 1, c.said, t0 + c.silent);
    // The earliest time expire() drops one (the agent's next tick).
    auto next = t.next_expiry();
    ASSERT_TRUE(next);
    EXPECT_EQ(*next <= t0 + c.silent, c.lost);
    auto lost = t.expire(t0 + c.silent);
    EXPECT_EQ(lost.size(), c.lost ? 1u : 0u);
    if (c.lost) {
      EXPECT_EQ(lost.front(), (next_hop{1, 7}));
    }
    EXPECT_EQ(t.size(), c.lost ? 1u : 2u);
    EXPECT_NE(t.find({1, 8}), nullptr);
  }
}

TEST(neighbour_table, lost_neighbours_come_back_in_next_hop_order) {
  neighbour_table t;
  for (auto nh : {next_hop{2, 1}, next_hop{1, 9}, next_hop{1, 3}})
    t.heard(nh, 0x10, 1, 1000ms, t0);
  auto lost = t.expire(t0 + 10s);
  EXPECT_EQ(lost, (std::vector<next_hop>{{1, 3}, {1, 9}, {2, 1}}));
  EXPECT_EQ(t.size(), 0u);
  EXPECT_EQ(t.next_expiry(), std::nullopt);
}
