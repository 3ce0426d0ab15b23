// The publish/subscribe core (actors/topic_table.hpp), time passed in and
// the outbox read directly: advertisements, leases, late joiners, sequence
// numbers with lost and repeated publications, renewals, and both peer
// bounds with their counters.

#include <chrono>
#include <string>
#include <variant>
#include <vector>

#include "actors/app_support.hpp"
#include "actors/topic_table.hpp"
#include "tests/support/actor_fixture.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = topic_table::time_point;

const time_point t0{};

constexpr module_id a = 0x21;
constexpr module_id b = 0x22;
constexpr module_id c = 0x23;

asl_subscribe lease(const std::string& topic, uint32_t ms) {
  return asl_subscribe{topic, ms};
}

/// The outbox as (destination, kind, topic, seq) rows, then emptied.
struct sent {
  module_id dst;
  std::string kind;
  std::string topic;
  uint32_t seq_or_lease = 0;

  bool operator==(const sent& x) const {
    return dst == x.dst && kind == x.kind && topic == x.topic
           && seq_or_lease == x.seq_or_lease;
  }
};

std::ostream& operator<<(std::ostream& os, const sent& x) {
  return os << x.kind << " " << x.topic << " " << x.seq_or_lease << " to "
            << x.dst;
}

std::vector<sent> drain(asl_outbox& out) {
  std::vector<sent> result;
  for (auto& item : out.items) {
    sent s{item.dst, "?", "", 0};
    if (auto p = std::get_if<asl_publish>(&item.msg))
      s = {item.dst, "publish", p->topic, p->seq};
    else if (auto sub = std::get_if<asl_subscribe>(&item.msg))
      s = {item.dst, "subscribe", sub->topic, sub->lease_ms};
    else if (auto unsub = std::get_if<asl_unsubscribe>(&item.msg))
      s = {item.dst, "unsubscribe", unsub->topic, 0};
    else if (auto adv = std::get_if<asl_advertise>(&item.msg))
      s = {item.dst, "advertise", adv->topic, 0};
    result.push_back(s);
  }
  out.items.clear();
  return result;
}

class topic_table_test : public herm::test::actor_fixture {
public:
  caf::actor subscriber() {
    return track(sys().spawn([]() -> caf::behavior { return {[](int) {}}; }));
  }

  app_support_stats stats;
  asl_outbox out;
};

using rows = std::vector<sent>;

// -- publishing -----------------------------------------------------------------------

TEST_F(topic_table_test, publications_go_to_subscribed_modules_while_their_lease_holds) {
  topic_table tt{8, 3s, stats};
  tt.publish("t", caf::make_message(1), {1}, t0, out);
  EXPECT_EQ(drain(out), (rows{{broadcast_module, "advertise", "t", 0}}));
  // A late joiner gets the last value at once; a renewal does not.
  tt.on_subscribe(a, lease("t", 1000), t0, out);
  tt.on_subscribe(a, lease("t", 1000), t0 + 100ms, out);
  EXPECT_EQ(drain(out), (rows{{a, "publish", "t", 1}}));
  tt.on_subscribe(b, lease("t", 5000), t0, out);
  EXPECT_EQ(drain(out), (rows{{b, "publish", "t", 1}}));
  tt.publish("t", caf::make_message(2), {2}, t0 + 900ms, out);
  EXPECT_EQ(drain(out), (rows{{a, "publish", "t", 2}, {b, "publish", "t", 2}}));
  // a's lease (renewed at 100 ms) ended at 1100 ms.
  tt.publish("t", caf::make_message(3), {3}, t0 + 1200ms, out);
  EXPECT_EQ(drain(out), (rows{{b, "publish", "t", 3}}));
  tt.on_unsubscribe(b, asl_unsubscribe{"t"});
  tt.publish("t", caf::make_message(4), {4}, t0 + 1300ms, out);
  EXPECT_TRUE(drain(out).empty());
  EXPECT_EQ(stats.published, 4u);
  EXPECT_EQ(stats.publications_sent, 5u);
  EXPECT_EQ(tt.find("t")->seq, 4u);
  EXPECT_EQ(tt.find("t")->last.get_as<int>(0), 4);
}

TEST_F(topic_table_test, a_subscription_for_a_topic_not_published_here_is_ignored) {
  topic_table tt{8, 3s, stats};
  tt.on_subscribe(a, lease("t", 1000), t0, out);
  EXPECT_TRUE(drain(out).empty());
  EXPECT_EQ(tt.find("t"), nullptr);
}

TEST_F(topic_table_test, a_lease_is_cut_to_a_day) {
  topic_table tt{8, 3s, stats};
  tt.publish("t", caf::make_message(1), {1}, t0, out);
  tt.on_subscribe(a, lease("t", UINT32_MAX), t0, out);
  drain(out);
  EXPECT_EQ(tt.find("t")->remote_subs.at(a), t0 + 24h);
}

TEST_F(topic_table_test, remote_subscribers_per_topic_stay_within_the_bound) {
  topic_table tt{2, 3s, stats};
  tt.publish("t", caf::make_message(1), {1}, t0, out);
  for (auto m : {a, b, c})
    tt.on_subscribe(m, lease("t", 1000), t0, out);
  // a and b joined late and got the value; c was refused and got nothing.
  EXPECT_EQ(drain(out), (rows{{broadcast_module, "advertise", "t", 0},
                              {a, "publish", "t", 1},
                              {b, "publish", "t", 1}}));
  EXPECT_EQ(stats.subscribers_refused, 1u);
  // A renewal of a held lease always fits.
  tt.on_subscribe(a, lease("t", 1000), t0 + 1ms, out);
  EXPECT_EQ(stats.subscribers_refused, 1u);
}

// -- subscribing ----------------------------------------------------------------------

TEST_F(topic_table_test, the_first_local_subscriber_subscribes_the_module_and_the_last_unsubscribes_it) {
  topic_table tt{8, 3s, stats};
  auto s1 = subscriber();
  auto s2 = subscriber();
  ASSERT_NE(tt.subscribe("t", s1, t0, out), nullptr);
  EXPECT_EQ(drain(out), (rows{{broadcast_module, "subscribe", "t", 3000}}));
  EXPECT_EQ(tt.subscribe("t", s1, t0, out), nullptr); // already
  ASSERT_NE(tt.subscribe("t", s2, t0, out), nullptr);
  EXPECT_TRUE(drain(out).empty());
  tt.unsubscribe(s1.address(), nullptr, out);
  EXPECT_TRUE(drain(out).empty());
  tt.unsubscribe(s2.address(), nullptr, out);
  EXPECT_EQ(drain(out), (rows{{broadcast_module, "unsubscribe", "t", 0}}));
  EXPECT_EQ(tt.find("t"), nullptr); // neither subscribed nor published
}

TEST_F(topic_table_test, subscriptions_are_renewed_at_a_third_of_the_lease) {
  topic_table tt{8, 3s, stats};
  tt.subscribe("t", subscriber(), t0, out);
  drain(out);
  struct row {
    time_point now;
    size_t renewals;
  };
  std::vector<row> steps{{t0 + 999ms, 0}, {t0 + 1s, 1}, {t0 + 1999ms, 0},
                         {t0 + 2s, 1}};
  for (auto& r : steps) {
    tt.housekeep(r.now, out);
    EXPECT_EQ(drain(out).size(), r.renewals);
  }
  // A publisher that advertises hears from this subscriber at once.
  tt.on_advertise(b, asl_advertise{"t"}, t0 + 2100ms, out);
  tt.on_advertise(b, asl_advertise{"other"}, t0 + 2100ms, out);
  EXPECT_EQ(drain(out), (rows{{b, "subscribe", "t", 3000}}));
}

TEST_F(topic_table_test, sequence_numbers_drop_repeats_and_count_gaps) {
  topic_table tt{8, 3s, stats};
  auto s = subscriber();
  tt.subscribe("t", s, t0, out);
  struct row {
    module_id src;
    uint32_t seq;
    bool delivered;
    uint64_t lost;
  };
  std::vector<row> rows_{
    {a, 5, true, 0},  // the first from a: taken as it is
    {a, 5, false, 0}, // the same value again (a late joiner's copy)
    {a, 6, true, 0},  {a, 9, true, 2}, // 7 and 8 lost
    {b, 1, true, 2},  // another publisher, tracked on its own
    {a, 4, true, 2},  // older: delivered, nothing counted
  };
  for (auto& r : rows_) {
    SCOPED_TRACE(std::to_string(r.src) + ":" + std::to_string(r.seq));
    auto subs = tt.on_publish(r.src, asl_publish{"t", r.seq, {}});
    EXPECT_EQ(subs != nullptr, r.delivered);
    if (subs != nullptr) {
      ASSERT_EQ(subs->local_subs.size(), 1u);
      EXPECT_EQ(subs->local_subs.front(), s);
    }
    EXPECT_EQ(stats.publications_lost, r.lost);
  }
  EXPECT_EQ(stats.publications_received, rows_.size());
  EXPECT_EQ(tt.on_publish(a, asl_publish{"unknown", 1, {}}), nullptr);
}

TEST_F(topic_table_test, publishers_tracked_per_topic_stay_within_the_bound) {
  topic_table tt{2, 3s, stats};
  tt.subscribe("t", subscriber(), t0, out);
  for (auto m : {a, b, c})
    EXPECT_NE(tt.on_publish(m, asl_publish{"t", 1, {}}), nullptr);
  EXPECT_EQ(stats.publishers_refused, 1u);
  // c is not tracked: its repeat is delivered again (and counted again).
  EXPECT_NE(tt.on_publish(c, asl_publish{"t", 1, {}}), nullptr);
  EXPECT_EQ(stats.publishers_refused, 2u);
  // A module gone frees its place.
  tt.module_lost(a);
  EXPECT_NE(tt.on_publish(c, asl_publish{"t", 1, {}}), nullptr);
  EXPECT_EQ(tt.on_publish(c, asl_publish{"t", 1, {}}), nullptr);
  EXPECT_EQ(stats.publishers_refused, 2u);
}

// -- sample subscribers and the list ---------------------------------------------------

TEST_F(topic_table_test, a_sample_subscriber_subscribes_once_with_a_typed_one) {
  topic_table tt{8, 3s, stats};
  auto typed = subscriber();
  auto tool = subscriber();
  ASSERT_NE(tt.subscribe("t", tool, t0, out, true), nullptr);
  EXPECT_EQ(drain(out), (rows{{broadcast_module, "subscribe", "t", 3000}}));
  // Already subscribed in that mode: nullptr; the other mode joins quietly.
  EXPECT_EQ(tt.subscribe("t", tool, t0, out, true), nullptr);
  ASSERT_NE(tt.subscribe("t", typed, t0, out), nullptr);
  EXPECT_TRUE(drain(out).empty());
  auto t = tt.on_publish(a, asl_publish{"t", 1, {}});
  ASSERT_NE(t, nullptr);
  EXPECT_EQ(t->local_subs, topic_table::subscribers{typed});
  EXPECT_EQ(t->sample_subs, topic_table::subscribers{tool});
  // The network subscription ends with the last subscriber of either kind.
  tt.unsubscribe(typed.address(), nullptr, out);
  EXPECT_TRUE(drain(out).empty());
  tt.unsubscribe(tool.address(), nullptr, out);
  EXPECT_EQ(drain(out), (rows{{broadcast_module, "unsubscribe", "t", 0}}));
  EXPECT_EQ(tt.find("t"), nullptr);
}

TEST_F(topic_table_test, the_list_shows_both_sides_and_the_last_type) {
  topic_table tt{8, 3s, stats};
  // 01 01 04 "@u16" 07 00: one @u16.
  byte_buffer u16{0x01, 0x01, 0x04, '@', 'u', '1', '6', 0x07, 0x00};
  tt.publish("out", caf::make_message(uint16_t{7}), u16, t0, out);
  tt.on_subscribe(b, lease("out", 3000), t0, out);
  tt.subscribe("in", subscriber(), t0, out, true);
  tt.on_publish(c, asl_publish{"in", 4, {0x01, 0x01, 0x04, '@', 's', 't', 'r', 0x00}});
  auto rows_ = tt.list();
  ASSERT_EQ(rows_.size(), 2u);
  EXPECT_EQ(rows_[0].topic, "in");
  EXPECT_FALSE(rows_[0].publishing);
  EXPECT_EQ(rows_[0].local_subscribers, 1u);
  EXPECT_EQ(rows_[0].publishers, std::vector<module_id>{c});
  EXPECT_EQ(rows_[0].type, "@str");
  EXPECT_EQ(rows_[1].topic, "out");
  EXPECT_TRUE(rows_[1].publishing);
  EXPECT_EQ(rows_[1].seq, 1u);
  EXPECT_EQ(rows_[1].remote_subscribers, std::vector<module_id>{b});
  EXPECT_EQ(rows_[1].type, "@u16");
}

} // namespace
