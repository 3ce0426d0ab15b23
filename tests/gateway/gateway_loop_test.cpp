// The gateway in one process with a real module and a real DDS participant
// of the test's own: values cross once each way on a `both` mapping and
// never loop back through the gateway; HERM values of the wrong type are
// dropped and counted. Bounded waits; nothing asserts on timing.

#include <gtest/gtest.h>

#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"

#include "actors/module.hpp"
#include "actors/runtime/system.hpp"
#include "actors/type_description.hpp"
#include "apps/dds_gateway/gateway.hpp"
#include "apps/dds_gateway/types.hpp"
#include "apps/hermd/srf04.hpp"
#include "apps/hermd/testbed_types.hpp"

#include "std_msgs/Basic.h"

using namespace herm;
using namespace std::chrono_literals;

namespace {

const char* loopback_only
  = "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name=\"lo\"/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<Peers><Peer address=\"127.0.0.1\"/></Peers><ParticipantIndex>auto"
    "</ParticipantIndex></Discovery></Domain></CycloneDDS>";

/// Polls `done` every 10 ms for at most 20 s.
bool eventually(const std::function<bool()>& done) {
  for (int i = 0; i < 2000; ++i) {
    if (done())
      return true;
    std::this_thread::sleep_for(10ms);
  }
  return false;
}

struct seen {
  std::mutex mtx;
  std::vector<std::string> values;

  size_t count(const std::string& x) {
    std::lock_guard<std::mutex> guard{mtx};
    return static_cast<size_t>(std::count(values.begin(), values.end(), x));
  }
};

class gateway_loop_test : public ::testing::Test {
protected:
  gateway_loop_test() : sys_{init(cfg_)} {
    // nop
  }

  static caf::actor_system_config& init(caf::actor_system_config& cfg) {
    ::setenv("CYCLONEDDS_URI", loopback_only, 1);
    configure(cfg);
    cfg.add_message_types<caf::id_block::herm_apos>();
    dds_gateway::add_gateway_types(cfg);
    return cfg;
  }

  void SetUp() override {
    domain_ = 1 + static_cast<uint32_t>((::getpid() + 100) % 200);
    module_config mc;
    mc.routing.id = 0x41;
    auto m = run_module(sys_, mc);
    ASSERT_TRUE(m) << render(m.error());
    module_ = std::move(*m);
    pp_ = dds_create_participant(domain_, nullptr, nullptr);
    ASSERT_GT(pp_, 0) << dds_strretcode(pp_);
  }

  void TearDown() override {
    // The actor system waits for every actor when it ends.
    if (gw_)
      caf::anon_send_exit(gw_, caf::exit_reason::user_shutdown);
    for (auto& sub : subs_)
      caf::anon_send_exit(sub, caf::exit_reason::user_shutdown);
    if (pp_ > 0)
      dds_delete(pp_);
  }

  void start(const std::map<std::string, std::string>& options) {
    auto o = options;
    o["domain"] = std::to_string(domain_);
    auto cfg = dds_gateway::parse_gateway_options(o);
    ASSERT_TRUE(cfg) << render(cfg.error());
    const module_handles& h = module_.handles();
    auto gw = dds_gateway::spawn_dds_gateway(sys_, h, *cfg);
    ASSERT_TRUE(gw) << render(gw.error());
    gw_ = *gw;
  }

  dds_gateway::gateway_stats stats() {
    dds_gateway::gateway_stats out;
    caf::scoped_actor self{sys_};
    self->request(gw_, 5s, atom::get_v, atom::stats_v)
      .receive([&](const dds_gateway::gateway_stats& s) { out = s; },
               [](caf::error& err) { FAIL() << render(err); });
    return out;
  }

  /// Waits until `topic` has a local subscriber (the gateway subscribes
  /// after it starts, asynchronously).
  bool subscribed(const std::string& topic) {
    return eventually([&] {
      bool yes = false;
      caf::scoped_actor self{sys_};
      const module_handles& h = module_.handles();
      self->request(h.apps, 5s, atom::get_v, atom::topics_v)
        .receive(
          [&](const std::vector<topic_info>& rows) {
            for (auto& r : rows)
              yes = yes || (r.topic == topic && r.local_subscribers > 0);
          },
          [](caf::error&) {});
      return yes;
    });
  }

  /// A HERM subscriber of `topic` that records every value it gets, as
  /// CAF prints it, into `into`.
  void subscribe_any(const std::string& topic, seen& into) {
    auto sub = sys_.spawn([&into](caf::event_based_actor* self) -> caf::behavior {
      self->set_default_handler(
        [&into](caf::scheduled_actor*, caf::message_view& x) -> caf::result<caf::message> {
          std::lock_guard<std::mutex> guard{into.mtx};
          into.values.push_back(caf::to_string(x.copy_content_to_message()));
          return caf::message{};
        });
      return {[](caf::unit_t) {}};
    });
    subs_.push_back(sub);
    caf::scoped_actor self{sys_};
    const module_handles& h = module_.handles();
    self->request(h.apps, 5s, atom::subscribe_v, topic, sub)
      .receive([] {}, [](caf::error& err) { FAIL() << render(err); });
  }

  /// A HERM subscriber of `topic` that records strings into `into`.
  void subscribe(const std::string& topic, seen& into) {
    auto sub = sys_.spawn([&into](caf::event_based_actor*) -> caf::behavior {
      return {[&into](const std::string& x) {
        std::lock_guard<std::mutex> guard{into.mtx};
        into.values.push_back(x);
      }};
    });
    subs_.push_back(sub);
    caf::scoped_actor self{sys_};
    const module_handles& h = module_.handles();
    self->request(h.apps, 5s, atom::subscribe_v, topic, sub)
      .receive([] {}, [](caf::error& err) { FAIL() << render(err); });
  }

  caf::actor_system_config cfg_;
  caf::actor_system sys_;
  running_module module_;
  caf::actor gw_;
  std::vector<caf::actor> subs_;
  uint32_t domain_ = 0;
  dds_entity_t pp_ = 0;
};

/// Our writer and reader of one topic (in one participant) matched the
/// gateway's: each matches the other and the gateway's end, two each.
bool matched_with_the_gateway(dds_entity_t writer, dds_entity_t reader) {
  return eventually([&] {
    dds_publication_matched_status_t p;
    dds_subscription_matched_status_t q;
    return dds_get_publication_matched_status(writer, &p) == 0
           && p.current_count >= 2
           && dds_get_subscription_matched_status(reader, &q) == 0
           && q.current_count >= 2;
  });
}

/// Every string a reader holds, taken.
std::vector<std::string> take_strings(dds_entity_t reader) {
  std::vector<std::string> out;
  void* samples[8] = {nullptr};
  dds_sample_info_t infos[8];
  auto n = dds_take(reader, samples, infos, 8, 8);
  for (int i = 0; i < n; ++i)
    if (infos[i].valid_data)
      out.emplace_back(static_cast<std_msgs_msg_dds__String_*>(samples[i])->data);
  if (n > 0)
    dds_return_loan(reader, samples, n);
  return out;
}

} // namespace

TEST_F(gateway_loop_test, a_both_mapping_carries_each_value_once_each_way) {
  start({{"chat.type", "std_msgs/msg/String"}, {"chat.direction", "both"}});
  ASSERT_TRUE(subscribed("chat")); // the gateway's HERM side is listening
  seen herm_side;
  subscribe("chat", herm_side);
  auto topic = dds_create_topic(pp_, &std_msgs_msg_dds__String__desc, "rt/chat",
                                nullptr, nullptr);
  ASSERT_GT(topic, 0);
  auto reader = dds_create_reader(pp_, topic, nullptr, nullptr);
  auto writer = dds_create_writer(pp_, topic, nullptr, nullptr);
  ASSERT_GT(reader, 0);
  ASSERT_GT(writer, 0);
  ASSERT_TRUE(matched_with_the_gateway(writer, reader));
  // HERM -> DDS, once.
  const module_handles& h = module_.handles();
  caf::anon_send(h.apps, atom::publish_v, std::string{"chat"},
                 caf::make_message(std::string{"from herm"}));
  std::vector<std::string> on_dds;
  ASSERT_TRUE(eventually([&] {
    for (auto& x : take_strings(reader))
      on_dds.push_back(x);
    return !on_dds.empty();
  }));
  EXPECT_EQ(on_dds, std::vector<std::string>{"from herm"});
  // DDS -> HERM, once, and not written back to DDS: the gateway takes its
  // own publication for what it is.
  std_msgs_msg_dds__String_ sample{const_cast<char*>("from dds")};
  ASSERT_EQ(dds_write(writer, &sample), 0);
  ASSERT_TRUE(eventually([&] { return herm_side.count("from dds") == 1; }));
  ASSERT_TRUE(eventually([&] { return stats().looped_back == 1; }));
  auto st = stats();
  EXPECT_EQ(st.to_dds, 1u);   // "from herm" only
  EXPECT_EQ(st.from_dds, 1u); // "from dds" only: its own write never came in
  EXPECT_EQ(st.dds_rejected, 0u);
  EXPECT_EQ(herm_side.count("from herm"), 1u);
}

TEST_F(gateway_loop_test, a_herm_value_of_the_wrong_type_is_dropped_and_counted) {
  start({{"level.type", "std_msgs/msg/Int32"}});
  auto topic = dds_create_topic(pp_, &std_msgs_msg_dds__Int32__desc, "rt/level",
                                nullptr, nullptr);
  auto reader = dds_create_reader(pp_, topic, nullptr, nullptr);
  ASSERT_GT(reader, 0);
  ASSERT_TRUE(eventually([&] {
    dds_subscription_matched_status_t s;
    return dds_get_subscription_matched_status(reader, &s) == 0
           && s.current_count > 0;
  }));
  const module_handles& h = module_.handles();
  auto publish = [&](caf::message x) {
    caf::anon_send(h.apps, atom::publish_v, std::string{"level"},
                   std::move(x));
  };
  // The gateway subscribes once it runs: publish until a value crossed.
  ASSERT_TRUE(eventually([&] {
    publish(caf::make_message(int32_t{7}));
    return stats().to_dds > 0;
  }));
  publish(caf::make_message(2.5)); // a double, not an int32_t
  publish(caf::make_message(int32_t{8}));
  std::vector<int32_t> got;
  ASSERT_TRUE(eventually([&] {
    void* samples[4] = {nullptr};
    dds_sample_info_t infos[4];
    auto n = dds_take(reader, samples, infos, 4, 4);
    for (int i = 0; i < n; ++i)
      if (infos[i].valid_data)
        got.push_back(static_cast<std_msgs_msg_dds__Int32_*>(samples[i])->data);
    if (n > 0)
      dds_return_loan(reader, samples, n);
    return !got.empty() && got.back() == 8;
  }));
  // The 7s, then the 8; the double, handled before the 8, was dropped and
  // counted and never reached DDS.
  for (size_t i = 0; i + 1 < got.size(); ++i)
    EXPECT_EQ(got[i], 7);
  EXPECT_EQ(stats().herm_rejected, 1u);
}

TEST_F(gateway_loop_test, the_gateway_types_are_described_for_tools) {
  // add_gateway_types ran in the fixture's set-up.
  auto d = find_description("herm::dds_gateway::twist");
  ASSERT_TRUE(d);
  ASSERT_EQ(d->fields.size(), 2u);
  EXPECT_EQ(d->fields[0].name, "linear");
  EXPECT_EQ(d->fields[1].name, "angular");
  EXPECT_TRUE(find_description("herm::dds_gateway::vector3"));
}

// Every shipped type crosses real DDS both ways: a HERM value goes out as a
// DDS sample, and that very sample written back by another DDS writer
// comes in as the HERM value the type's table says.
TEST_F(gateway_loop_test, every_shipped_type_crosses_dds_both_ways) {
  using herm::hermd::srf04_reading;
  using herm::hermd::vision_frame;
  struct {
    const char* type;
    caf::message out; // published on HERM
    caf::message in;  // what the sample becomes, back from DDS
  } cases[] = {
    {"std_msgs/msg/String", caf::make_message(std::string{"hi"}),
     caf::make_message(std::string{"hi"})},
    {"std_msgs/msg/Float64", caf::make_message(2.5), caf::make_message(2.5)},
    {"std_msgs/msg/Int32", caf::make_message(int32_t{-7}),
     caf::make_message(int32_t{-7})},
    // seq counts the mapping's samples; echo_us follows the distance.
    {"sensor_msgs/msg/Range", caf::make_message(srf04_reading{9, 1234, 1}),
     caf::make_message(srf04_reading{0, 1234, 1234 * 2000 / 343})},
    // The source becomes the mapping's frame id (its topic by default).
    {"sensor_msgs/msg/Image", caf::make_message(vision_frame{"cam", 5, {1, 2, 3}}),
     caf::make_message(vision_frame{"t4", 0, {1, 2, 3}})},
    {"geometry_msgs/msg/Twist",
     caf::make_message(dds_gateway::twist{{0.5, 0, 0}, {0, 0, -1}}),
     caf::make_message(dds_gateway::twist{{0.5, 0, 0}, {0, 0, -1}})},
  };
  ASSERT_EQ(std::size(cases), dds_gateway::ros_types().size());
  std::map<std::string, std::string> opts;
  for (size_t i = 0; i < std::size(cases); ++i) {
    opts["t" + std::to_string(i) + ".type"] = cases[i].type;
    opts["t" + std::to_string(i) + ".direction"] = "both";
  }
  start(opts);
  // The subscribers write into these until the test ends.
  std::vector<seen> sides(std::size(cases));
  for (size_t i = 0; i < std::size(cases); ++i) {
    auto& c = cases[i];
    SCOPED_TRACE(c.type);
    auto name = "t" + std::to_string(i);
    auto& herm_side = sides[i];
    // The gateway's own subscription first (ours would satisfy the wait).
    ASSERT_TRUE(subscribed(name));
    subscribe_any(name, herm_side);
    auto* t = dds_gateway::find_ros_type(c.type);
    ASSERT_NE(t, nullptr);
    auto topic = dds_create_topic(pp_, t->descriptor, ("rt/" + name).c_str(),
                                  nullptr, nullptr);
    ASSERT_GT(topic, 0);
    auto reader = dds_create_reader(pp_, topic, nullptr, nullptr);
    auto writer = dds_create_writer(pp_, topic, nullptr, nullptr);
    ASSERT_TRUE(matched_with_the_gateway(writer, reader));
    const module_handles& h = module_.handles();
    caf::anon_send(h.apps, atom::publish_v, name, c.out);
    // HERM -> DDS: the sample, written straight back from our writer.
    bool echoed = eventually([&] {
      void* samples[1] = {nullptr};
      dds_sample_info_t info;
      auto n = dds_take(reader, samples, &info, 1, 1);
      bool ok = n == 1 && info.valid_data && dds_write(writer, samples[0]) == 0;
      if (n > 0)
        dds_return_loan(reader, samples, n);
      return ok;
    });
    ASSERT_TRUE(echoed);
    // DDS -> HERM: after the local publication, the value from DDS.
    auto values = [&] {
      std::lock_guard<std::mutex> guard{herm_side.mtx};
      return herm_side.values;
    };
    ASSERT_TRUE(eventually([&] { return values().size() >= 2; }));
    std::this_thread::sleep_for(50ms); // nothing more comes
    EXPECT_EQ(values(), (std::vector<std::string>{caf::to_string(c.out),
                                                   caf::to_string(c.in)}));
  }
  auto st = stats();
  EXPECT_EQ(st.to_dds, std::size(cases));
  EXPECT_EQ(st.from_dds, std::size(cases));
  EXPECT_EQ(st.dds_rejected, 0u);
  EXPECT_EQ(st.herm_rejected, 0u);
}

// durability: transient_local keeps the last `depth` samples for readers
// that join later, as a ROS 2 latched topic does; volatile does not.
TEST_F(gateway_loop_test, a_transient_local_mapping_serves_a_late_reader) {
  start({{"latched.type", "std_msgs/msg/String"},
         {"latched.durability", "transient_local"},
         {"latched.depth", "1"},
         {"plain.type", "std_msgs/msg/String"}});
  ASSERT_TRUE(subscribed("latched") && subscribed("plain"));
  const module_handles& h = module_.handles();
  for (auto t : {"latched", "plain"})
    for (auto v : {"first", "last"})
      caf::anon_send(h.apps, atom::publish_v, std::string{t},
                     caf::make_message(std::string{v}));
  ASSERT_TRUE(eventually([&] { return stats().to_dds == 4; }));
  // Readers that join now, asking for what was kept.
  auto* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
  auto reader_of = [&](const char* name) {
    auto topic = dds_create_topic(pp_, &std_msgs_msg_dds__String__desc, name,
                                  nullptr, nullptr);
    return dds_create_reader(pp_, topic, qos, nullptr);
  };
  auto latched = reader_of("rt/latched");
  // A transient_local reader does not match a volatile writer: a plain
  // reader for the volatile one.
  auto plain_topic = dds_create_topic(pp_, &std_msgs_msg_dds__String__desc,
                                      "rt/plain", nullptr, nullptr);
  auto plain = dds_create_reader(pp_, plain_topic, nullptr, nullptr);
  dds_delete_qos(qos);
  ASSERT_GT(latched, 0);
  ASSERT_GT(plain, 0);
  std::vector<std::string> got;
  ASSERT_TRUE(eventually([&] {
    for (auto& x : take_strings(latched))
      got.push_back(x);
    return !got.empty();
  }));
  EXPECT_EQ(got, std::vector<std::string>{"last"}); // depth 1: the last only
  // The volatile mapping kept nothing for a late reader (given time to
  // match and deliver, as the latched one did).
  ASSERT_TRUE(eventually([&] {
    dds_subscription_matched_status_t q;
    return dds_get_subscription_matched_status(plain, &q) == 0 && q.current_count > 0;
  }));
  std::this_thread::sleep_for(200ms);
  EXPECT_TRUE(take_strings(plain).empty());
}
