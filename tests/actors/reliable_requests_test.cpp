// The reliable-request machine (actors/reliable_requests.hpp), time passed
// in: RFC 6298 arithmetic, the copy schedule with its backoff and its limit,
// Karn's rule, the sender's memory of completed requests, and the
// receiver's duplicate cache with its size and age bounds and counters.

#include <gtest/gtest.h>

#include <chrono>
#include <vector>

#include "actors/app_support.hpp"
#include "actors/reliable_requests.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using ms = std::chrono::milliseconds;
using time_point = reliable_requests::time_point;

const time_point t0{};

constexpr module_id a = 0x21;
constexpr module_id b = 0x22;

reliable_requests::config small_config() {
  reliable_requests::config cfg;
  cfg.tick = 100ms;
  cfg.rto_initial = 300ms;
  cfg.rto_min = 50ms;
  cfg.rto_max = 2000ms;
  cfg.max_transmissions = 6;
  cfg.cache_size = 3;
  cfg.cache_ttl = 15000ms;
  return cfg;
}

// -- round trips and RTO ----------------------------------------------------------

TEST(reliable_requests, rto_follows_rfc_6298_within_its_bounds) {
  struct row {
    const char* what;
    std::vector<double> samples_ms;
    double srtt;
    double rttvar;
    ms rto;
  };
  std::vector<row> rows{
    {"no sample: the initial timeout", {}, 0, 0, 300ms},
    {"first sample: SRTT = R, RTTVAR = R/2", {100}, 100, 50, 300ms},
    {"a fast module: clamped to the minimum", {10}, 10, 5, 50ms},
    {"a slow module: clamped to the maximum", {1000}, 1000, 500, 2000ms},
    {"steady samples shrink RTTVAR", {100, 100}, 100, 37.5, 250ms},
    {"a slower sample: alpha 1/8, beta 1/4, rounded", {100, 200}, 112.5,
     62.5, 363ms},
    {"a faster sample", {200, 100}, 187.5, 100, 588ms},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    app_support_stats stats;
    reliable_requests rr{small_config(), stats};
    for (auto x : r.samples_ms)
      rr.sample(a, std::chrono::duration<double, std::milli>(x));
    EXPECT_EQ(rr.rto(a), r.rto);
    EXPECT_EQ(rr.rto(b), 300ms); // other modules are not affected
    auto e = rr.estimate(a);
    if (r.samples_ms.empty()) {
      EXPECT_EQ(e, nullptr);
      continue;
    }
    ASSERT_NE(e, nullptr);
    EXPECT_DOUBLE_EQ(e->srtt, r.srtt);
    EXPECT_DOUBLE_EQ(e->rttvar, r.rttvar);
  }
}

TEST(reliable_requests, only_an_answer_to_a_single_copy_is_a_sample) {
  struct row {
    const char* what;
    uint32_t copies;
    bool sampled;
  };
  std::vector<row> rows{
    {"answered on its first copy", 1, true},
    {"answered after a retransmission (Karn)", 2, false},
    {"answered after five copies", 5, false},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    app_support_stats stats;
    reliable_requests rr{small_config(), stats};
    reliable_requests::transmission tx;
    auto now = t0;
    for (uint32_t i = 0; i < r.copies; ++i) {
      ASSERT_TRUE(rr.send(tx, a, now));
      now = tx.next_send;
    }
    rr.answered(tx, tx.first_sent + 80ms);
    EXPECT_EQ(rr.estimate(a) != nullptr, r.sampled);
    if (r.sampled) {
      EXPECT_DOUBLE_EQ(rr.estimate(a)->srtt, 80);
    }
  }
}

// -- the copy schedule --------------------------------------------------------------

TEST(reliable_requests, copies_back_off_doubling_up_to_the_maximum_then_stop) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  reliable_requests::transmission tx;
  // Copy k goes when copy k-1's timeout ran out; its own timeout is:
  std::vector<ms> timeouts{300ms, 600ms, 1200ms, 2000ms, 2000ms, 2000ms};
  auto now = t0;
  for (size_t k = 0; k < timeouts.size(); ++k) {
    SCOPED_TRACE("copy " + std::to_string(k + 1));
    ASSERT_TRUE(rr.send(tx, a, now));
    EXPECT_EQ(tx.sends, k + 1);
    EXPECT_EQ(tx.rto, timeouts[k]);
    EXPECT_EQ(tx.next_send, now + timeouts[k]);
    EXPECT_EQ(tx.first_sent, t0);
    EXPECT_EQ(stats.retransmissions, k);
    now = tx.next_send;
  }
  // max_transmissions reached: no more copies, looked at every tick until
  // the caller's deadline ends it.
  for (int i = 0; i < 3; ++i) {
    EXPECT_FALSE(rr.send(tx, a, now));
    EXPECT_EQ(tx.sends, 6u);
    EXPECT_EQ(tx.next_send, now + 100ms);
    now = tx.next_send;
  }
  EXPECT_EQ(stats.retransmissions, 5u);
}

TEST(reliable_requests, the_first_timeout_comes_from_the_destinations_estimate) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  rr.sample(a, std::chrono::duration<double, std::milli>(20)); // RTO 60 ms
  reliable_requests::transmission tx;
  ASSERT_TRUE(rr.send(tx, a, t0));
  EXPECT_EQ(tx.rto, 60ms);
  ASSERT_TRUE(rr.send(tx, a, t0 + 60ms));
  EXPECT_EQ(tx.rto, 120ms);
}

TEST(reliable_requests, a_new_destination_starts_the_schedule_over) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  reliable_requests::transmission tx;
  ASSERT_TRUE(rr.send(tx, a, t0));
  ASSERT_TRUE(rr.send(tx, a, t0 + 300ms));
  rr.acknowledged(tx, t0 + 400ms);
  // A rebinding proxy's request now goes to module b.
  ASSERT_TRUE(rr.send(tx, b, t0 + 500ms));
  EXPECT_EQ(tx.dst, b);
  EXPECT_EQ(tx.sends, 1u);
  EXPECT_FALSE(tx.acked);
  EXPECT_EQ(tx.first_sent, t0 + 500ms);
  EXPECT_EQ(tx.rto, 300ms);
  EXPECT_EQ(stats.retransmissions, 1u); // not counted as one
}

TEST(reliable_requests, an_acknowledged_request_is_probed_at_the_slowest_pace) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  reliable_requests::transmission tx;
  ASSERT_TRUE(rr.send(tx, a, t0));
  rr.acknowledged(tx, t0 + 100ms);
  EXPECT_TRUE(tx.acked);
  EXPECT_EQ(tx.next_send, t0 + 2100ms);
  ASSERT_TRUE(rr.send(tx, a, tx.next_send));
  EXPECT_EQ(tx.rto, 2000ms);
  EXPECT_EQ(stats.retransmissions, 1u);
}

TEST(reliable_requests, a_request_without_a_target_waits_a_tick_counted_once) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  reliable_requests::transmission tx, other;
  rr.wait(tx, t0);
  EXPECT_EQ(tx.next_send, t0 + 100ms);
  rr.wait(tx, t0 + 100ms);
  EXPECT_EQ(tx.next_send, t0 + 200ms);
  EXPECT_EQ(stats.reliable_waited, 1u);
  rr.wait(other, t0);
  EXPECT_EQ(stats.reliable_waited, 2u);
  // Deferring (a local target not there yet) is not waiting.
  reliable_requests::transmission third;
  rr.defer(third, t0);
  EXPECT_EQ(third.next_send, t0 + 100ms);
  EXPECT_EQ(stats.reliable_waited, 2u);
  EXPECT_EQ(tx.sends, 0u);
}

// -- the sender's memory of completed requests --------------------------------------

TEST(reliable_requests, late_answers_are_told_from_unknown_ones_up_to_the_bound) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats}; // remembers 3
  for (uint64_t rid : {11, 12, 12, 13, 14})
    rr.complete(rid);
  EXPECT_EQ(rr.completed(), 3u);
  struct row {
    uint64_t rid;
    bool late;
  };
  std::vector<row> rows{
    {11, false}, // pushed out by the fourth completion
    {12, true},  {13, true}, {14, true},
    {99, false}, // never sent: a stray or forged answer
  };
  uint64_t expected_late = 0;
  for (auto& r : rows) {
    SCOPED_TRACE(r.rid);
    EXPECT_EQ(rr.late(r.rid), r.late);
    expected_late += r.late ? 1 : 0;
    EXPECT_EQ(stats.late_duplicates, expected_late);
  }
}

// -- the receiver's duplicate cache -------------------------------------------------

TEST(reliable_requests, a_copy_of_a_remembered_request_is_a_suppressed_duplicate) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  EXPECT_EQ(rr.duplicate(a, 7), nullptr);
  auto& c = rr.remember(a, 7, false, false, t0);
  c.sign = true;
  // Being served: the copy finds it not done (the caller acks it).
  auto d = rr.duplicate(a, 7);
  ASSERT_NE(d, nullptr);
  EXPECT_FALSE(d->done);
  EXPECT_TRUE(d->sign);
  // Answered: later copies get the same response again.
  asl_response r;
  r.request_id = 7;
  r.payload = {1, 2, 3};
  rr.respond(a, 7, r);
  d = rr.duplicate(a, 7);
  ASSERT_NE(d, nullptr);
  EXPECT_TRUE(d->done);
  EXPECT_EQ(d->response, r);
  // The same id from another module is another request.
  EXPECT_EQ(rr.duplicate(b, 7), nullptr);
  EXPECT_EQ(stats.duplicates_suppressed, 2u);
  // A response for an entry not (or no longer) cached changes nothing.
  rr.respond(b, 8, r);
  EXPECT_EQ(rr.duplicate(b, 8), nullptr);
  EXPECT_EQ(rr.cached(), 1u);
}

TEST(reliable_requests, one_way_messages_are_cached_done) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats};
  rr.remember(a, 5, true, true, t0);
  auto d = rr.duplicate(a, 5);
  ASSERT_NE(d, nullptr);
  EXPECT_TRUE(d->done);
  EXPECT_TRUE(d->oneway);
}

TEST(reliable_requests, the_cache_holds_at_most_its_size_dropping_the_oldest) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats}; // 3 entries
  for (uint64_t rid = 1; rid <= 5; ++rid)
    rr.remember(a, rid, true, true, t0 + ms(rid));
  EXPECT_EQ(rr.cached(), 3u);
  struct row {
    uint64_t rid;
    bool cached;
  };
  std::vector<row> rows{{1, false}, {2, false}, {3, true}, {4, true}, {5, true}};
  uint64_t suppressed = 0;
  for (auto& r : rows) {
    SCOPED_TRACE(r.rid);
    EXPECT_EQ(rr.duplicate(a, r.rid) != nullptr, r.cached);
    suppressed += r.cached ? 1 : 0;
    EXPECT_EQ(stats.duplicates_suppressed, suppressed);
  }
}

TEST(reliable_requests, cache_entries_expire_after_their_lifetime) {
  app_support_stats stats;
  reliable_requests rr{small_config(), stats}; // ttl 15 s
  rr.remember(a, 1, true, true, t0);
  rr.remember(a, 2, true, true, t0 + 1s);
  struct row {
    time_point now;
    size_t cached;
  };
  std::vector<row> rows{
    {t0 + 14999ms, 2},
    {t0 + 15s, 1}, // the first one's lifetime is over
    {t0 + 15999ms, 1},
    {t0 + 16s, 0},
  };
  for (auto& r : rows) {
    rr.expire(r.now);
    EXPECT_EQ(rr.cached(), r.cached);
  }
  EXPECT_EQ(rr.duplicate(a, 1), nullptr);
  EXPECT_EQ(stats.duplicates_suppressed, 0u);
}

} // namespace
