// The emulated media on the event loop (channels/drivers/emu_medium.hpp):
// the "emu" link kind and the can kind's emulated bus receive through
// readiness callbacks and loop timers of the loop given to start(), and
// transmit in a step on that loop, not on threads of their own. Every case runs on both media, each on its own
// io_thread and mkdtemp directory; waits are bounded and nothing here
// asserts a duration.

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <dirent.h>
#include <memory>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"
#include "tests/channels/recorder.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm;
using namespace std::chrono_literals;
using herm::test::recorder;

namespace {

/// One kind of emulated medium: how a station on it is configured.
struct medium_kind {
  const char* name;     // test name suffix
  const char* kind;     // link kind
  const char* scheme;   // before the directory in the interface
  const char* addr_key; // option naming the station
};

/// Short frames: a classic CAN frame carries at most 8 bytes.
const medium_kind media[] = {
  {"emu", "emu", "", "station"},
  {"can_bus", "can", "emu:", "node"},
};

/// Records like recorder and counts calls made off the loop thread.
class loop_checker : public recorder {
public:
  explicit loop_checker(event_loop& loop) : loop_(loop) {
  }

  void on_frame_in_lane(link_addr src, uint8_t lane, const uint8_t* data,
                        size_t size) override {
    check();
    recorder::on_frame_in_lane(src, lane, data, size);
  }

  void on_malformed(link_addr src, const char* why) override {
    check();
    recorder::on_malformed(src, why);
  }

  void on_failure(caf::error reason) override {
    check();
    recorder::on_failure(std::move(reason));
  }

  uint64_t off_loop() const {
    return off_loop_.load();
  }

private:
  void check() {
    if (!loop_.in_loop_thread())
      ++off_loop_;
  }

  event_loop& loop_;
  std::atomic<uint64_t> off_loop_{0};
};

size_t thread_count() {
  size_t n = 0;
  if (auto* dir = ::opendir("/proc/self/task")) {
    while (auto* e = ::readdir(dir))
      if (e->d_name[0] != '.')
        ++n;
    ::closedir(dir);
  }
  return n;
}

byte_buffer bytes_of(const std::string& str) {
  return byte_buffer(str.begin(), str.end());
}

void PrintTo(const medium_kind& m, std::ostream* os) {
  *os << m.name;
}

class emu_loop_test : public ::testing::TestWithParam<medium_kind> {
protected:
  void SetUp() override {
    ASSERT_FALSE(dir_.path().empty());
    auto io = io_thread::make();
    ASSERT_TRUE(io) << render(io.error());
    io_ = std::move(*io);
  }

  void TearDown() override {
    for (auto& d : drivers_)
      d->stop();
    drivers_.clear();
  }

  event_loop& loop() {
    return io_->loop();
  }

  std::string medium_dir() const {
    return dir_.path() + "/medium";
  }

  /// Opens station `n` (not started); null on failure (recorded).
  link_driver_ptr open(uint64_t n) {
    auto& m = GetParam();
    device_config cfg{std::string{m.name} + std::to_string(n), m.kind,
                      m.scheme + medium_dir(),
                      {{m.addr_key, std::to_string(n)}}};
    auto d = find_link_kind(m.kind)->open(cfg);
    if (!d) {
      ADD_FAILURE() << "cannot open station " << n << ": "
                    << render(d.error());
      return nullptr;
    }
    drivers_.push_back(*d);
    return *d;
  }

  /// Opens and starts station `n` on the test's loop with `handler`.
  link_driver_ptr start(uint64_t n, std::shared_ptr<frame_handler> handler) {
    auto d = open(n);
    if (d == nullptr)
      return nullptr;
    if (auto err = d->start(std::move(handler), loop())) {
      ADD_FAILURE() << "cannot start station " << n << ": " << render(err);
      return nullptr;
    }
    return d;
  }

  static caf::error send(const link_driver_ptr& d, link_addr dst,
                         const std::string& text) {
    auto bytes = bytes_of(text);
    return d->send(dst, bytes.data(), bytes.size(), prio_normal);
  }

  test::temp_dir dir_{"herm-emu-loop-test"};
  std::unique_ptr<io_thread> io_;
  std::vector<link_driver_ptr> drivers_;
};

// Receiving and transmitting (the wire's pacing, the bus's arbitration)
// are the loop's: a station starts no thread, not even while it sends.
TEST_P(emu_loop_test, a_station_adds_no_thread) {
  auto before = thread_count();
  auto d = open(1);
  ASSERT_TRUE(d);
  EXPECT_EQ(thread_count(), before);
  ASSERT_FALSE(d->start(std::make_shared<recorder>(), loop()));
  EXPECT_EQ(thread_count(), before);
  for (int i = 0; i < 20; ++i)
    ASSERT_FALSE(send(d, broadcast_addr, "x" + std::to_string(i)));
  loop().run_sync([] {});
  EXPECT_EQ(thread_count(), before);
  d->stop();
  EXPECT_EQ(thread_count(), before);
}

TEST_P(emu_loop_test, frames_and_failures_reach_the_handler_on_the_loop_thread) {
  auto rx = std::make_shared<loop_checker>(loop());
  auto a = start(1, std::make_shared<recorder>());
  auto b = start(2, rx);
  ASSERT_TRUE(a && b);
  for (int i = 0; i < 20; ++i)
    ASSERT_FALSE(send(a, 2, "f" + std::to_string(i)));
  ASSERT_TRUE(rx->wait_frames(20));
  // The liveness timer notices the socket file is gone.
  ASSERT_EQ(::unlink((medium_dir() + "/2.sock").c_str()), 0);
  ASSERT_TRUE(rx->wait_failures(1));
  EXPECT_TRUE(is(rx->failures()[0], ec::device_failed));
  EXPECT_EQ(rx->off_loop(), 0u);
}

// Sender and receiver on one loop: a burst outgrows the receiver's socket
// queue (net.unix.max_dgram_qlen, 10 by default) long before the receiver
// gets a turn. The frames the queue refuses wait in the sender (stalled)
// until the receiver has read: none is lost, and they arrive in order.
// (The emu medium's default bandwidth makes the 60 frames due at once and
// stalls; the CAN bus's bit rate paces them so that the receiver reads in
// between.)
TEST_P(emu_loop_test, a_burst_to_a_receiver_on_the_same_loop_loses_nothing) {
  auto rx = std::make_shared<recorder>();
  auto a = start(1, std::make_shared<recorder>());
  auto b = start(2, rx);
  ASSERT_TRUE(a && b);
  constexpr int n = 60; // within the CAN driver's transmit queue (64)
  loop().run_sync([&] { // all queued before the transmit step runs
    for (int i = 0; i < n; ++i)
      ASSERT_FALSE(send(a, 2, "b" + std::to_string(i)));
  });
  ASSERT_TRUE(rx->wait_frames(n)) << rx->frames().size() << " of " << n;
  for (int i = 0; i < n; ++i)
    EXPECT_EQ(rx->frames()[static_cast<size_t>(i)].bytes,
              bytes_of("b" + std::to_string(i)));
  auto overruns = a->get_param("tx_overruns");
  ASSERT_TRUE(overruns);
  EXPECT_EQ(*overruns, "0");
}

// A receiver that does not read at all holds the sender back only for the
// grace period (emu_medium::overrun_wait_ns): then what it refused counts
// as overruns and the medium carries frames for others again.
TEST_P(emu_loop_test, a_receiver_that_never_reads_costs_only_overruns) {
  auto observer = std::make_shared<recorder>();
  auto a = start(1, std::make_shared<recorder>());
  auto c = start(3, observer);
  auto b = open(2); // bound, never started: nobody reads its socket
  ASSERT_TRUE(a && b && c);
  for (int i = 0; i < 40; ++i)
    ASSERT_FALSE(send(a, 2, "s" + std::to_string(i)));
  ASSERT_FALSE(send(a, 3, "after"));
  ASSERT_TRUE(observer->wait_frame(bytes_of("after")));
  auto overruns = a->get_param("tx_overruns");
  ASSERT_TRUE(overruns);
  EXPECT_GT(std::stoull(*overruns), 0u);
  EXPECT_LE(std::stoull(*overruns), 40u);
}

TEST_P(emu_loop_test, stop_from_a_handler_ends_a_batch_of_queued_frames) {
  auto observer = std::make_shared<recorder>();
  auto a = start(1, std::make_shared<recorder>());
  auto c = start(3, observer);
  auto b = open(2); // bound, not started: frames queue in its socket
  ASSERT_TRUE(a && b && c);
  constexpr int n = 20;
  for (int i = 0; i < n; ++i)
    ASSERT_FALSE(send(a, 2, "q" + std::to_string(i)));
  // The transmit step sends in order: once station 3 has this frame, all
  // n reached station 2's socket (or overran it).
  ASSERT_FALSE(send(a, 3, "marker"));
  ASSERT_TRUE(observer->wait_frame(bytes_of("marker")));
  auto rx = std::make_shared<recorder>();
  std::atomic<bool> stopped{false};
  auto* raw = b.get();
  rx->on_each_frame([&](const recorder::frame&) {
    raw->stop();
    stopped = true;
  });
  ASSERT_FALSE(b->start(rx, loop()));
  ASSERT_TRUE(rx->wait_frames(1));
  loop().run_sync([] {}); // the callback that called the handler returned
  EXPECT_TRUE(stopped.load());
  EXPECT_EQ(rx->frames().size(), 1u);
  EXPECT_TRUE(rx->failures().empty());
  b->stop(); // again, from outside: harmless
  EXPECT_EQ(rx->frames().size(), 1u);
}

TEST_P(emu_loop_test, no_handler_call_follows_stop_from_another_thread) {
  auto a = start(1, std::make_shared<recorder>());
  ASSERT_TRUE(a);
  auto rx = std::make_shared<recorder>();
  std::atomic<bool> stop_returned{false};
  std::atomic<uint64_t> late{0};
  rx->on_each_frame([&](const recorder::frame&) {
    if (stop_returned.load())
      ++late;
  });
  auto b = start(2, rx);
  ASSERT_TRUE(b);
  std::atomic<bool> done{false};
  std::atomic<uint64_t> sent{0};
  std::thread flood{[&] {
    while (!done.load()) {
      if (!send(a, 2, "flood"))
        ++sent;
      else
        std::this_thread::yield(); // queue full: let it drain
    }
  }};
  bool heard = rx->wait_frames(10);
  b->stop();
  stop_returned = true;
  // Keep the flood going a while after stop: frames in flight, due
  // datagrams held, the socket's readiness.
  auto after = sent.load();
  auto deadline = std::chrono::steady_clock::now() + 10s;
  while (sent.load() < after + 100 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(1ms);
  loop().run_sync([] {});
  done = true;
  flood.join();
  ASSERT_TRUE(heard);
  EXPECT_EQ(late.load(), 0u);
  EXPECT_TRUE(rx->failures().empty());
}

INSTANTIATE_TEST_SUITE_P(media, emu_loop_test, ::testing::ValuesIn(media),
                         [](const auto& param_info) {
                           return std::string{param_info.param.name};
                         });

} // namespace
