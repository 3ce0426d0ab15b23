#pragma once

// The module's event loop: one thread waits in epoll for every driver's
// descriptor, for timers and for work handed over by other threads, and runs
// what became ready. Drivers own no thread; they register readiness callbacks
// here (docs/architecture.md, "Threads").
//
// Who runs it: the loop scheduler (actors/runtime/loop_scheduler.hpp) runs it
// on the thread that also runs the module's actors, so a frame read from a
// socket reaches its actor without waking another thread. Programs and tests
// on another CAF scheduler get one io_thread per process (io_loop_of).

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "caf/error.hpp"
#include "caf/expected.hpp"
#include "caf/fwd.hpp"

struct epoll_event;

namespace caf {
class actor_system;
} // namespace caf

namespace herm {

/// epoll over descriptors, a timer map and a queue of posted tasks, run by one
/// thread at a time (the loop thread: whichever calls run or run_once).
///
/// Threading: watch/modify/unwatch, add_timer/cancel_timer and the callbacks
/// belong to the loop thread (or to any thread while no thread runs the
/// loop); post, wake, run_sync and request_stop are for any thread.
/// Callbacks must not block: they run between other modules' packets.
///
/// Cost per turn: one epoll_pwait2 for up to `max_events` ready descriptors,
/// O(log n) per timer added, cancelled or fired. Memory: one entry per watched
/// descriptor and per pending timer or posted task, all owned by local code
/// (nothing here grows with network input).
class event_loop {
public:
  /// Called with the ready events (EPOLLIN, EPOLLOUT, EPOLLERR, EPOLLHUP).
  using io_callback = std::function<void(uint32_t events)>;

  using task = std::function<void()>;

  /// Names a pending timer for cancel_timer. Default: no timer.
  struct timer_handle {
    int64_t due_ns = 0;
    uint64_t seq = 0;
    explicit operator bool() const {
      return seq != 0;
    }
  };

  /// Ready descriptors handled per turn.
  static constexpr int max_events = 64;

  /// Creates the epoll instance and the wake-up eventfd. Errors:
  /// ec::device_unavailable with the system's reason.
  static caf::expected<std::unique_ptr<event_loop>> make();

  event_loop(const event_loop&) = delete;
  event_loop& operator=(const event_loop&) = delete;

  /// Runs no callback. Posted tasks not yet run are dropped (destroyed).
  ~event_loop();

  // -- descriptors (loop thread) ------------------------------------------------

  /// Calls `cb` on the loop thread whenever `fd` is ready for `events`
  /// (EPOLLIN, EPOLLOUT; level-triggered). One registration per descriptor.
  /// Errors: ec::invalid_parameter when `fd` is watched already or epoll
  /// refuses it (with the system's reason).
  caf::error watch(int fd, uint32_t events, io_callback cb);

  /// Changes the events `fd` is watched for. Errors as for watch.
  caf::error modify(int fd, uint32_t events);

  /// Stops watching `fd`; its callback is not called again, not even for
  /// events already collected in the current turn. Call it before closing
  /// `fd`. No effect when `fd` is not watched.
  void unwatch(int fd);

  /// Number of watched descriptors.
  size_t watched() const {
    return watchers_.size();
  }

  // -- timers (loop thread) ---------------------------------------------------------

  /// Runs `fn` on the loop thread once CLOCK_MONOTONIC reaches `due_ns`
  /// (posix::now_ns's clock), in due order; a due time in the past runs in
  /// the next turn. The loop thread runs with 1 ns timer slack, so timers
  /// fire within the kernel's wake-up latency.
  timer_handle add_timer(int64_t due_ns, task fn);

  /// Cancels a pending timer; no effect when it fired or was cancelled.
  void cancel_timer(timer_handle handle);

  /// The due time of the earliest timer, or INT64_MAX.
  int64_t next_timer_ns() const;

  // -- any thread -------------------------------------------------------------------

  /// Runs `fn` on the loop thread in its next turn (in post order) and wakes
  /// the loop if it sleeps. Never blocks beyond a short mutex.
  void post(task fn);

  /// Runs `fn` on the loop thread and returns once it ran. Runs it at once
  /// when called on the loop thread, or when no thread runs the loop now.
  /// Must not be called while holding anything a loop callback waits for.
  void run_sync(const task& fn);

  /// Makes a sleeping loop return from its wait. Cheap when it is awake: one
  /// atomic exchange, no system call. Any thread.
  void wake();

  /// Makes run() return after the current turn. Any thread.
  void request_stop();

  bool stop_requested() const {
    return stop_.load(std::memory_order_acquire);
  }

  /// Whether the calling thread is the one running the loop now.
  bool in_loop_thread() const {
    return owner_.load(std::memory_order_acquire) == std::this_thread::get_id();
  }

  // -- the loop thread ----------------------------------------------------------

  /// Runs turns until request_stop. The calling thread becomes the loop
  /// thread until it returns.
  void run();

  /// One turn: waits at most `max_wait_ns` (0: polls) for ready descriptors,
  /// due timers or posted tasks, unless `has_work` (when set) says there is
  /// work already, then runs what is ready: descriptors, then due timers,
  /// then posted tasks. Returns the number of callbacks, timers and tasks
  /// run. The calling thread is the loop thread during the call.
  size_t run_once(int64_t max_wait_ns);

  /// Says that the calling thread, which ran turns with run_once, runs no
  /// more: run_sync runs its task at once from then on. run() does it itself
  /// when it returns.
  void leave_thread();

  /// Set by a scheduler that runs the loop: asked, after the loop announced
  /// that it is about to sleep, whether work arrived elsewhere (then it does
  /// not sleep). Whoever queues that work calls wake() after queuing it.
  /// Loop thread, before run/run_once.
  void set_has_work(std::function<bool()> has_work) {
    has_work_ = std::move(has_work);
  }

  /// Wake-ups: how often the loop slept in epoll and how often another
  /// thread had to wake it (for tests and benchmarks).
  uint64_t sleeps() const {
    return sleeps_.load(std::memory_order_relaxed);
  }
  uint64_t wakes() const {
    return wakes_.load(std::memory_order_relaxed);
  }

private:
  event_loop(int epoll_fd, int wake_fd);

  struct watcher {
    int fd;
    io_callback cb;
  };

  int wait(int64_t max_wait_ns, epoll_event* out);
  size_t dispatch_ready(const epoll_event* ready, int n);
  size_t run_due_timers();
  size_t run_posted();

  int epoll_fd_;
  int wake_fd_;

  // Loop thread.
  std::unordered_map<int, uint64_t> fd_ids_;       // fd -> registration id
  std::unordered_map<uint64_t, watcher> watchers_; // registration id -> watcher
  uint64_t next_id_ = 1;
  std::map<std::pair<int64_t, uint64_t>, task> timers_;
  uint64_t next_timer_ = 1;
  std::function<bool()> has_work_;
  std::vector<task> running_; // posted tasks taken for this turn

  // Any thread.
  std::mutex posted_mtx_;
  std::vector<task> posted_;
  std::atomic<bool> has_posted_{false};
  std::atomic<bool> sleeping_{false};
  std::atomic<bool> stop_{false};
  std::atomic<std::thread::id> owner_{};
  std::atomic<uint64_t> sleeps_{0};
  std::atomic<uint64_t> wakes_{0};
};

/// Owns an event_loop and the thread that runs it: the loop of a process
/// whose actors run on another scheduler, and of driver tests and benchmarks.
class io_thread {
public:
  /// Creates the loop and starts the thread ("herm-io"). Errors as for
  /// event_loop::make, or ec::device_unavailable when no thread can start.
  static caf::expected<std::unique_ptr<io_thread>> make();

  /// Stops the loop and joins the thread. Stop every driver on it first.
  ~io_thread();

  event_loop& loop() {
    return *loop_;
  }

private:
  explicit io_thread(std::unique_ptr<event_loop> loop);

  std::unique_ptr<event_loop> loop_;
  std::thread thread_;
};

/// Implemented by a CAF scheduler that runs an event_loop on its own thread
/// (actors/runtime/loop_scheduler.hpp), so that the channels layer finds it
/// without depending on the layer above.
class loop_owner {
public:
  virtual ~loop_owner();
  virtual event_loop& io_loop() = 0;

  /// Delivers `content` to `receiver` on a wake of the loop at or after
  /// `t`, at `latest` at the latest (channels/lax_timer.hpp).
  virtual void schedule_lax(std::chrono::steady_clock::time_point t,
                            std::chrono::steady_clock::time_point latest,
                            caf::strong_actor_ptr receiver,
                            caf::mailbox_element_ptr content)
    = 0;
};

/// One io_thread shared by the whole process, started on first use and
/// stopped at exit: the loop of drivers started without one (driver tests,
/// benchmarks) and of systems on another scheduler. Aborts with a message
/// if its thread cannot start (the process cannot do IO then).
event_loop& shared_io_loop();

/// The loop on which `sys`'s devices run their drivers: the scheduler's own
/// when it is a loop_owner, else shared_io_loop().
event_loop& io_loop_of(caf::actor_system& sys);

} // namespace herm
