// The sender's table of requests waiting for an answer
// (actors/outgoing_requests.hpp), time passed in: ids, the bound, which
// answer matches which request, and what leaves the table when.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <set>
#include <vector>

#include "actors/app_support.hpp"
#include "actors/asl_errors.hpp"
#include "actors/outgoing_requests.hpp"
#include "actors/runtime/error.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = outgoing_requests::time_point;

const time_point t0{};

constexpr module_id a = 0x21;
constexpr module_id b = 0x22;

outgoing request(uint32_t binding, module_id dst, time_point deadline,
                 bool reliable = false, uint32_t sends = 1) {
  outgoing out;
  out.binding = binding;
  out.deadline = deadline;
  out.reliable = reliable;
  out.tx.dst = dst;
  out.tx.sends = sends;
  return out;
}

/// What the table works with: the reliable machine and the counters.
struct env {
  app_support_stats stats;
  reliable_requests rr{reliable_requests::config{}, stats};
};

std::vector<uint32_t> bindings_of(const std::vector<outgoing>& xs) {
  std::vector<uint32_t> result;
  for (auto& x : xs)
    result.push_back(x.binding);
  std::sort(result.begin(), result.end());
  return result;
}

TEST(outgoing_requests, ids_are_distinct_not_sequential_and_the_table_is_bounded) {
  env e;
  outgoing_requests reqs{42, 3, e.rr, e.stats};
  std::vector<uint64_t> ids;
  for (uint32_t i = 1; i <= 3; ++i) {
    EXPECT_FALSE(reqs.full());
    ids.push_back(reqs.add(request(i, a, t0 + 1s)).first);
  }
  EXPECT_TRUE(reqs.full());
  EXPECT_EQ(reqs.size(), 3u);
  EXPECT_EQ(std::set<uint64_t>(ids.begin(), ids.end()).size(), 3u);
  for (auto id : ids)
    EXPECT_NE(id, 0u);
  EXPECT_NE(ids[1], ids[0] + 1);
  // Another key, other ids.
  outgoing_requests other{43, 3, e.rr, e.stats};
  EXPECT_NE(other.add(request(1, a, t0)).first, ids[0]);
}

TEST(outgoing_requests, an_answer_matches_only_the_request_it_can_be_for) {
  struct row {
    const char* what;
    bool reliable;
    uint32_t sends;
    module_id from;
    bool ack;
    bool matches;
  };
  std::vector<row> rows{
    {"a response from where a plain request went", false, 1, a, false, true},
    {"a response from another module", false, 1, b, false, false},
    {"an ack for a plain request", false, 1, a, true, false},
    {"a response to a reliable request", true, 1, a, false, true},
    {"an ack for a reliable request", true, 3, a, true, true},
    {"an ack from another module", true, 1, b, true, false},
    {"an answer to a reliable request not sent yet", true, 0, a, false,
     false},
    {"an ack for a reliable request not sent yet", true, 0, a, true, false},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    env e;
    outgoing_requests reqs{1, 10, e.rr, e.stats};
    auto rid = reqs.add(request(7, a, t0, r.reliable, r.sends)).first;
    EXPECT_EQ(reqs.expecting(rid, r.from, r.ack) != nullptr, r.matches);
    EXPECT_EQ(reqs.expecting(rid + 1, r.from, r.ack), nullptr);
    EXPECT_EQ(e.stats.rx_unexpected_response, r.matches ? 1u : 2u);
  }
}

TEST(outgoing_requests, requests_leave_by_binding_module_deadline_or_all_at_once) {
  env e;
  outgoing_requests reqs{1, 10, e.rr, e.stats};
  reqs.add(request(1, a, t0 + 1s));
  reqs.add(request(2, a, t0 + 2s, true));
  reqs.add(request(3, b, t0 + 3s));
  reqs.add(request(4, b, t0 + 4s, true));
  reqs.add(request(5, a, t0 + 5s));
  // Binding 2, keeping reliable ones: none goes.
  EXPECT_TRUE(reqs.take_waiting_on(2, no_module, true).empty());
  // Module a, keeping reliable ones: 1 and 5.
  EXPECT_EQ(bindings_of(reqs.take_waiting_on(0, a, true)),
            (std::vector<uint32_t>{1, 5}));
  // Deadlines passed at 3 s: 2 and 3 (a deadline at `now` has passed).
  EXPECT_EQ(bindings_of(reqs.take_expired(t0 + 3s)),
            (std::vector<uint32_t>{2, 3}));
  EXPECT_EQ(bindings_of(reqs.take_all()), (std::vector<uint32_t>{4}));
  EXPECT_EQ(reqs.size(), 0u);
}

TEST(outgoing_requests, due_lists_reliable_requests_whose_time_came_or_that_are_forced) {
  env e;
  outgoing_requests reqs{1, 10, e.rr, e.stats};
  auto plain = reqs.add(request(1, a, t0 + 9s)).first;
  auto later = reqs.add(request(2, a, t0 + 9s, true)).first;
  auto now_due = reqs.add(request(3, a, t0 + 9s, true)).first;
  auto acked = reqs.add(request(2, a, t0 + 9s, true)).first;
  reqs.find(later)->tx.next_send = t0 + 2s;
  reqs.find(now_due)->tx.next_send = t0 + 1s;
  reqs.find(acked)->tx.next_send = t0 + 5s;
  reqs.find(acked)->tx.acked = true;
  auto sorted = [](std::vector<uint64_t> xs) {
    std::sort(xs.begin(), xs.end());
    return xs;
  };
  struct row {
    const char* what;
    std::vector<uint32_t> forced;
    bool unacked_only;
    std::vector<uint64_t> due;
  };
  std::vector<row> rows{
    {"only the one whose time came", {}, false, {now_due}},
    {"binding 2 forced: both of its", {2}, false, {later, now_due, acked}},
    {"binding 2 forced, acked ones spared", {2}, true, {later, now_due}},
    {"a plain request's binding forced: never", {1}, false, {now_due}},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    EXPECT_EQ(sorted(reqs.due(t0 + 1s, r.forced, r.unacked_only)),
              sorted(r.due));
  }
  EXPECT_NE(reqs.find(plain), nullptr);
}

TEST(outgoing_requests, an_ack_ends_a_one_way_message_and_slows_a_requests_probes) {
  env e;
  outgoing_requests reqs{1, 10, e.rr, e.stats};
  auto oneway = reqs.add(request(1, a, t0 + 9s, true)).first;
  reqs.find(oneway)->oneway = true;
  reqs.find(oneway)->tx.first_sent = t0;
  auto served = reqs.add(request(2, a, t0 + 9s, true)).first;
  reqs.on_ack(a, asl_ack{oneway}, t0 + 40ms);
  EXPECT_EQ(reqs.find(oneway), nullptr);
  ASSERT_NE(e.rr.estimate(a), nullptr); // answered on its first copy
  EXPECT_DOUBLE_EQ(e.rr.estimate(a)->srtt, 40);
  reqs.on_ack(a, asl_ack{served}, t0 + 50ms);
  ASSERT_NE(reqs.find(served), nullptr);
  EXPECT_TRUE(reqs.find(served)->tx.acked);
  EXPECT_EQ(reqs.find(served)->tx.next_send, t0 + 50ms + 2s);
  EXPECT_EQ(e.stats.acks_received, 2u);
  // A copy of the first ack is late; an ack nobody asked for, unexpected.
  reqs.on_ack(a, asl_ack{oneway}, t0 + 60ms);
  reqs.on_ack(a, asl_ack{oneway + served}, t0 + 60ms);
  EXPECT_EQ(e.stats.late_duplicates, 1u);
  EXPECT_EQ(e.stats.rx_unexpected_response, 1u);
  EXPECT_EQ(e.stats.acks_received, 2u);
}

TEST(outgoing_requests, a_response_replies_waits_for_a_rebinding_target_or_ends_quietly) {
  using step = outgoing_requests::response_step;
  auto gone = [](uint64_t rid) {
    asl_response r;
    r.request_id = rid;
    r.ok = false;
    r.error = to_wire(make_error(app_ec::apo_gone, "gone"));
    return r;
  };
  auto fine = [](uint64_t rid) {
    asl_response r;
    r.request_id = rid;
    return r;
  };
  struct row {
    const char* what;
    bool reliable;
    bool oneway;
    bool rebind;
    bool ok;
    step::kind_t kind;
    bool stays;
  };
  std::vector<row> rows{
    {"a plain request's response", false, false, false, true, step::reply,
     false},
    {"a plain request's error, even on a rebinding binding", false, false,
     true, false, step::reply, false},
    {"a reliable request's response", true, false, false, true, step::reply,
     false},
    {"apo_gone for a rebinding binding's reliable request", true, false, true,
     false, step::rebind, true},
    {"apo_gone for a reliable request of a plain binding", true, false, false,
     false, step::reply, false},
    {"an error for a reliable one-way message", true, true, true, false,
     step::none, false},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    env e;
    binding_table bindings;
    asl_outbox out;
    auto [id, binding] = bindings.add(t0);
    binding.rebind = r.rebind;
    outgoing_requests reqs{1, 10, e.rr, e.stats};
    auto rid = reqs.add(request(id, a, t0 + 9s, r.reliable)).first;
    reqs.find(rid)->oneway = r.oneway;
    auto result = reqs.on_response(a, r.ok ? fine(rid) : gone(rid), t0 + 30ms,
                                   bindings);
    EXPECT_EQ(result.kind, r.kind);
    EXPECT_EQ(reqs.find(rid) != nullptr, r.stays);
    EXPECT_EQ(e.stats.responses_received, r.kind == step::reply ? 1u : 0u);
    if (r.kind == step::rebind) {
      EXPECT_EQ(result.binding, id);
      EXPECT_TRUE(is(result.error, app_ec::apo_gone));
      EXPECT_EQ(reqs.find(rid)->tx.sends, 0u); // sent again when rebound
    }
    if (r.kind == step::reply) {
      EXPECT_EQ(result.out.binding, id);
    }
    // Reliable ones that ended are remembered: a copy of the answer is late.
    if (r.reliable && !r.stays) {
      reqs.on_response(a, fine(rid), t0 + 40ms, bindings);
      EXPECT_EQ(e.stats.late_duplicates, 1u);
    }
  }
}

} // namespace
