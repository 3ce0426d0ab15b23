// The flood cache: one memory of flooded packets for every kind (control
// floods, broadcasts), each entry with its own lifetime, one bound for all;
// past the bound the entry that would expire soonest is forgotten and
// counted by its kind. Pure, so time is passed in.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <vector>

#include "routing/flood_cache.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = flood_cache::time_point;
using key = flood_cache::key;

const time_point t0{std::chrono::seconds{100}};

constexpr uint8_t control = 3;
constexpr uint8_t broadcast = 0;

} // namespace

TEST(flood_cache, a_flood_is_a_duplicate_within_its_lifetime_and_fresh_after) {
  struct {
    const char* name;
    std::chrono::milliseconds lifetime;
    std::chrono::milliseconds later;
    bool fresh;
  } cases[] = {
    {"at once", 500ms, 0ms, false},
    {"just before the end", 500ms, 499ms, false},
    {"at the end", 500ms, 500ms, true},
    {"long after", 500ms, 10s, true},
    {"a broadcast's 30 s", 30s, 29s, false},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    flood_cache fc{16};
    EXPECT_TRUE(fc.admit({control, 1, 2}, t0, c.lifetime));
    EXPECT_EQ(fc.admit({control, 1, 2}, t0 + c.later, c.lifetime), c.fresh);
    EXPECT_EQ(fc.evicted(), 0u);
  }
}

TEST(flood_cache, a_duplicate_does_not_extend_the_lifetime) {
  flood_cache fc{16};
  EXPECT_TRUE(fc.admit({control, 1, 2}, t0, 500ms));
  EXPECT_FALSE(fc.admit({control, 1, 2}, t0 + 400ms, 500ms));
  EXPECT_TRUE(fc.admit({control, 1, 2}, t0 + 500ms, 500ms));
}

TEST(flood_cache, keys_differ_in_kind_and_both_numbers) {
  flood_cache fc{16};
  for (auto k : {key{control, 1, 2}, key{broadcast, 1, 2}, key{control, 2, 2},
                 key{control, 1, 3}})
    EXPECT_TRUE(fc.admit(k, t0, 1s));
  EXPECT_EQ(fc.size(), 4u);
}

TEST(flood_cache, distinct_floods_past_the_bound_forget_the_oldest_and_count_it) {
  struct {
    const char* name;
    size_t capacity;
    size_t floods;
    uint64_t evicted;
  } cases[] = {
    {"within", 8, 8, 0},
    {"one past", 8, 9, 1},
    {"twenty into eight", 8, 20, 12},
    {"capacity 0 holds one", 0, 3, 2},
    {"the default 8192", 8192, 10000, 10000 - 8192},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    flood_cache fc{c.capacity};
    for (uint64_t i = 0; i < c.floods; ++i)
      EXPECT_TRUE(fc.admit({control, i, 0}, t0, 500ms));
    EXPECT_EQ(fc.evicted(control), c.evicted);
    EXPECT_EQ(fc.evicted(), c.evicted);
    EXPECT_EQ(fc.size(), std::min(c.floods, fc.capacity()));
    // The newest is remembered; the oldest forgotten (taken as new, which
    // pushes out another) unless nothing was.
    EXPECT_FALSE(fc.admit({control, c.floods - 1, 0}, t0, 500ms));
    EXPECT_EQ(fc.admit({control, 0, 0}, t0, 500ms), c.evicted > 0);
    EXPECT_EQ(fc.evicted(control), c.evicted + (c.evicted > 0 ? 1 : 0));
  }
}

TEST(flood_cache, expired_entries_make_room_without_counting_as_evicted) {
  flood_cache fc{4};
  for (uint64_t i = 0; i < 4; ++i)
    fc.admit({control, i, 0}, t0, 500ms);
  for (uint64_t i = 10; i < 14; ++i)
    EXPECT_TRUE(fc.admit({control, i, 0}, t0 + 500ms, 500ms));
  EXPECT_EQ(fc.evicted(), 0u);
  EXPECT_EQ(fc.size(), 4u);
}

TEST(flood_cache, one_bound_serves_every_kind_and_counts_evictions_by_kind) {
  struct {
    const char* name;
    /// Kinds admitted in order, all at t0 (control: 500 ms, broadcast: 30 s).
    std::vector<uint8_t> kinds;
    uint64_t control_evicted;
    uint64_t broadcast_evicted;
  } cases[] = {
    // Control floods expire first, so they go first, wherever they stand.
    {"broadcasts push out control floods", {control, control, broadcast,
                                            broadcast, broadcast, broadcast},
     2, 0},
    {"control floods push out control floods first",
     {broadcast, broadcast, control, control, control, control}, 2, 0},
    {"only broadcasts left: the oldest goes",
     {broadcast, broadcast, broadcast, broadcast, control}, 0, 1},
    {"broadcasts only", {broadcast, broadcast, broadcast, broadcast, broadcast,
                         broadcast}, 0, 2},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    flood_cache fc{4};
    uint64_t n = 0;
    for (auto kind : c.kinds)
      EXPECT_TRUE(fc.admit({kind, n++, 0}, t0,
                           kind == control ? 500ms : 30000ms));
    EXPECT_EQ(fc.evicted(control), c.control_evicted);
    EXPECT_EQ(fc.evicted(broadcast), c.broadcast_evicted);
    EXPECT_EQ(fc.evicted(), c.control_evicted + c.broadcast_evicted);
    EXPECT_EQ(fc.size(), 4u);
  }
}

TEST(flood_cache, among_one_lifetime_the_oldest_goes_first) {
  flood_cache fc{2};
  fc.admit({broadcast, 1, 0}, t0, 30s);
  fc.admit({broadcast, 2, 0}, t0 + 1s, 30s);
  fc.admit({broadcast, 3, 0}, t0 + 2s, 30s);
  EXPECT_TRUE(fc.admit({broadcast, 1, 0}, t0 + 3s, 30s));
  EXPECT_FALSE(fc.admit({broadcast, 3, 0}, t0 + 3s, 30s));
  EXPECT_EQ(fc.evicted(broadcast), 2u);
}
