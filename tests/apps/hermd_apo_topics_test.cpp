// hermd's testbed APOs publish their data on HERM topics as well as sending
// it to their target: srf04_batcher each reading on `sonar`, vision_source
// each frame on `vision` (option `topic`: another name, or "" / off for
// none). A real module in one process, the APOs made by hermd's own kind
// registry, a subscriber and a stand-in collector of the test's. Bounded
// waits; nothing asserts on timing.

#include <gtest/gtest.h>

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
#include "apps/hermd/apo_kinds.hpp"
#include "apps/hermd/testbed_types.hpp"

using namespace herm;
using namespace std::chrono_literals;
using hermd::sonar_batch;
using hermd::srf04_reading;
using hermd::vision_frame;

namespace {

/// Polls `done` every 10 ms for at most 20 s.
bool eventually(const std::function<bool()>& done) {
  for (int i = 0; i < 2000; ++i) {
    if (done())
      return true;
    std::this_thread::sleep_for(10ms);
  }
  return false;
}

/// What an actor of the test received, shared with the test's thread.
template <class T>
struct seen {
  std::mutex mtx;
  std::vector<T> values;

  size_t size() {
    std::lock_guard<std::mutex> guard{mtx};
    return values.size();
  }

  std::vector<T> all() {
    std::lock_guard<std::mutex> guard{mtx};
    return values;
  }
};

class hermd_apo_topics_test : public ::testing::Test {
protected:
  hermd_apo_topics_test() : sys_{init(cfg_)} {
    // nop
  }

  static caf::actor_system_config& init(caf::actor_system_config& cfg) {
    configure(cfg);
    hermd::add_apo_types(cfg);
    return cfg;
  }

  void SetUp() override {
    module_config mc;
    mc.routing.id = 0x40;
    auto m = run_module(sys_, mc);
    ASSERT_TRUE(m) << render(m.error());
    module_ = std::move(*m);
  }

  void TearDown() override {
    // The actor system waits for every actor when it ends.
    for (auto& a : actors_)
      caf::anon_send_exit(a, caf::exit_reason::user_shutdown);
  }

  const module_handles& handles() {
    return module_.handles();
  }

  /// Registers `a` in the module's application table as `name`.
  void add(const std::string& name, const caf::actor& a) {
    caf::scoped_actor self{sys_};
    self->request(handles().apps, 5s, atom::add_v, name, "herm.test", a)
      .receive([](apo_ref&) {}, [](caf::error& err) { FAIL() << render(err); });
  }

  /// An APO of hermd's kind `kind` named `name`, registered as hermd does.
  caf::actor apo(const std::string& kind, const std::string& name,
                 std::map<std::string, std::string> options) {
    auto* k = hermd::find_apo_kind(kind);
    EXPECT_NE(k, nullptr) << kind;
    if (k == nullptr)
      return {};
    apo_config cfg;
    cfg.name = name;
    cfg.kind = kind;
    cfg.options = std::move(options);
    EXPECT_FALSE(k->check(cfg)) << render(k->check(cfg));
    auto a = k->spawn(hermd::apo_context{&sys_, handles(), "sensor"}, cfg);
    EXPECT_TRUE(a) << render(a.error());
    if (!a)
      return {};
    actors_.push_back(*a);
    add(name, *a);
    return *a;
  }

  /// A subscriber of `topic` that records every `T` it receives.
  template <class T>
  void subscribe(const std::string& topic, seen<T>& into) {
    auto a = sys_.spawn([&into](caf::event_based_actor*) -> caf::behavior {
      return {[&into](const T& x) {
        std::lock_guard<std::mutex> guard{into.mtx};
        into.values.push_back(x);
      }};
    });
    actors_.push_back(a);
    caf::scoped_actor self{sys_};
    self->request(handles().apps, 5s, atom::subscribe_v, topic, a)
      .receive([] {}, [](caf::error& err) { FAIL() << render(err); });
  }

  /// A stand-in for hermd's collector: records every `T` it is asked and
  /// acknowledges it with a number, as the collector does.
  template <class T>
  caf::actor collector(seen<T>& into) {
    auto a = sys_.spawn([&into](caf::event_based_actor*) -> caf::behavior {
      return {[&into](const T& x) -> uint32_t {
        std::lock_guard<std::mutex> guard{into.mtx};
        into.values.push_back(x);
        return static_cast<uint32_t>(into.values.size());
      }};
    });
    actors_.push_back(a);
    return a;
  }

  /// The module's topics that it publishes.
  std::vector<std::string> published_topics() {
    std::vector<std::string> out;
    caf::scoped_actor self{sys_};
    self->request(handles().apps, 5s, atom::get_v, atom::topics_v)
      .receive(
        [&](std::vector<topic_info>& ts) {
          for (auto& t : ts)
            if (t.publishing)
              out.push_back(t.topic);
        },
        [](caf::error& err) { FAIL() << render(err); });
    return out;
  }

  caf::actor_system_config cfg_;
  caf::actor_system sys_;
  running_module module_;
  std::vector<caf::actor> actors_;
};

bool same(const srf04_reading& a, const srf04_reading& b) {
  return a.seq == b.seq && a.distance_mm == b.distance_mm
         && a.echo_us == b.echo_us;
}

} // namespace

TEST_F(hermd_apo_topics_test, srf04_batcher_publishes_every_reading_on_sonar_and_still_batches) {
  seen<srf04_reading> on_topic;
  seen<sonar_batch> batches;
  subscribe("sonar", on_topic);
  add("collector", collector(batches));
  auto sonar = apo("srf04_batcher", "sonar", {{"batch", "2"}});
  ASSERT_TRUE(sonar);
  // The third is out of range: published as it came, counted, not batched.
  std::vector<srf04_reading> sent{{1, 1200, 6960}, {2, 1300, 7540},
                                  {3, hermd::srf04_out_of_range, 0},
                                  {4, 1500, 8700}, {5, 1600, 9280}};
  for (auto& r : sent)
    caf::anon_send(sonar, r);
  ASSERT_TRUE(eventually([&] { return on_topic.size() >= sent.size(); }))
    << on_topic.size() << " readings on 'sonar'";
  auto got = on_topic.all();
  ASSERT_EQ(got.size(), sent.size());
  for (size_t i = 0; i < sent.size(); ++i)
    EXPECT_TRUE(same(got[i], sent[i])) << "reading " << i;
  ASSERT_TRUE(eventually([&] { return batches.size() >= 2; }));
  auto b = batches.all();
  EXPECT_EQ(b[0].distances_mm, (std::vector<uint16_t>{1200, 1300}));
  EXPECT_EQ(b[1].distances_mm, (std::vector<uint16_t>{1500, 1600}));
  EXPECT_EQ(b[1].first_seq, 4u);
  EXPECT_EQ(b[0].source, "sensor");
}

TEST_F(hermd_apo_topics_test, srf04_batcher_topic_option_renames_or_turns_it_off) {
  seen<srf04_reading> front;
  seen<sonar_batch> batches;
  subscribe("sonar_front", front);
  add("collector", collector(batches));
  auto named = apo("srf04_batcher", "front", {{"batch", "1"}, {"topic", "sonar_front"}});
  auto quiet = apo("srf04_batcher", "quiet", {{"batch", "1"}, {"topic", "off"}});
  auto empty = apo("srf04_batcher", "empty", {{"batch", "1"}, {"topic", ""}});
  ASSERT_TRUE(named && quiet && empty);
  caf::anon_send(named, srf04_reading{7, 900, 5220});
  caf::anon_send(quiet, srf04_reading{8, 901, 5226});
  caf::anon_send(empty, srf04_reading{9, 902, 5232});
  // Each reading made a batch: every APO has taken its reading.
  ASSERT_TRUE(eventually([&] { return batches.size() >= 3; }));
  ASSERT_TRUE(eventually([&] { return front.size() >= 1; }));
  EXPECT_TRUE(same(front.all().at(0), srf04_reading{7, 900, 5220}));
  EXPECT_EQ(published_topics(), std::vector<std::string>{"sonar_front"});
}

TEST_F(hermd_apo_topics_test, vision_source_publishes_every_frame_on_vision_and_still_sends_it) {
  seen<vision_frame> on_topic;
  seen<vision_frame> collected;
  subscribe("vision", on_topic);
  add("collector", collector(collected));
  auto camera = apo("vision_source", "camera", {{"period_ms", "20"}, {"bytes", "5"}});
  ASSERT_TRUE(camera);
  ASSERT_TRUE(eventually([&] { return on_topic.size() >= 3 && collected.size() >= 3; }));
  auto got = on_topic.all();
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(got[i].seq, i + 1);
    EXPECT_EQ(got[i].source, "sensor");
    EXPECT_EQ(got[i].data.size(), 5u);
    EXPECT_EQ(got[i].data.at(0), static_cast<uint8_t>(i + 1));
  }
  EXPECT_EQ(collected.all().at(0).seq, 1u);
}

TEST_F(hermd_apo_topics_test, vision_source_with_topic_off_publishes_nothing) {
  seen<vision_frame> collected;
  add("collector", collector(collected));
  auto camera = apo("vision_source", "camera",
                    {{"period_ms", "20"}, {"bytes", "1"}, {"topic", "off"}});
  ASSERT_TRUE(camera);
  ASSERT_TRUE(eventually([&] { return collected.size() >= 2; }));
  EXPECT_TRUE(published_topics().empty());
}

TEST(hermd_apo_kinds, topic_is_an_option_of_both_and_others_are_still_refused) {
  for (auto kind : {"srf04_batcher", "vision_source"}) {
    apo_config cfg;
    cfg.name = "x";
    cfg.kind = kind;
    cfg.options = {{"topic", "t"}};
    EXPECT_FALSE(hermd::find_apo_kind(kind)->check(cfg)) << kind;
    cfg.options = {{"topics", "t"}};
    auto err = hermd::find_apo_kind(kind)->check(cfg);
    EXPECT_NE(render(err).find("unknown option 'topics'"), std::string::npos)
      << render(err);
  }
}
