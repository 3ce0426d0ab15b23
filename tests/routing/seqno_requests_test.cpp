// Seqno-request bookkeeping (RFC 8966 3.8.2.1): one request per destination
// per hello interval, at most a bounded number of destinations per
// interval, the excess held back and counted. Pure, so time is passed in.

#include <gtest/gtest.h>

#include <chrono>

#include "routing/seqno_requests.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = seqno_requests::time_point;
using decision = seqno_requests::decision;

const time_point t0{std::chrono::seconds{100}};

seqno_requests with_bound(size_t per_interval) {
  return seqno_requests{{1000ms, per_interval}};
}

} // namespace

TEST(seqno_requests, destinations_past_the_bound_are_held_back_and_counted) {
  struct {
    const char* name;
    size_t per_interval;
    size_t starving;
    size_t sent;
  } cases[] = {
    {"within", 4, 3, 3},
    {"exactly the bound", 4, 4, 4},
    {"ten starving, four allowed", 4, 10, 4},
    {"the default 64", 64, 1000, 64},
    {"bound 0: none", 0, 5, 0},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    auto r = with_bound(c.per_interval);
    size_t sent = 0;
    for (module_id d = 1; d <= c.starving; ++d)
      sent += r.request(d, t0) == decision::send ? 1 : 0;
    EXPECT_EQ(sent, c.sent);
    EXPECT_EQ(r.over_limit(), c.starving - c.sent);
    EXPECT_EQ(r.size(), c.sent);
  }
}

TEST(seqno_requests, one_request_per_destination_per_interval) {
  struct {
    const char* name;
    std::chrono::milliseconds later;
    decision again;
  } cases[] = {
    {"at once", 0ms, decision::duplicate},
    {"within the interval", 999ms, decision::duplicate},
    {"an interval later", 1000ms, decision::send},
    {"long after", 1h, decision::send},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    auto r = with_bound(4);
    EXPECT_EQ(r.request(7, t0), decision::send);
    EXPECT_EQ(r.request(7, t0 + c.later), c.again);
    EXPECT_EQ(r.over_limit(), 0u);
    EXPECT_EQ(r.size(), 1u);
  }
}

TEST(seqno_requests, a_remembered_destination_is_sent_again_even_when_full) {
  auto r = with_bound(2);
  EXPECT_EQ(r.request(1, t0), decision::send);
  EXPECT_EQ(r.request(2, t0 + 500ms), decision::send);
  EXPECT_EQ(r.request(3, t0 + 1s), decision::over_limit);
  // Not expired yet: 1 holds its place and may be asked again.
  EXPECT_EQ(r.request(1, t0 + 1s), decision::send);
  EXPECT_EQ(r.request(1, t0 + 1500ms), decision::duplicate);
  EXPECT_EQ(r.over_limit(), 1u);
}

TEST(seqno_requests, expiry_forgets_requests_an_interval_old_and_makes_room) {
  auto r = with_bound(2);
  r.request(1, t0);
  r.request(2, t0 + 500ms);
  EXPECT_EQ(r.next_expiry(), t0 + 1s);
  r.expire(t0 + 999ms);
  EXPECT_EQ(r.size(), 2u);
  EXPECT_EQ(r.request(3, t0 + 999ms), decision::over_limit);
  r.expire(t0 + 1s);
  EXPECT_EQ(r.size(), 1u);
  EXPECT_EQ(r.request(3, t0 + 1s), decision::send);
  EXPECT_EQ(r.request(4, t0 + 1s), decision::over_limit);
  EXPECT_EQ(r.next_expiry(), t0 + 1500ms);
  r.expire(t0 + 2s);
  EXPECT_EQ(r.size(), 0u);
  EXPECT_EQ(r.next_expiry(), std::nullopt);
  EXPECT_EQ(r.over_limit(), 2u);
}
