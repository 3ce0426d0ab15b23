// The event loop on its own: descriptors, timers, posted work, wake-ups.

#include "channels/event_loop.hpp"

#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"

#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

constexpr int64_t ms = 1'000'000;

std::unique_ptr<event_loop> make_loop() {
  auto loop = event_loop::make();
  EXPECT_TRUE(loop) << render(loop.error());
  return std::move(*loop);
}

/// A non-blocking eventfd that reads as ready once signalled.
struct ready_fd {
  posix::unique_fd fd{::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)};
  void signal() {
    posix::signal_eventfd(fd.get());
  }
  void drain() {
    uint64_t n;
    [[maybe_unused]] auto res = ::read(fd.get(), &n, sizeof(n));
  }
};

} // namespace

TEST(event_loop, calls_a_watcher_when_its_descriptor_is_ready) {
  auto loop = make_loop();
  ready_fd a;
  std::vector<uint32_t> seen;
  ASSERT_FALSE(loop->watch(a.fd.get(), EPOLLIN, [&](uint32_t ev) {
    seen.push_back(ev);
    a.drain();
  }));
  EXPECT_EQ(loop->run_once(0), 0u);
  a.signal();
  EXPECT_EQ(loop->run_once(1000 * ms), 1u);
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_NE(seen[0] & EPOLLIN, 0u);
  EXPECT_EQ(loop->run_once(0), 0u); // level-triggered, but drained
}

TEST(event_loop, refuses_a_descriptor_watched_twice_and_modifying_an_unknown_one) {
  auto loop = make_loop();
  ready_fd a;
  ASSERT_FALSE(loop->watch(a.fd.get(), EPOLLIN, [](uint32_t) {}));
  auto err = loop->watch(a.fd.get(), EPOLLIN, [](uint32_t) {});
  ASSERT_TRUE(err);
  EXPECT_TRUE(is(err, ec::invalid_parameter));
  EXPECT_NE(render(err).find("watched already"), std::string::npos);
  ready_fd b;
  EXPECT_TRUE(is(loop->modify(b.fd.get(), EPOLLIN), ec::invalid_parameter));
  EXPECT_TRUE(is(loop->watch(-1, EPOLLIN, [](uint32_t) {}),
                 ec::invalid_parameter));
  EXPECT_EQ(loop->watched(), 1u);
}

TEST(event_loop, an_unwatched_descriptor_gets_no_call_even_within_the_same_turn) {
  auto loop = make_loop();
  ready_fd a;
  ready_fd b;
  int calls = 0;
  // Whichever runs first unwatches the other: only one call in the turn.
  ASSERT_FALSE(loop->watch(a.fd.get(), EPOLLIN, [&](uint32_t) {
    ++calls;
    loop->unwatch(b.fd.get());
    loop->unwatch(a.fd.get());
  }));
  ASSERT_FALSE(loop->watch(b.fd.get(), EPOLLIN, [&](uint32_t) {
    ++calls;
    loop->unwatch(a.fd.get());
    loop->unwatch(b.fd.get());
  }));
  a.signal();
  b.signal();
  loop->run_once(1000 * ms);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(loop->watched(), 0u);
  EXPECT_EQ(loop->run_once(0), 0u);
}

TEST(event_loop, fires_timers_in_due_order_and_not_cancelled_ones) {
  auto loop = make_loop();
  auto now = posix::now_ns();
  std::vector<int> order;
  loop->add_timer(now + 3 * ms, [&] { order.push_back(3); });
  auto cancelled = loop->add_timer(now + 2 * ms, [&] { order.push_back(2); });
  loop->add_timer(now + 1 * ms, [&] { order.push_back(1); });
  loop->add_timer(now - 5 * ms, [&] { order.push_back(0); }); // past: next turn
  loop->cancel_timer(cancelled);
  loop->cancel_timer(cancelled); // twice: no effect
  EXPECT_EQ(loop->next_timer_ns(), now - 5 * ms);
  auto deadline = now + 2000 * ms;
  while (order.size() < 3 && posix::now_ns() < deadline)
    loop->run_once(1000 * ms);
  EXPECT_EQ(order, (std::vector<int>{0, 1, 3}));
  EXPECT_GE(posix::now_ns(), now + 3 * ms); // none fired early
  EXPECT_EQ(loop->next_timer_ns(), INT64_MAX);
}

TEST(event_loop, a_timer_set_from_a_timer_runs_in_a_later_turn) {
  auto loop = make_loop();
  int fired = 0;
  loop->add_timer(posix::now_ns(), [&] {
    ++fired;
    loop->add_timer(posix::now_ns(), [&] { ++fired; });
  });
  loop->run_once(0);
  loop->run_once(0);
  EXPECT_EQ(fired, 2);
}

TEST(event_loop, post_from_another_thread_wakes_a_sleeping_loop) {
  auto loop = make_loop();
  std::atomic<bool> ran{false};
  std::thread poster{[&] {
    // Wait until the loop sleeps, then post.
    while (loop->sleeps() == 0)
      std::this_thread::sleep_for(1ms);
    std::this_thread::sleep_for(5ms);
    loop->post([&] { ran = true; });
  }};
  auto start = std::chrono::steady_clock::now();
  loop->run_once(10'000 * ms); // would sleep 10 s without the wake-up
  poster.join();
  EXPECT_TRUE(ran);
  EXPECT_LT(std::chrono::steady_clock::now() - start, 5s);
  EXPECT_EQ(loop->wakes(), 1u);
}

TEST(event_loop, post_to_an_awake_loop_makes_no_system_call) {
  auto loop = make_loop();
  int ran = 0;
  for (int i = 0; i < 100; ++i)
    loop->post([&] { ++ran; });
  EXPECT_EQ(loop->wakes(), 0u); // the loop never announced sleep
  loop->run_once(1000 * ms);    // sees the posted work: does not sleep
  EXPECT_EQ(ran, 100);
  EXPECT_EQ(loop->sleeps(), 0u);
}

TEST(event_loop, has_work_keeps_the_loop_from_sleeping) {
  auto loop = make_loop();
  int asked = 0;
  loop->set_has_work([&] { return ++asked == 1; });
  auto start = std::chrono::steady_clock::now();
  loop->run_once(10'000 * ms); // has_work says yes: polls only
  EXPECT_LT(std::chrono::steady_clock::now() - start, 5s);
  EXPECT_EQ(asked, 1);
  EXPECT_EQ(loop->sleeps(), 0u);
}

TEST(event_loop, run_sync_runs_on_the_loop_thread_or_at_once_without_one) {
  auto loop = make_loop();
  // No thread runs the loop: at once, here.
  auto here = std::this_thread::get_id();
  std::thread::id where;
  loop->run_sync([&] { where = std::this_thread::get_id(); });
  EXPECT_EQ(where, here);
  std::thread runner{[&] { loop->run(); }};
  auto runner_id = runner.get_id();
  // Wait until the runner owns the loop.
  while (loop->sleeps() == 0)
    std::this_thread::sleep_for(1ms);
  loop->run_sync([&] { where = std::this_thread::get_id(); });
  EXPECT_EQ(where, runner_id);
  loop->request_stop();
  runner.join();
  loop->run_sync([&] { where = std::this_thread::get_id(); });
  EXPECT_EQ(where, here); // the runner left
}

TEST(event_loop, request_stop_ends_run_from_any_thread) {
  auto loop = make_loop();
  std::thread runner{[&] { loop->run(); }};
  std::this_thread::sleep_for(10ms);
  loop->request_stop();
  runner.join();
  EXPECT_TRUE(loop->stop_requested());
}

TEST(io_thread, runs_watchers_on_its_own_thread_and_stops_on_destruction) {
  auto t = io_thread::make();
  ASSERT_TRUE(t) << render(t.error());
  auto& loop = (*t)->loop();
  ready_fd a;
  std::atomic<int> calls{0};
  std::atomic<bool> on_loop{false};
  loop.run_sync([&] {
    ASSERT_FALSE(loop.watch(a.fd.get(), EPOLLIN, [&](uint32_t) {
      a.drain();
      on_loop = loop.in_loop_thread();
      ++calls;
    }));
  });
  EXPECT_FALSE(loop.in_loop_thread());
  a.signal();
  auto deadline = std::chrono::steady_clock::now() + 10s;
  while (calls == 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(1ms);
  EXPECT_EQ(calls, 1);
  EXPECT_TRUE(on_loop);
  loop.run_sync([&] { loop.unwatch(a.fd.get()); });
  t->reset(); // joins
}

TEST(io_loop_of, gives_every_system_on_another_scheduler_one_shared_loop) {
  caf::actor_system_config c1;
  c1.set("scheduler.policy", caf::atom("sharing"));
  c1.set("scheduler.max-threads", 1);
  caf::actor_system s1{c1};
  caf::actor_system_config c2;
  c2.set("scheduler.policy", caf::atom("sharing"));
  c2.set("scheduler.max-threads", 1);
  caf::actor_system s2{c2};
  auto& l1 = io_loop_of(s1);
  auto& l2 = io_loop_of(s2);
  EXPECT_EQ(&l1, &l2);
  std::atomic<bool> ran{false};
  l1.run_sync([&] { ran = l1.in_loop_thread(); });
  EXPECT_TRUE(ran);
}
