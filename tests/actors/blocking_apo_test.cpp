// Blocking work and the loop scheduler (docs/user-guide.md, "Blocking
// work"): an APO that must block is spawned detached, on a thread of its
// own, and while it blocks the modules' routing and their other APOs go on.
// Two modules share one actor system here, so they also share its one loop
// thread: an APO blocking on that thread would stall both.

#include <gtest/gtest.h>

#include <atomic>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <thread>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/app_support.hpp"
#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/loop_scheduler.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "routing/error.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

caf::behavior echo(caf::event_based_actor*) {
  return {[](const std::string& x) { return x; }};
}

// [blocking-apo]
// An APO that blocks (here: until `release`) is an ordinary actor, spawned
// detached: it gets a thread of its own, the module's loop thread goes on.
caf::behavior slow(caf::event_based_actor*, std::shared_future<void> release,
                   std::atomic<bool>* blocked) {
  return {[=](const std::string& x) {
    *blocked = true;
    release.wait(); // blocks this actor's own thread only
    return "slow " + x;
  }};
}
// [blocking-apo-end]

class blocking_apo : public ::testing::Test {
protected:
  void SetUp() override {
    configure(cfg); // the loop scheduler
    sys.emplace(cfg);
    auto seg = "blocking" + std::to_string(::getpid());
    for (module_id id : {0x41, 0x42}) {
      module_config mc;
      mc.routing.id = id;
      mc.routing.hello_interval = 100ms;
      mc.devices.push_back({"eth0", "inproc", seg, {}});
      auto m = start_module(*sys, mc);
      ASSERT_TRUE(m) << render(m.error());
      mods.push_back(*m);
    }
  }

  void TearDown() override {
    for (auto& m : mods)
      stop_module(m);
    mods.clear();
    sys.reset();
  }

  void add(const module_handles& m, const std::string& name, caf::actor apo) {
    caf::scoped_actor self{*sys};
    self->request(m.apps, 5s, atom::add_v, name, std::string{"test.blocking"},
                  apo)
      .receive([](apo_ref&) {},
               [&](caf::error& err) { FAIL() << render(err); });
  }

  /// A proxy for the APO `name`, bound from `m` (retried while routes
  /// converge; bounded).
  caf::actor bind(const module_handles& m, const std::string& name) {
    caf::scoped_actor self{*sys};
    auto deadline = std::chrono::steady_clock::now() + 20s;
    while (std::chrono::steady_clock::now() < deadline) {
      caf::actor proxy;
      caf::error err;
      self->request(m.apps, 5s, atom::bind_v,
                    bind_request{query_by::name, name, 500, false})
        .receive([&](caf::actor& p) { proxy = p; },
                 [&](caf::error& e) { err = e; });
      if (proxy)
        return proxy;
      if (!is(err, app_ec::not_found) && !is(err, routing_ec::no_route)) {
        ADD_FAILURE() << render(err);
        return {};
      }
      std::this_thread::sleep_for(50ms);
    }
    ADD_FAILURE() << "cannot bind " << name;
    return {};
  }

  caf::actor_system_config cfg;
  std::optional<caf::actor_system> sys;
  std::vector<module_handles> mods;
};

} // namespace

TEST_F(blocking_apo, a_blocked_detached_apo_stalls_neither_routing_nor_other_apos) {
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::atomic<bool> blocked{false};
  // [spawn-detached]
  add(mods[1], "slow", sys->spawn<caf::detached>(slow, released, &blocked));
  // [spawn-detached-end]
  add(mods[1], "echo", sys->spawn(echo));
  auto slow_proxy = bind(mods[0], "slow");
  ASSERT_TRUE(slow_proxy);
  // A request to the slow APO, from a thread of its own.
  std::promise<std::string> slow_reply;
  std::thread caller{[&] {
    caf::scoped_actor self{*sys};
    self->request(slow_proxy, 60s, std::string{"call"})
      .receive([&](std::string& x) { slow_reply.set_value(x); },
               [&](caf::error& err) { slow_reply.set_value(render(err)); });
  }};
  auto deadline = std::chrono::steady_clock::now() + 20s;
  while (!blocked && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(1ms);
  ASSERT_TRUE(blocked) << "the request never reached the slow APO";
  // While it blocks: discovery and binding (a flood through routing), and a
  // request to the other APO, all answered.
  auto echo_proxy = bind(mods[0], "echo");
  ASSERT_TRUE(echo_proxy);
  caf::scoped_actor self{*sys};
  std::string answer;
  self->request(echo_proxy, 10s, std::string{"ping"})
    .receive([&](std::string& x) { answer = x; },
             [&](caf::error& err) { answer = render(err); });
  EXPECT_EQ(answer, "ping");
  auto fut = slow_reply.get_future();
  EXPECT_EQ(fut.wait_for(0s), std::future_status::timeout); // still blocked
  release.set_value();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  EXPECT_EQ(fut.get(), "slow call");
  caller.join();
  EXPECT_GT(loop_stats_of(*sys).resumes, 0u); // it ran on the loop scheduler
}

TEST_F(blocking_apo, requests_answered_through_a_proxy_leave_no_timeout_behind) {
  // Application support drops the timeout of each request it answers
  // (loop_scheduler.hpp, request_answered): 50 requests with an hour's
  // timeout leave none in the clock, where CAF 0.17 would keep all 50 for
  // an hour and then fire them for nothing.
  add(mods[1], "echo", sys->spawn(echo));
  auto proxy = bind(mods[0], "echo");
  ASSERT_TRUE(proxy);
  constexpr int n = 50;
  std::promise<int> done;
  auto before = loop_stats_of(*sys).request_timeouts;
  auto client = sys->spawn([&, proxy](caf::event_based_actor* self) {
    auto left = std::make_shared<int>(n);
    auto next = std::make_shared<std::function<void()>>();
    *next = [=, &done] {
      self->request(proxy, 3600s, std::string{"ping"})
        .then(
          [=, &done](const std::string&) {
            if (--*left == 0) {
              done.set_value(n);
              *next = nullptr; // ends the cycle through the capture
              return;
            }
            (*next)();
          },
          [=, &done](caf::error& err) {
            ADD_FAILURE() << render(err);
            done.set_value(n - *left);
            *next = nullptr;
          });
    };
    (*next)();
    // Stays (an actor that ends takes its timeouts along).
    return caf::behavior{[](int) {}};
  });
  auto fut = done.get_future();
  ASSERT_EQ(fut.wait_for(60s), std::future_status::ready);
  ASSERT_EQ(fut.get(), n);
  // Only timeouts set before (by the scoped actors above) can remain.
  EXPECT_LE(loop_stats_of(*sys).request_timeouts, before);
  caf::anon_send_exit(client, caf::exit_reason::user_shutdown);
}
