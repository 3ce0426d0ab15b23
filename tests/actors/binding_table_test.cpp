// The bindings of proxies to remote APOs (actors/binding_table.hpp), time
// passed in and the outbox read directly: watches and their renewal,
// losing a target with and without rebinding, the last binding to an APO
// ending its watch, and the searches of rebinding proxies.

#include <gtest/gtest.h>

#include <chrono>
#include <variant>
#include <vector>

#include "actors/binding_table.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = binding_table::time_point;

const time_point t0{};

constexpr module_id self = 0x10;
constexpr module_id a = 0x21;

apo_ref remote(uint32_t apo) {
  return apo_ref{a, apo, "echo", "demo.echo"};
}

/// The watches (+apo) and unwatches (-apo) in the outbox, then empties it.
std::vector<int64_t> watches(asl_outbox& out) {
  std::vector<int64_t> result;
  for (auto& item : out.items) {
    EXPECT_EQ(item.dst, a);
    if (auto w = std::get_if<asl_watch>(&item.msg))
      result.push_back(w->apo);
    else if (auto u = std::get_if<asl_unwatch>(&item.msg))
      result.push_back(-int64_t{u->apo});
  }
  out.items.clear();
  return result;
}

TEST(binding_table, ids_start_at_one_and_are_never_reused) {
  binding_table bt;
  asl_outbox out;
  auto first = bt.add(t0).first;
  auto second = bt.add(t0).first;
  EXPECT_EQ(first, 1u);
  EXPECT_EQ(second, 2u);
  bt.close(first, self, out);
  EXPECT_EQ(bt.add(t0).first, 3u);
  EXPECT_EQ(bt.find(first), nullptr);
  EXPECT_EQ(bt.all().size(), 2u);
}

TEST(binding_table, a_remote_target_is_watched_and_the_watch_renewed) {
  binding_table bt;
  asl_outbox out;
  auto [id, b] = bt.add(t0);
  binding_table::bind(b, remote(7), self, t0, out);
  EXPECT_EQ(watches(out), (std::vector<int64_t>{7}));
  auto [local_id, local] = bt.add(t0);
  binding_table::bind(local, apo_ref{self, 9, "x", "y"}, self, t0, out);
  EXPECT_TRUE(watches(out).empty()); // a local APO needs no watch
  struct row {
    time_point now;
    std::vector<int64_t> renewed;
  };
  std::vector<row> rows{{t0 + 4999ms, {}}, {t0 + 5s, {7}},
                        {t0 + 9999ms, {}}, {t0 + 10s, {7}}};
  for (auto& r : rows) {
    EXPECT_TRUE(bt.housekeep(r.now, 5s, 1s, self, out).empty());
    EXPECT_EQ(watches(out), r.renewed);
  }
  EXPECT_EQ(bt.bound_to(a, 7), (std::vector<uint32_t>{id}));
  EXPECT_EQ(bt.bound_to(a, 0), (std::vector<uint32_t>{id}));
  EXPECT_EQ(bt.bound_to(self, 0), (std::vector<uint32_t>{local_id}));
  EXPECT_TRUE(bt.bound_to(a, 8).empty());
}

TEST(binding_table, only_the_last_binding_to_an_apo_ends_its_watch) {
  binding_table bt;
  asl_outbox out;
  auto [one, b1] = bt.add(t0);
  binding_table::bind(b1, remote(7), self, t0, out);
  auto [two, b2] = bt.add(t0);
  binding_table::bind(b2, remote(7), self, t0, out);
  watches(out);
  bt.close(one, self, out);
  EXPECT_TRUE(watches(out).empty());
  bt.close(two, self, out);
  EXPECT_EQ(watches(out), (std::vector<int64_t>{-7}));
  bt.close(two, self, out); // gone already
  EXPECT_TRUE(watches(out).empty());
}

TEST(binding_table, a_lost_target_ends_a_binding_unless_it_rebinds) {
  binding_table bt;
  asl_outbox out;
  auto [plain, p] = bt.add(t0);
  binding_table::bind(p, remote(7), self, t0, out);
  auto [rebinding, r] = bt.add(t0);
  r.rebind = true;
  binding_table::bind(r, remote(8), self, t0, out);
  // No proxy was ever made here, so there is none to end.
  EXPECT_EQ(bt.lose(plain, t0 + 1s), nullptr);
  EXPECT_EQ(bt.find(plain), nullptr);
  EXPECT_EQ(bt.lose(rebinding, t0 + 1s), nullptr);
  ASSERT_NE(bt.find(rebinding), nullptr);
  EXPECT_FALSE(bt.find(rebinding)->bound);
  EXPECT_EQ(bt.find(rebinding)->next_search, t0 + 1s);
  EXPECT_TRUE(bt.take_proxies().empty());
  EXPECT_TRUE(bt.all().empty());
}

TEST(binding_table, a_rebinding_binding_searches_until_it_finds_a_target) {
  binding_table bt;
  asl_outbox out;
  auto [id, b] = bt.add(t0);
  b.rebind = true;
  b.by = query_by::type;
  b.pattern = "demo.echo";
  auto searches = bt.housekeep(t0, 5s, 1s, self, out);
  ASSERT_EQ(searches.size(), 1u);
  EXPECT_EQ(searches[0].id, id);
  EXPECT_EQ(searches[0].query.by, query_by::type);
  EXPECT_EQ(searches[0].query.pattern, "demo.echo");
  EXPECT_EQ(searches[0].query.timeout_ms, 500u); // half the interval
  EXPECT_TRUE(searches[0].query.first);
  // Searching: not started again.
  EXPECT_TRUE(bt.housekeep(t0 + 100ms, 5s, 1s, self, out).empty());
  // Nothing found: the next search is due an interval later.
  EXPECT_FALSE(bt.found(id, {}, self, t0 + 500ms, 1s, out));
  EXPECT_TRUE(bt.housekeep(t0 + 1499ms, 5s, 1s, self, out).empty());
  EXPECT_EQ(bt.housekeep(t0 + 1500ms, 5s, 1s, self, out).size(), 1u);
  // Found: bound and watched.
  EXPECT_TRUE(bt.found(id, {remote(3), remote(4)}, self, t0 + 2s, 1s, out));
  EXPECT_EQ(watches(out), (std::vector<int64_t>{3}));
  EXPECT_EQ(bt.find(id)->target, remote(3));
  // A late search result changes nothing.
  EXPECT_FALSE(bt.found(id, {remote(5)}, self, t0 + 2s, 1s, out));
  EXPECT_FALSE(bt.found(99, {remote(5)}, self, t0 + 2s, 1s, out));
  EXPECT_EQ(bt.find(id)->target, remote(3));
}

} // namespace
