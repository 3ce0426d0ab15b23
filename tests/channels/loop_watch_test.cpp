// The descriptor drivers' shared life cycle on the event loop.

#include "channels/drivers/loop_watch.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "channels/drivers/posix.hpp"

using namespace herm;

namespace {

struct loop_watch_life : ::testing::Test {
  loop_watch_life() {
    auto l = event_loop::make();
    EXPECT_TRUE(l);
    loop = std::move(*l);
  }

  loop_watch::fail_fn fail = [](ec code, const std::string& what) {
    return make_error(code, "device 'x': " + what);
  };

  caf::error start(loop_watch& w, bool has_handler = true) {
    return w.start(*loop, fd.get(), has_handler, "socket", fail, nullptr,
                   [this](uint32_t) {
                     uint64_t n;
                     [[maybe_unused]] auto r = ::read(fd.get(), &n, sizeof(n));
                     ++calls;
                   },
                   [this] { ++running; });
  }

  std::unique_ptr<event_loop> loop;
  posix::unique_fd fd{::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)};
  int calls = 0;
  int running = 0;
  int closes = 0;
};

} // namespace

TEST_F(loop_watch_life, start_watches_the_descriptor_and_stop_unwatches_and_closes_once) {
  loop_watch w;
  ASSERT_FALSE(start(w));
  EXPECT_EQ(running, 1);
  EXPECT_EQ(w.loop(), loop.get());
  posix::signal_eventfd(fd.get());
  loop->run_once(0);
  EXPECT_EQ(calls, 1);
  w.stop([this] { ++closes; });
  w.stop([this] { ++closes; });
  EXPECT_EQ(closes, 1);
  EXPECT_TRUE(w.stopping());
  EXPECT_EQ(loop->watched(), 0u);
  posix::signal_eventfd(fd.get());
  loop->run_once(0);
  EXPECT_EQ(calls, 1);
}

TEST_F(loop_watch_life, refuses_a_second_start_a_start_after_stop_and_no_handler) {
  loop_watch none;
  auto err = start(none, false);
  EXPECT_TRUE(is(err, ec::invalid_parameter));
  EXPECT_NE(render(err).find("start needs a frame handler"), std::string::npos);
  loop_watch w;
  ASSERT_FALSE(start(w));
  err = start(w);
  EXPECT_TRUE(is(err, ec::device_unavailable));
  EXPECT_NE(render(err).find("device 'x': already started"), std::string::npos);
  w.stop([] {});
  err = start(w);
  EXPECT_NE(render(err).find("already stopped"), std::string::npos);
  EXPECT_EQ(running, 1);
}

TEST_F(loop_watch_life, a_failed_preparation_or_watch_leaves_it_unstarted) {
  loop_watch w;
  auto err = w.start(*loop, fd.get(), true, "socket", fail,
                     [] { return make_error(ec::device_unavailable, "no"); },
                     [](uint32_t) {}, [this] { ++running; });
  EXPECT_TRUE(is(err, ec::device_unavailable));
  loop_watch bad;
  err = bad.start(*loop, -1, true, "line", fail, nullptr, [](uint32_t) {},
                  [this] { ++running; });
  EXPECT_NE(render(err).find("cannot watch the line"), std::string::npos);
  EXPECT_EQ(running, 0);
  EXPECT_EQ(bad.loop(), nullptr);
  // Never started: stop closes at once, without the loop.
  bad.stop([this] { ++closes; });
  EXPECT_EQ(closes, 1);
}

TEST_F(loop_watch_life, stop_from_inside_the_callback_ends_delivery_at_once) {
  loop_watch w;
  bool stopped_seen = false;
  ASSERT_FALSE(w.start(*loop, fd.get(), true, "socket", fail, nullptr,
                       [&](uint32_t) {
                         w.stop([this] { ++closes; });
                         stopped_seen = w.stopping();
                       },
                       [] {}));
  posix::signal_eventfd(fd.get());
  loop->run_once(0);
  EXPECT_TRUE(stopped_seen);
  EXPECT_EQ(closes, 1);
  EXPECT_EQ(loop->watched(), 0u);
}
