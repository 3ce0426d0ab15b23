// The loop scheduler: every actor and every descriptor callback on one
// thread; timeouts on that thread's timer map; other threads wake it only
// while it sleeps.

#include "actors/runtime/loop_scheduler.hpp"

#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <set>
#include <string>
#include <tuple>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/actor_cast.hpp"
#include "caf/mailbox_element.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/system.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/event_loop.hpp"
#include "channels/lax_timer.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

struct loop_system : ::testing::Test {
  loop_system() {
    configure(cfg); // "loop" is the default
  }
  caf::actor_system_config cfg;
};

/// Replies to an int with the int plus one, and says on which thread.
caf::behavior adder(caf::event_based_actor*,
                    std::shared_ptr<std::set<std::thread::id>> threads,
                    std::shared_ptr<std::mutex> mtx) {
  return {[=](int x) {
    std::lock_guard<std::mutex> guard{*mtx};
    threads->insert(std::this_thread::get_id());
    return x + 1;
  }};
}

/// Sends `n` to `server`, then the reply, until the reply is `last`; each
/// request with a timeout the clock sets and cancels.
void request_chain(caf::event_based_actor* self, caf::actor server, int n,
                   int last, std::promise<int>* result) {
  if (n == last) {
    result->set_value(n);
    self->quit();
    return;
  }
  self->request(server, 10s, n).then([=](int y) {
    request_chain(self, server, y, last, result);
  });
}

} // namespace

TEST_F(loop_system, runs_every_actor_and_the_io_loop_on_one_thread) {
  caf::actor_system sys{cfg};
  auto threads = std::make_shared<std::set<std::thread::id>>();
  auto mtx = std::make_shared<std::mutex>();
  auto a = sys.spawn(adder, threads, mtx);
  auto b = sys.spawn(adder, threads, mtx);
  caf::scoped_actor self{sys};
  for (int i = 0; i < 10; ++i) {
    self->request(i % 2 ? a : b, caf::infinite, i)
      .receive([&](int y) { EXPECT_EQ(y, i + 1); },
               [&](caf::error& err) { FAIL() << sys.render(err); });
  }
  std::thread::id loop_thread;
  io_loop_of(sys).run_sync([&] { loop_thread = std::this_thread::get_id(); });
  ASSERT_EQ(threads->size(), 1u);
  EXPECT_EQ(*threads->begin(), loop_thread);
  EXPECT_NE(loop_thread, std::this_thread::get_id());
  EXPECT_GT(loop_stats_of(sys).resumes, 0u);
}

TEST_F(loop_system, requests_between_loop_actors_with_timeouts_wake_no_thread) {
  caf::actor_system sys{cfg};
  auto threads = std::make_shared<std::set<std::thread::id>>();
  auto mtx = std::make_shared<std::mutex>();
  auto server = sys.spawn(adder, threads, mtx);
  std::promise<int> result;
  // A client that does 1,000 requests in a row, each with a timeout that the
  // loop's clock sets and cancels.
  auto client = sys.spawn([&, server](caf::event_based_actor* self) {
    return caf::behavior{[=, &result](caf::ok_atom) {
      request_chain(self, server, 0, 1000, &result);
    }};
  });
  // Let the spawns settle, then count wake-ups from here on.
  std::this_thread::sleep_for(50ms);
  auto before = loop_stats_of(sys);
  caf::anon_send(client, caf::ok_atom::value); // one enqueue from here
  auto fut = result.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  EXPECT_EQ(fut.get(), 1000);
  auto after = loop_stats_of(sys);
  EXPECT_LE(after.wakes - before.wakes, 1u);
  EXPECT_LE(after.foreign_enqueues - before.foreign_enqueues, 1u);
  EXPECT_GE(after.resumes - before.resumes, 2000u);
}

TEST_F(loop_system, the_timeouts_of_answered_requests_fire_on_wakes_the_loop_makes_anyway) {
  // A client ticks every 5 ms; on each of its first 20 ticks it makes a
  // request with a 30 ms timeout, answered at once. CAF 0.17 leaves each
  // timeout in the clock; all of them come due while the ticks go on (40
  // in all). The loop sleeps once per tick: a due timeout of an answered
  // request rides along instead of waking it (20 more sleeps without the
  // request timeouts' slack).
  constexpr int ticks = 40;
  constexpr int requests = 20;
  caf::actor_system sys{cfg};
  auto threads = std::make_shared<std::set<std::thread::id>>();
  auto mtx = std::make_shared<std::mutex>();
  auto server = sys.spawn(adder, threads, mtx);
  std::promise<void> done;
  auto client = sys.spawn([&, server](caf::event_based_actor* self) {
    auto left = std::make_shared<int>(ticks);
    return caf::behavior{[=, &done](caf::tick_atom) {
      if (--*left < 0) {
        done.set_value();
        self->quit();
        return;
      }
      if (ticks - *left <= requests)
        self->request(server, 30ms, *left).then([](int) {});
      self->delayed_send(self, 5ms, caf::tick_atom::value);
    }};
  });
  std::this_thread::sleep_for(50ms); // the spawns settle, the loop sleeps
  auto before = loop_stats_of(sys);
  caf::anon_send(client, caf::tick_atom::value);
  auto fut = done.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  auto sleeps = loop_stats_of(sys).sleeps - before.sleeps;
  // At least half the ticks slept (a tick due before the loop got to its
  // wait, on a loaded machine, is handled without one).
  EXPECT_GE(sleeps, static_cast<uint64_t>(ticks / 2));
  EXPECT_LE(sleeps, static_cast<uint64_t>(ticks + requests / 4))
    << "timeouts of answered requests woke the loop on their own";
}

TEST_F(loop_system, request_answered_drops_the_timeout_of_the_request_it_names) {
  // Application support calls request_answered for each response it
  // delivers; the timeout goes, where CAF 0.17 would let it fire for
  // nothing. A request nobody declares answered keeps its timeout.
  caf::actor_system sys{cfg};
  auto threads = std::make_shared<std::set<std::thread::id>>();
  auto mtx = std::make_shared<std::mutex>();
  auto server = sys.spawn(adder, threads, mtx);
  std::promise<void> done;
  auto before = loop_stats_of(sys).request_timeouts;
  auto client = sys.spawn([&, server](caf::event_based_actor* self) {
    auto declared = self->request(server, 600s, 1);
    auto rid = declared.id(); // the response's id already
    std::move(declared).then([=, &done](int) {
      request_answered(self->system(), self, rid);
      self->request(server, 600s, 2).then([&done](int) { done.set_value(); });
    });
    // Stays (an actor that ends takes its timeouts along).
    return caf::behavior{[](int) {}};
  });
  auto fut = done.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  EXPECT_EQ(loop_stats_of(sys).request_timeouts, before + 1);
  caf::anon_send_exit(client, caf::exit_reason::user_shutdown);
}

TEST_F(loop_system, an_actor_that_ends_takes_its_request_timeouts_along) {
  caf::actor_system sys{cfg};
  auto silent = sys.spawn([](caf::event_based_actor*) -> caf::behavior {
    return {[](int) -> caf::result<int> { return caf::delegated<int>{}; }};
  });
  auto client = sys.spawn([silent](caf::event_based_actor* self) {
    self->request(silent, 600s, 1).then([](int) {});
    return caf::behavior{[](int) {}};
  });
  // Bounded waits: CAF cancels an ending actor's timeouts after it told its
  // monitors, so the count may lag a moment behind what is observed here.
  auto settles_at = [&](uint64_t n) {
    for (int i = 0; i < 3000; ++i) {
      if (loop_stats_of(sys).request_timeouts == n)
        return true;
      std::this_thread::sleep_for(1ms);
    }
    return false;
  };
  EXPECT_TRUE(settles_at(1)) << "the request's timeout was never set";
  caf::anon_send_exit(client, caf::exit_reason::user_shutdown);
  EXPECT_TRUE(settles_at(0)) << "the ended actor's timeout stayed";
}

TEST_F(loop_system, delayed_messages_due_at_the_same_time_arrive_in_the_order_sent) {
  caf::actor_system sys{cfg};
  auto got = std::make_shared<std::vector<int>>();
  std::promise<void> done;
  constexpr int n = 200;
  auto sink = sys.spawn([&, got](caf::event_based_actor*) -> caf::behavior {
    return {[&, got](int x) {
      got->push_back(x);
      if (got->size() == n)
        done.set_value();
    }};
  });
  auto& clock = sys.clock();
  auto at = clock.now() + 20ms;
  for (int i = 0; i < n; ++i)
    clock.schedule_message(at, caf::actor_cast<caf::strong_actor_ptr>(sink),
                           caf::make_mailbox_element(nullptr,
                                                     caf::make_message_id(),
                                                     {}, i));
  auto fut = done.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  std::vector<int> want(n);
  for (int i = 0; i < n; ++i)
    want[i] = i;
  EXPECT_EQ(*got, want);
}

/// Sets a lax timer every `period` with `slack` (0: lax_slack(period))
/// until told to stop ("stop" as a string); counts what fired and what
/// fired before its time.
struct housekeeper_state {
  int64_t due_ns = 0;
  int fired = 0;
  int early = 0;
  bool stopped = false;
};

static caf::behavior housekeeper(caf::stateful_actor<housekeeper_state>* self,
                                 std::chrono::milliseconds period,
                                 std::chrono::milliseconds slack) {
  auto arm = [self, period, slack] {
    self->state.due_ns = posix::now_ns()
                         + std::chrono::nanoseconds(period).count();
    if (slack.count() == 0)
      delayed_send_lax(self, period, caf::tick_atom::value);
    else
      send_lax_at(self, self->clock().now() + period, slack,
                  caf::tick_atom::value);
  };
  arm();
  return {
    [self, arm](caf::tick_atom) {
      if (posix::now_ns() < self->state.due_ns)
        ++self->state.early;
      ++self->state.fired;
      if (!self->state.stopped)
        arm();
    },
    [self](const std::string&) {
      self->state.stopped = true;
      return std::make_tuple(self->state.fired, self->state.early);
    },
  };
}

struct lax_run {
  uint64_t sleeps = 0; // of the loop while the client ticked
  int fired = 0;       // lax timers
  int early = 0;       // lax timers that fired before their time
};

/// A client ticks `ticks` times every `tick` (ordinary timers) while a
/// housekeeper sets a lax timer every `period` with `slack`.
static lax_run run_beside_a_ticking_client(caf::actor_system_config& cfg,
                                           int ticks,
                                           std::chrono::milliseconds tick,
                                           std::chrono::milliseconds period,
                                           std::chrono::milliseconds slack) {
  caf::actor_system sys{cfg};
  std::promise<void> done;
  auto client = sys.spawn([&](caf::event_based_actor* self) {
    auto left = std::make_shared<int>(ticks);
    return caf::behavior{[=, &done](caf::tick_atom) {
      if (--*left < 0) {
        done.set_value();
        self->quit();
        return;
      }
      self->delayed_send(self, tick, caf::tick_atom::value);
    }};
  });
  std::this_thread::sleep_for(50ms); // the spawns settle, the loop sleeps
  auto before = loop_stats_of(sys);
  auto keeper = sys.spawn(housekeeper, period, slack);
  caf::anon_send(client, caf::tick_atom::value);
  lax_run result;
  auto fut = done.get_future();
  if (fut.wait_for(30s) != std::future_status::ready) {
    ADD_FAILURE() << "the client did not finish";
    return result;
  }
  result.sleeps = loop_stats_of(sys).sleeps - before.sleeps;
  caf::scoped_actor self{sys};
  self->request(keeper, 10s, std::string{"stop"})
    .receive([&](int f, int e) { result.fired = f; result.early = e; },
             [&](caf::error& err) { ADD_FAILURE() << sys.render(err); });
  caf::anon_send_exit(keeper, caf::exit_reason::user_shutdown);
  return result;
}

TEST_F(loop_system, lax_timers_fire_on_wakes_the_loop_makes_anyway_and_never_early) {
  // A client ticks every 2 ms, 150 times; meanwhile a housekeeper sets a
  // lax timer every 24 ms (3 ms of slack). The loop sleeps about once per
  // tick: a due lax timer rides along with the next tick instead of waking
  // the loop (about 12 more sleeps as ordinary timers).
  constexpr int ticks = 150;
  auto run = run_beside_a_ticking_client(cfg, ticks, 2ms, 24ms, 0ms);
  // About 12 in 300 ms; fewer on a loaded machine, never none.
  EXPECT_GE(run.fired, 5);
  EXPECT_EQ(run.early, 0);
  EXPECT_GE(run.sleeps, static_cast<uint64_t>(ticks / 2));
  // Without the slack: about ticks + fired.
  EXPECT_LE(run.sleeps, static_cast<uint64_t>(ticks + run.fired / 2))
    << "lax timers woke the loop on their own (" << run.fired << " fired)";
}

TEST_F(loop_system, a_lax_timer_with_a_wide_slack_rides_on_slower_wakes) {
  // As application support's idle tick: a lax timer every 30 ms that may
  // come 30 ms late, beside a client ticking every 20 ms, 40 times. Every
  // window of 30 ms holds a client tick, so the lax timers never wake the
  // loop themselves; with the default slack (3.75 ms) most would.
  constexpr int ticks = 40;
  auto run = run_beside_a_ticking_client(cfg, ticks, 20ms, 30ms, 30ms);
  // About 20 in 800 ms; fewer on a loaded machine, never none.
  EXPECT_GE(run.fired, 5);
  EXPECT_EQ(run.early, 0);
  EXPECT_LE(run.sleeps, static_cast<uint64_t>(ticks + run.fired / 2))
    << "lax timers woke the loop on their own (" << run.fired << " fired)";
}

TEST_F(loop_system, a_lax_timer_alone_wakes_the_loop_itself) {
  caf::actor_system sys{cfg};
  std::promise<void> done;
  int64_t sent = 0;
  int64_t arrived = 0;
  sys.spawn([&](caf::event_based_actor* self) {
    sent = posix::now_ns();
    delayed_send_lax(self, 30ms, caf::tick_atom::value);
    return caf::behavior{[&, self](caf::tick_atom) {
      arrived = posix::now_ns();
      done.set_value();
      self->quit();
    }};
  });
  auto fut = done.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  EXPECT_GE(arrived - sent, 30'000'000);
}

TEST_F(loop_system, a_request_without_reply_times_out_with_a_typed_error) {
  caf::actor_system sys{cfg};
  auto silent = sys.spawn([](caf::event_based_actor*) -> caf::behavior {
    return {[](int) -> caf::result<int> { return caf::delegated<int>{}; }};
  });
  std::promise<caf::error> got;
  sys.spawn([&, silent](caf::event_based_actor* self) {
    self->request(silent, 30ms, 1)
      .then([&](int) { got.set_value(caf::error{}); },
            [&](caf::error& err) { got.set_value(std::move(err)); });
  });
  auto fut = got.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  EXPECT_EQ(fut.get(), caf::sec::request_timeout);
}

TEST_F(loop_system, a_delayed_message_from_another_thread_arrives_after_its_delay) {
  caf::actor_system sys{cfg};
  std::promise<int64_t> arrived;
  auto target = sys.spawn([&](caf::event_based_actor*) -> caf::behavior {
    return {[&](int) { arrived.set_value(posix::now_ns()); }};
  });
  std::this_thread::sleep_for(20ms); // the loop sleeps now
  auto sent = posix::now_ns();
  caf::delayed_anon_send(target, 40ms, 7);
  auto fut = arrived.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  EXPECT_GE(fut.get() - sent, 40'000'000);
}

TEST_F(loop_system, a_blocked_detached_actor_does_not_stall_the_loop) {
  caf::actor_system sys{cfg};
  std::promise<void> release;
  auto released = release.get_future().share();
  // Shared with the detached actor, which may outlive this scope's locals.
  auto blocked = std::make_shared<std::atomic<bool>>(false);
  auto done = std::make_shared<std::atomic<bool>>(false);
  // Blocking work belongs in a detached actor: a thread of its own.
  auto slow = sys.spawn<caf::detached>([=](caf::event_based_actor*) -> caf::behavior {
    return {[=](int) {
      *blocked = true;
      released.wait();
      *done = true;
    }};
  });
  caf::anon_send(slow, 1);
  while (!*blocked)
    std::this_thread::sleep_for(1ms);
  auto threads = std::make_shared<std::set<std::thread::id>>();
  auto mtx = std::make_shared<std::mutex>();
  auto quick = sys.spawn(adder, threads, mtx);
  caf::scoped_actor self{sys};
  bool answered = false;
  self->request(quick, 30s, 41).receive([&](int y) { answered = y == 42; },
                                         [&](caf::error&) {});
  EXPECT_TRUE(answered);
  EXPECT_FALSE(*done); // the slow one is still blocked
  release.set_value();
  while (!*done)
    std::this_thread::sleep_for(1ms);
}

TEST_F(loop_system, descriptor_callbacks_run_on_the_actors_thread_and_reach_actors_without_a_wake) {
  caf::actor_system sys{cfg};
  auto& loop = io_loop_of(sys);
  posix::unique_fd fd{::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)};
  std::promise<std::thread::id> seen_by_actor;
  auto sink = sys.spawn([&](caf::event_based_actor*) -> caf::behavior {
    return {[&](int) { seen_by_actor.set_value(std::this_thread::get_id()); }};
  });
  std::thread::id cb_thread;
  loop.run_sync([&] {
    ASSERT_FALSE(loop.watch(fd.get(), EPOLLIN, [&, sink](uint32_t) {
      uint64_t n;
      [[maybe_unused]] auto res = ::read(fd.get(), &n, sizeof(n));
      cb_thread = std::this_thread::get_id();
      caf::anon_send(sink, 1); // same thread: no foreign enqueue
    }));
  });
  std::this_thread::sleep_for(20ms);
  auto before = loop_stats_of(sys);
  posix::signal_eventfd(fd.get()); // the kernel wakes the loop
  auto fut = seen_by_actor.get_future();
  ASSERT_EQ(fut.wait_for(30s), std::future_status::ready);
  auto actor_thread = fut.get();
  auto after = loop_stats_of(sys);
  loop.run_sync([&] { loop.unwatch(fd.get()); });
  EXPECT_EQ(actor_thread, cb_thread);
  EXPECT_EQ(after.foreign_enqueues, before.foreign_enqueues);
  EXPECT_EQ(after.wakes, before.wakes);
}

TEST_F(loop_system, shuts_down_with_timeouts_and_messages_still_pending) {
  auto sys = std::make_unique<caf::actor_system>(cfg);
  auto a = sys->spawn([](caf::event_based_actor* self) -> caf::behavior {
    self->delayed_send(self, 1h, 1);
    return {[](int) {}};
  });
  caf::delayed_anon_send(a, 1h, 2);
  caf::anon_send_exit(a, caf::exit_reason::user_shutdown);
  sys.reset(); // returns; nothing leaks (checked under ASan)
  SUCCEED();
}

TEST(loop_scheduler, busy_polls_before_sleeping_when_configured_and_still_sleeps) {
  caf::actor_system_config cfg;
  configure(cfg, "loop", 1, 200); // 200 us
  caf::actor_system sys{cfg};
  auto threads = std::make_shared<std::set<std::thread::id>>();
  auto mtx = std::make_shared<std::mutex>();
  auto a = sys.spawn(adder, threads, mtx);
  caf::scoped_actor self{sys};
  for (int i = 0; i < 20; ++i)
    self->request(a, 10s, i).receive([&](int y) { EXPECT_EQ(y, i + 1); },
                                     [&](caf::error& err) {
                                       FAIL() << sys.render(err);
                                     });
  std::this_thread::sleep_for(20ms); // idle: polls for 200 us, then sleeps
  auto s = loop_stats_of(sys);
  EXPECT_GT(s.busy_polls, 0u);
  EXPECT_GT(s.sleeps, 0u);
}

TEST(loop_scheduler, a_lax_timer_on_another_scheduler_is_an_ordinary_delayed_message) {
  caf::actor_system_config cfg;
  configure(cfg, "sharing", 1);
  caf::actor_system sys{cfg};
  auto keeper = sys.spawn(housekeeper, 2ms, 0ms);
  std::this_thread::sleep_for(50ms);
  caf::scoped_actor self{sys};
  self->request(keeper, 10s, std::string{"stop"})
    .receive(
      [&](int fired, int early) {
        EXPECT_GE(fired, 1);
        EXPECT_EQ(early, 0);
      },
      [&](caf::error& err) { FAIL() << sys.render(err); });
  caf::anon_send_exit(keeper, caf::exit_reason::user_shutdown);
}

TEST(loop_scheduler, stats_are_zero_on_another_scheduler) {
  caf::actor_system_config cfg;
  configure(cfg, "sharing", 1);
  caf::actor_system sys{cfg};
  auto s = loop_stats_of(sys);
  EXPECT_EQ(s.resumes, 0u);
  EXPECT_EQ(s.sleeps, 0u);
}
