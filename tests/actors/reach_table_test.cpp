// Which modules the application support actor can reach
// (actors/reach_table.hpp), time passed in: a module is given up only
// after the grace period, once, and coming back cancels that.

#include <gtest/gtest.h>

#include <chrono>
#include <vector>

#include "actors/reach_table.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = reach_table::time_point;

const time_point t0{};

constexpr module_id a = 0x21;
constexpr module_id b = 0x22;

TEST(reach_table, a_module_is_lost_once_after_the_grace_period_unless_it_returns) {
  reach_table reach;
  enum op { up, down, tick };
  struct row {
    op what;
    module_id m;
    time_point now;
    bool a_reachable;
    std::vector<module_id> lost;
  };
  std::vector<row> rows{
    {down, a, t0, false, {}},       // never up: nothing to lose
    {tick, 0, t0 + 5s, false, {}},
    {up, a, t0 + 5s, true, {}},
    {up, b, t0 + 5s, true, {}},
    {down, a, t0 + 6s, false, {}},
    {tick, 0, t0 + 6400ms, false, {}}, // within the grace period
    {up, a, t0 + 6500ms, true, {}},    // back in time
    {tick, 0, t0 + 8s, true, {}},
    {down, a, t0 + 9s, false, {}},
    {down, b, t0 + 9500ms, false, {}},
    {tick, 0, t0 + 10s, false, {a}},   // a: a second unreachable
    {tick, 0, t0 + 10500ms, false, {b}},
    {tick, 0, t0 + 20s, false, {}},    // each reported once
  };
  for (size_t i = 0; i < rows.size(); ++i) {
    SCOPED_TRACE(i);
    auto& r = rows[i];
    std::vector<module_id> lost;
    if (r.what == up)
      reach.up(r.m);
    else if (r.what == down)
      reach.down(r.m, r.now);
    else
      lost = reach.lost(r.now, 1s);
    EXPECT_EQ(reach.reachable(a), r.a_reachable);
    EXPECT_EQ(lost, r.lost);
  }
}

} // namespace
