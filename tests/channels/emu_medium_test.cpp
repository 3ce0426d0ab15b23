// Tests of the pure parts of the emulated medium
// (channels/drivers/emu_medium.hpp): the hold queue's order, the seeded
// impairment decisions, medium-time reservation and bus arbitration. No
// threads, no sockets, no clock: time goes in as numbers.

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "channels/drivers/emu_medium.hpp"

namespace {

using namespace herm::emu_medium;

// -- hold queue -------------------------------------------------------------------

std::vector<uint8_t> bytes_of(uint8_t tag) {
  return {tag, uint8_t(tag + 1)};
}

TEST(hold_queue, releases_earliest_first_and_in_arrival_order_among_ties) {
  struct item {
    int64_t deliver_at;
    uint8_t tag;
  };
  struct test_case {
    const char* name;
    std::vector<item> pushed;
    std::vector<uint8_t> want; // tags in release order
  };
  const std::vector<test_case> cases = {
    {"already ordered", {{1, 1}, {2, 2}, {3, 3}}, {1, 2, 3}},
    {"reversed", {{30, 1}, {20, 2}, {10, 3}}, {3, 2, 1}},
    {"ties keep arrival order", {{5, 1}, {5, 2}, {5, 3}, {5, 4}}, {1, 2, 3, 4}},
    {"ties among others",
     {{7, 1}, {3, 2}, {7, 3}, {3, 4}, {1, 5}},
     {5, 2, 4, 1, 3}},
    {"negative and zero times", {{0, 1}, {-5, 2}, {0, 3}}, {2, 1, 3}},
  };
  for (const auto& c : cases) {
    hold_queue q{16};
    for (const auto& x : c.pushed) {
      auto b = bytes_of(x.tag);
      q.push(x.deliver_at, b.data(), b.size());
    }
    std::vector<uint8_t> got;
    while (!q.empty()) {
      auto b = q.pop();
      ASSERT_EQ(b.size(), 2u) << c.name;
      EXPECT_EQ(b[1], uint8_t(b[0] + 1)) << c.name;
      got.push_back(b[0]);
      q.recycle(std::move(b));
    }
    EXPECT_EQ(got, c.want) << c.name;
  }
}

TEST(hold_queue, is_due_exactly_from_its_earliest_delivery_time) {
  struct test_case {
    int64_t now;
    bool due;
  };
  hold_queue q{4};
  EXPECT_FALSE(q.due(1'000'000)) << "empty";
  uint8_t b = 0;
  q.push(100, &b, 1);
  q.push(50, &b, 1);
  EXPECT_EQ(q.next_due(), 50);
  for (auto c : std::vector<test_case>{
         {0, false}, {49, false}, {50, true}, {51, true}, {100, true}})
    EXPECT_EQ(q.due(c.now), c.due) << "now " << c.now;
}

TEST(hold_queue, is_full_at_its_capacity_and_not_before) {
  for (size_t capacity : {1u, 2u, 5u}) {
    hold_queue q{capacity};
    uint8_t b = 0;
    for (size_t i = 0; i < capacity; ++i) {
      EXPECT_FALSE(q.full()) << capacity << " after " << i;
      q.push(int64_t(i), &b, 1);
    }
    EXPECT_TRUE(q.full()) << capacity;
    EXPECT_EQ(q.size(), capacity);
    q.pop();
    EXPECT_FALSE(q.full()) << capacity;
  }
}

TEST(hold_queue, holds_an_empty_datagram_and_a_recycled_buffer_takes_new_bytes) {
  hold_queue q{4};
  q.push(1, nullptr, 0);
  auto b = q.pop();
  EXPECT_TRUE(b.empty());
  q.recycle(std::vector<uint8_t>(100, 0xEE));
  uint8_t three[] = {1, 2, 3};
  q.push(2, three, 3);
  EXPECT_EQ(q.pop(), (std::vector<uint8_t>{1, 2, 3}));
}

// -- impairments ------------------------------------------------------------------

TEST(dice, casts_nothing_for_an_impossible_event) {
  dice a{42};
  dice b{42};
  for (int i = 0; i < 100; ++i) {
    EXPECT_FALSE(a.chance(0.0));
    EXPECT_EQ(a.up_to(0), 0);
  }
  // Nothing was drawn: both dice continue with the same sequence.
  for (int i = 0; i < 100; ++i)
    EXPECT_EQ(a.up_to(1'000'000), b.up_to(1'000'000));
}

TEST(dice, a_certain_event_always_happens_and_draws_stay_in_range) {
  dice d{7};
  for (int i = 0; i < 1000; ++i) {
    EXPECT_TRUE(d.chance(1.0));
    auto j = d.up_to(5);
    EXPECT_GE(j, 0);
    EXPECT_LE(j, 5);
    EXPECT_LT(d.bit_of(3), 3u);
  }
}

TEST(impairments, copies_follow_loss_and_duplication) {
  struct test_case {
    double loss;
    double duplicate;
    // Over 10,000 frames with seed 1: how many copies in total, within.
    int min_copies;
    int max_copies;
  };
  const std::vector<test_case> cases = {
    {0.0, 0.0, 10'000, 10'000}, // every frame once
    {1.0, 0.0, 0, 0},           // every frame lost
    {1.0, 1.0, 0, 0},           // lost frames are not duplicated
    {0.0, 1.0, 20'000, 20'000}, // every frame twice
    {0.5, 0.0, 4'800, 5'200},   // about half
    {0.0, 0.1, 10'900, 11'100}, // about a tenth twice
  };
  for (const auto& c : cases) {
    dice d{1};
    impairments imp;
    imp.loss = c.loss;
    imp.duplicate = c.duplicate;
    int total = 0;
    for (int i = 0; i < 10'000; ++i) {
      auto n = copies(d, imp);
      ASSERT_GE(n, 0);
      ASSERT_LE(n, 2);
      total += n;
    }
    EXPECT_GE(total, c.min_copies) << c.loss << " " << c.duplicate;
    EXPECT_LE(total, c.max_copies) << c.loss << " " << c.duplicate;
  }
}

TEST(impairments, a_copy_arrives_after_latency_and_jitter_with_at_most_one_flip) {
  struct test_case {
    int64_t latency_ns;
    int64_t jitter_ns;
    double corrupt;
    size_t payload;
    bool may_flip;
    bool must_flip;
  };
  const std::vector<test_case> cases = {
    {0, 0, 0.0, 100, false, false},
    {1'000, 0, 0.0, 100, false, false},
    {1'000, 500, 0.0, 100, false, false},
    {0, 0, 1.0, 0, false, false}, // nothing to corrupt
    {0, 0, 1.0, 1, true, true},
    {250, 10, 1.0, 64, true, true},
    {0, 0, 0.5, 8, true, false},
  };
  constexpr int64_t end = 1'000'000'000;
  for (const auto& c : cases) {
    dice d{99};
    impairments imp;
    imp.latency_ns = c.latency_ns;
    imp.jitter_ns = c.jitter_ns;
    imp.corrupt = c.corrupt;
    for (int i = 0; i < 1000; ++i) {
      auto f = fate_of_copy(d, imp, end, c.payload);
      EXPECT_GE(f.deliver_at_ns, end + c.latency_ns);
      EXPECT_LE(f.deliver_at_ns, end + c.latency_ns + c.jitter_ns);
      if (!c.may_flip) {
        EXPECT_EQ(f.flipped_bit, -1);
      }
      if (c.must_flip) {
        EXPECT_NE(f.flipped_bit, -1);
      }
      if (f.flipped_bit != -1) {
        EXPECT_GE(f.flipped_bit, 0);
        EXPECT_LT(f.flipped_bit, int64_t(c.payload * 8));
      }
    }
  }
}

/// The decisions the emu link kind made before the medium core existed,
/// written out draw by draw: a seed must keep reproducing the same run.
struct historical_copy {
  int64_t deliver_at;
  int64_t bit;
};

std::vector<historical_copy> historical(std::mt19937_64& rng,
                                        const impairments& imp, int64_t end,
                                        size_t size) {
  std::uniform_real_distribution<double> coin{0.0, 1.0};
  if (imp.loss > 0 && coin(rng) < imp.loss)
    return {};
  int n = imp.duplicate > 0 && coin(rng) < imp.duplicate ? 2 : 1;
  std::vector<historical_copy> result;
  for (int copy = 0; copy < n; ++copy) {
    historical_copy c{end + imp.latency_ns, -1};
    if (imp.jitter_ns > 0)
      c.deliver_at
        += std::uniform_int_distribution<int64_t>{0, imp.jitter_ns}(rng);
    if (size > 0 && imp.corrupt > 0 && coin(rng) < imp.corrupt)
      c.bit = static_cast<int64_t>(
        std::uniform_int_distribution<size_t>{0, size * 8 - 1}(rng));
    result.push_back(c);
  }
  return result;
}

TEST(impairments, a_seed_reproduces_the_historical_sequence_of_decisions) {
  struct test_case {
    uint64_t seed;
    impairments imp;
    size_t payload;
  };
  const std::vector<test_case> cases = {
    {1, {0.0, 0.0, 0.0, 0, 0}, 10},
    {2, {0.3, 0.0, 0.0, 0, 0}, 10},
    {3, {0.3, 0.4, 0.0, 1'000, 0}, 10},
    {4, {0.1, 0.2, 0.3, 1'000, 5'000}, 100},
    {5, {0.0, 0.5, 0.5, 0, 1}, 0},
    {6, {0.0, 0.0, 1.0, 0, 0}, 1500},
  };
  for (const auto& c : cases) {
    std::mt19937_64 rng{c.seed};
    dice d{c.seed};
    for (int frame = 0; frame < 500; ++frame) {
      auto end = int64_t{frame} * 1'000'000;
      auto want = historical(rng, c.imp, end, c.payload);
      auto n = copies(d, c.imp);
      ASSERT_EQ(size_t(n), want.size()) << "seed " << c.seed << " " << frame;
      for (int i = 0; i < n; ++i) {
        auto f = fate_of_copy(d, c.imp, end, c.payload);
        EXPECT_EQ(f.deliver_at_ns, want[i].deliver_at) << "seed " << c.seed;
        EXPECT_EQ(f.flipped_bit, want[i].bit) << "seed " << c.seed;
      }
    }
  }
}

// -- medium access ----------------------------------------------------------------

TEST(reserve, starts_when_the_medium_and_the_frame_are_ready_within_the_credit) {
  struct test_case {
    const char* name;
    int64_t busy;
    int64_t enqueued;
    int64_t now;
    int64_t frame;
    int64_t want_end;
  };
  constexpr int64_t credit = max_credit_ns;
  const std::vector<test_case> cases = {
    {"idle medium, fresh frame", 0, 1'000, 1'000, 10, 1'010},
    {"busy medium", 5'000, 1'000, 1'000, 10, 5'010},
    {"frame enqueued after the medium freed", 500, 1'000, 2'000, 10, 1'010},
    {"late wake-up keeps back-to-back timing", 1'000'000, 900'000,
     1'000'000 + credit / 2, 100, 1'000'100},
    {"credit bounds a stalled transmitter", 0, 0, 10 * credit, 100,
     10 * credit - credit + 100},
  };
  for (const auto& c : cases) {
    std::atomic<int64_t> busy{c.busy};
    int calls = 0;
    auto end = reserve(busy, c.enqueued, c.frame, [&] {
      ++calls;
      return c.now;
    });
    EXPECT_EQ(end, c.want_end) << c.name;
    EXPECT_EQ(busy.load(), c.want_end) << c.name;
    EXPECT_EQ(calls, 1) << c.name;
  }
}

TEST(reserve, reservations_follow_each_other_without_overlap) {
  std::atomic<int64_t> busy{0};
  auto now = [] { return int64_t{1'000}; };
  int64_t prev_end = 0;
  for (int64_t frame : {10, 20, 5, 1}) {
    auto end = reserve(busy, 1'000, frame, now);
    EXPECT_EQ(end, std::max<int64_t>(prev_end, 1'000) + frame);
    prev_end = end;
  }
}

TEST(arbitrate, the_lowest_key_ready_at_the_arbitration_point_wins) {
  struct test_case {
    const char* name;
    contender mine;
    std::vector<contender> rivals;
    int64_t busy;
    bool wins;
    int64_t point;
  };
  const std::vector<test_case> cases = {
    {"alone on an idle bus", {50, 100}, {}, 0, true, 100},
    {"alone, bus freed after the frame was ready", {50, 100}, {}, 300, true,
     300},
    {"lower rival key wins", {50, 100}, {{40, 100}}, 0, false, 100},
    {"higher rival key loses", {50, 100}, {{60, 100}}, 0, true, 100},
    {"equal key goes to me", {50, 100}, {{50, 100}}, 0, true, 100},
    {"rival ready first takes the idle bus", {10, 200}, {{90, 100}}, 0, false,
     100},
    {"rival ready after the point does not compete", {50, 100},
     {{10, 150}}, 120, true, 120},
    {"everybody ready by the point competes", {50, 100}, {{10, 150}}, 200,
     false, 200},
    {"several rivals, mine lowest", {5, 100}, {{6, 90}, {7, 80}}, 100, true,
     100},
    {"several rivals, one lower", {5, 100}, {{6, 90}, {4, 80}}, 100, false,
     100},
  };
  for (const auto& c : cases) {
    auto got = arbitrate(c.mine, c.rivals.data(), c.rivals.size(), c.busy);
    EXPECT_EQ(got.wins, c.wins) << c.name;
    EXPECT_EQ(got.point, c.point) << c.name;
  }
}

} // namespace
