// A module's supervision and ownership (actors/module.hpp): a core actor
// that ends while the module runs is reported to the embedder, through the
// on_failure callback and the supervisor's down message, naming the actor;
// a clean stop is no failure; running_module stops the module when it goes
// out of scope. A real actor system (start_module blocks on its requests);
// every wait is bounded.

#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>
#include <optional>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

/// What on_failure reported, for the test thread.
struct failures {
  std::mutex mtx;
  std::condition_variable cv;
  std::vector<module_failure> seen;

  std::function<void(const module_failure&)> callback() {
    return [this](const module_failure& f) {
      std::lock_guard<std::mutex> guard{mtx};
      seen.push_back(f);
      cv.notify_all();
    };
  }

  /// The first report, waiting at most `timeout`.
  std::optional<module_failure> first(std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> guard{mtx};
    if (!cv.wait_for(guard, timeout, [this] { return !seen.empty(); }))
      return std::nullopt;
    return seen.front();
  }

  size_t count() {
    std::lock_guard<std::mutex> guard{mtx};
    return seen.size();
  }
};

std::string context_of(const caf::error& err) {
  auto& ctx = err.context();
  return ctx.match_elements<std::string>() ? ctx.get_as<std::string>(0)
                                           : std::string{};
}

class module_test : public ::testing::Test {
protected:
  void SetUp() override {
    configure(cfg_);
    sys_.emplace(cfg_);
  }

  void TearDown() override {
    sys_.reset();
  }

  module_config config(failures& f) {
    module_config mc;
    mc.routing.id = 0x51;
    mc.routing.hello_interval = 100ms;
    mc.on_failure = f.callback();
    return mc;
  }

  /// The supervisor's exit reason, once it has ended (bounded wait).
  std::optional<caf::error> supervisor_down(caf::scoped_actor& self,
                                            const module_handles& m) {
    std::optional<caf::error> reason;
    self->monitor(m.supervisor);
    self->receive([&](caf::down_msg& d) { reason = d.reason; },
                  caf::after(5s) >> [] {});
    return reason;
  }

  caf::actor_system_config cfg_;
  std::optional<caf::actor_system> sys_;
};

} // namespace

TEST_F(module_test, each_core_actor_that_dies_is_reported_by_name_and_reason) {
  struct row {
    const char* name;
    std::function<caf::actor(const module_handles&)> pick;
  };
  const row rows[] = {
    {"herm.io",
     [](const module_handles& m) { return caf::actor_cast<caf::actor>(m.io); }},
    {"herm.routing",
     [](const module_handles& m) {
       return caf::actor_cast<caf::actor>(m.agent);
     }},
    {"herm.apps",
     [](const module_handles& m) { return caf::actor_cast<caf::actor>(m.apps); }},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    failures f;
    auto m = run_module(*sys_, config(f));
    ASSERT_TRUE(m) << render(m.error());
    caf::scoped_actor self{*sys_};
    self->monitor((*m)->supervisor);
    self->send_exit(r.pick(**m),
                    caf::make_error(caf::sec::runtime_error, "std::bad_alloc"));
    auto report = f.first(5s);
    ASSERT_TRUE(report);
    EXPECT_EQ(report->actor, r.name);
    EXPECT_EQ(report->reason, caf::sec::runtime_error);
    EXPECT_EQ(context_of(report->reason), "std::bad_alloc");
    // The down message says the same, the actor's name first.
    std::optional<caf::error> reason;
    self->receive([&](caf::down_msg& d) { reason = d.reason; },
                  caf::after(5s) >> [] {});
    ASSERT_TRUE(reason);
    EXPECT_EQ(*reason, caf::sec::runtime_error);
    EXPECT_EQ(context_of(*reason), std::string{r.name} + ": std::bad_alloc");
    m->stop();
    EXPECT_EQ(f.count(), 1u);
  }
}

TEST_F(module_test, any_reason_but_user_shutdown_is_a_failure) {
  const caf::error reasons[] = {
    caf::make_error(caf::exit_reason::kill),
    caf::make_error(caf::exit_reason::unhandled_exception),
    make_error(ec::already_exists, "module id 0x51 is already held"),
  };
  for (auto& reason : reasons) {
    SCOPED_TRACE(render(reason));
    failures f;
    auto m = run_module(*sys_, config(f));
    ASSERT_TRUE(m) << render(m.error());
    caf::scoped_actor self{*sys_};
    self->send_exit((*m)->agent, reason);
    auto report = f.first(5s);
    ASSERT_TRUE(report);
    EXPECT_EQ(report->actor, "herm.routing");
    EXPECT_EQ(report->reason, reason);
  }
}

TEST_F(module_test, an_extra_watched_actor_is_reported_under_its_name) {
  failures f;
  auto m = run_module(*sys_, config(f));
  ASSERT_TRUE(m) << render(m.error());
  auto control = sys_->spawn([]() -> caf::behavior {
    return {[](int) {}};
  });
  watch_module_actor(*m, control, "herm.control");
  // Whether the supervisor monitors it before or after it ends, it gets
  // its down message (monitoring an ended actor reports it at once).
  caf::scoped_actor self{*sys_};
  self->send_exit(control, caf::exit_reason::kill);
  auto report = f.first(5s);
  ASSERT_TRUE(report);
  EXPECT_EQ(report->actor, "herm.control");
}

TEST_F(module_test, a_clean_stop_is_no_failure) {
  failures f;
  auto m = start_module(*sys_, config(f));
  ASSERT_TRUE(m) << render(m.error());
  caf::scoped_actor self{*sys_};
  self->monitor(m->supervisor);
  stop_module(*m);
  std::optional<caf::error> reason;
  self->receive([&](caf::down_msg& d) { reason = d.reason; },
                caf::after(5s) >> [] {});
  ASSERT_TRUE(reason);
  EXPECT_EQ(*reason, caf::exit_reason::user_shutdown);
  // The core actors end after the supervisor: nothing is reported.
  for (auto a : {caf::actor_cast<caf::actor>(m->io),
                 caf::actor_cast<caf::actor>(m->agent),
                 caf::actor_cast<caf::actor>(m->apps)}) {
    self->monitor(a);
    bool down = false;
    self->receive([&](caf::down_msg&) { down = true; },
                  caf::after(5s) >> [] {});
    EXPECT_TRUE(down);
  }
  EXPECT_EQ(f.count(), 0u);
}

TEST_F(module_test, a_running_module_stops_its_actors_when_it_goes_out_of_scope) {
  failures f;
  module_handles handles;
  {
    auto m = run_module(*sys_, config(f));
    ASSERT_TRUE(m) << render(m.error());
    handles = **m;
    // Moving hands the ownership over; the moved-from one owns nothing.
    running_module owner = std::move(*m);
    EXPECT_TRUE(owner);
    EXPECT_FALSE(*m);
  }
  // stop() waited for the core actors: they are gone already.
  caf::scoped_actor self{*sys_};
  for (auto a : {caf::actor_cast<caf::actor>(handles.io),
                 caf::actor_cast<caf::actor>(handles.agent),
                 caf::actor_cast<caf::actor>(handles.apps)}) {
    self->monitor(a);
    std::optional<caf::error> reason;
    self->receive([&](caf::down_msg& d) { reason = d.reason; },
                  caf::after(1s) >> [] {});
    ASSERT_TRUE(reason);
    EXPECT_EQ(*reason, caf::exit_reason::user_shutdown);
  }
  EXPECT_EQ(f.count(), 0u);
}

TEST_F(module_test, release_keeps_the_module_running_until_stop_module) {
  failures f;
  module_handles handles;
  {
    auto m = run_module(*sys_, config(f));
    ASSERT_TRUE(m) << render(m.error());
    handles = m->release();
    EXPECT_FALSE(*m);
  }
  caf::scoped_actor self{*sys_};
  bool answered = false;
  self->request(handles.agent, 5s, atom::get_v, atom::stats_v)
    .receive([&](routing_stats& st) { answered = st.self == 0x51; },
             [](caf::error&) {});
  EXPECT_TRUE(answered);
  running_module again{handles};
  again.stop();
  again.stop(); // idempotent
  EXPECT_FALSE(again);
  EXPECT_EQ(f.count(), 0u);
}
