// Discovery (actors/discovery_table.hpp), time passed in and the outbox
// read directly: queries only when needed, answers split at
// max_answer_entries, matches collected and learned within their bounds,
// local matches first.

#include <gtest/gtest.h>

#include <chrono>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include "actors/discovery_table.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = discovery_table::time_point;

const time_point t0{};

constexpr module_id self = 0x10;
constexpr module_id a = 0x21;
constexpr module_id b = 0x22;

asl_entry entry(uint32_t apo, std::string name, std::string type = "t") {
  return asl_entry{apo, std::move(name), std::move(type)};
}

struct fixture {
  app_support_stats stats;
  app_table table{7};
  discovery_table dt{9, 2, table, stats};
  asl_outbox out;
  std::vector<apo_ref> result;

  discovery_table::callback keep() {
    return [this](std::vector<apo_ref> found) { result = std::move(found); };
  }
};

TEST(discovery_table, a_first_match_found_here_needs_no_query) {
  fixture f;
  auto mine = f.table.add_local("echo", "demo.echo");
  auto qid = f.dt.start(apo_query{query_by::name, "echo", 500, true}, self,
                        f.keep(), f.out);
  EXPECT_NE(qid, 0u);
  EXPECT_TRUE(f.dt.satisfied(qid));
  EXPECT_TRUE(f.out.items.empty());
  EXPECT_EQ(f.stats.queries_sent, 0u);
  auto done = f.dt.finish(qid, self);
  ASSERT_TRUE(done);
  done->finish(std::move(done->found));
  EXPECT_EQ(f.result, (std::vector<apo_ref>{{self, mine, "echo", "demo.echo"}}));
  EXPECT_FALSE(f.dt.finish(qid, self)); // ended
}

TEST(discovery_table, answers_are_collected_and_learned_within_their_bounds) {
  fixture f; // both bounds: 2
  auto mine = f.table.add_local("x", "t");
  auto qid = f.dt.start(apo_query{query_by::type, "t", 500, false}, self,
                        f.keep(), f.out);
  ASSERT_EQ(f.out.items.size(), 1u);
  EXPECT_EQ(f.out.items[0].dst, broadcast_module);
  EXPECT_EQ(std::get<asl_query>(f.out.items[0].msg),
            (asl_query{qid, query_by::type, "t"}));
  EXPECT_EQ(f.stats.queries_sent, 1u);
  struct row {
    module_id src;
    std::vector<asl_entry> entries;
    size_t remotes;
    uint64_t table_refused;
    uint64_t discovery_refused;
  };
  std::vector<row> rows{
    // a matching and a non-matching entry: both learned, one collected
    // (with the local one, 2: the discovery is full).
    {a, {entry(1, "a1"), entry(2, "a2", "other")}, 2, 0, 0},
    // b's entries: the table is full (refused), and so is the discovery.
    {b, {entry(3, "b3")}, 2, 1, 1},
    // a's again: refreshed entries always fit; a:1 is collected already.
    {a, {entry(1, "a1")}, 2, 1, 1},
  };
  for (auto& r : rows) {
    EXPECT_FALSE(f.dt.on_answer(r.src, asl_answer{qid, r.entries}, t0));
    EXPECT_EQ(f.table.remotes().size(), r.remotes);
    EXPECT_EQ(f.stats.remote_apos_refused, r.table_refused);
    EXPECT_EQ(f.stats.discovery_entries_refused, r.discovery_refused);
  }
  EXPECT_EQ(f.stats.answers_received, 3u);
  auto done = f.dt.finish(qid, self);
  ASSERT_TRUE(done);
  EXPECT_EQ(done->found, (std::vector<apo_ref>{{self, mine, "x", "t"},
                                               {a, 1, "a1", "t"}}));
}

TEST(discovery_table, the_first_remote_match_satisfies_a_first_discovery) {
  fixture f;
  auto qid = f.dt.start(apo_query{query_by::name, "e", 500, true}, self,
                        f.keep(), f.out);
  EXPECT_FALSE(f.dt.on_answer(a, asl_answer{qid, {entry(1, "other")}}, t0));
  EXPECT_TRUE(f.dt.on_answer(b, asl_answer{qid, {entry(2, "e")}}, t0));
  // An answer to a query not running (ended, or forged) collects nothing.
  EXPECT_FALSE(f.dt.on_answer(a, asl_answer{qid + 1, {entry(3, "e")}}, t0));
  EXPECT_EQ(f.dt.running(), (std::vector<uint32_t>{qid}));
}

TEST(discovery_table, query_ids_are_distinct_and_never_zero) {
  fixture f;
  std::set<uint32_t> ids;
  for (int i = 0; i < 100; ++i)
    ids.insert(f.dt.start(apo_query{query_by::name, "n", 500, false}, self,
                          f.keep(), f.out));
  EXPECT_EQ(ids.size(), 100u);
  EXPECT_EQ(ids.count(0), 0u);
  EXPECT_EQ(f.dt.running().size(), 100u);
}

TEST(discovery_table, queries_are_answered_in_parts_of_at_most_max_answer_entries) {
  struct row {
    size_t matching;
    std::vector<size_t> parts;
  };
  std::vector<row> rows{
    {0, {}}, {1, {1}}, {max_answer_entries, {max_answer_entries}},
    {max_answer_entries + 6, {max_answer_entries, 6}},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.matching);
    fixture f;
    f.table.add_local("unrelated", "u");
    for (size_t i = 0; i < r.matching; ++i)
      f.table.add_local("n" + std::to_string(i), "t");
    f.dt.on_query(a, asl_query{77, query_by::type, "t"}, f.out);
    std::vector<size_t> parts;
    for (auto& item : f.out.items) {
      EXPECT_EQ(item.dst, a);
      auto& ans = std::get<asl_answer>(item.msg);
      EXPECT_EQ(ans.query_id, 77u);
      parts.push_back(ans.entries.size());
    }
    EXPECT_EQ(parts, r.parts);
    EXPECT_EQ(f.stats.queries_answered, r.matching > 0 ? 1u : 0u);
  }
}

} // namespace
