#include "channels/event_loop.hpp"

#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <future>

#include "caf/actor_system.hpp"
#include "caf/scheduler/abstract_coordinator.hpp"

#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"
#include "channels/lax_timer.hpp"

namespace herm {

using posix::errno_text;
using posix::now_ns;

// -- event_loop ---------------------------------------------------------------------

caf::expected<std::unique_ptr<event_loop>> event_loop::make() {
  int ep = ::epoll_create1(EPOLL_CLOEXEC);
  if (ep < 0)
    return make_error(ec::device_unavailable,
                      "event loop: cannot create epoll: " + errno_text(errno));
  int wk = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wk < 0) {
    auto err = errno;
    ::close(ep);
    return make_error(ec::device_unavailable,
                      "event loop: cannot create eventfd: " + errno_text(err));
  }
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.u64 = 0; // id 0: the wake-up eventfd
  if (::epoll_ctl(ep, EPOLL_CTL_ADD, wk, &ev) != 0) {
    auto err = errno;
    ::close(wk);
    ::close(ep);
    return make_error(ec::device_unavailable,
                      "event loop: cannot watch eventfd: " + errno_text(err));
  }
  return std::unique_ptr<event_loop>{new event_loop(ep, wk)};
}

event_loop::event_loop(int epoll_fd, int wake_fd)
  : epoll_fd_(epoll_fd), wake_fd_(wake_fd) {
}

event_loop::~event_loop() {
  ::close(wake_fd_);
  ::close(epoll_fd_);
}

caf::error event_loop::watch(int fd, uint32_t events, io_callback cb) {
  if (fd_ids_.count(fd) != 0)
    return make_error(ec::invalid_parameter, "event loop: descriptor "
                                               + std::to_string(fd)
                                               + " is watched already");
  auto id = next_id_++;
  epoll_event ev{};
  ev.events = events;
  ev.data.u64 = id;
  if (::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, fd, &ev) != 0)
    return make_error(ec::invalid_parameter,
                      "event loop: cannot watch descriptor "
                        + std::to_string(fd) + ": " + errno_text(errno));
  fd_ids_.emplace(fd, id);
  watchers_.emplace(id, watcher{fd, std::move(cb)});
  return caf::none;
}

caf::error event_loop::modify(int fd, uint32_t events) {
  auto i = fd_ids_.find(fd);
  if (i == fd_ids_.end())
    return make_error(ec::invalid_parameter, "event loop: descriptor "
                                               + std::to_string(fd)
                                               + " is not watched");
  epoll_event ev{};
  ev.events = events;
  ev.data.u64 = i->second;
  if (::epoll_ctl(epoll_fd_, EPOLL_CTL_MOD, fd, &ev) != 0)
    return make_error(ec::invalid_parameter,
                      "event loop: cannot modify descriptor "
                        + std::to_string(fd) + ": " + errno_text(errno));
  return caf::none;
}

void event_loop::unwatch(int fd) {
  auto i = fd_ids_.find(fd);
  if (i == fd_ids_.end())
    return;
  ::epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, fd, nullptr);
  watchers_.erase(i->second);
  fd_ids_.erase(i);
}

event_loop::timer_handle event_loop::add_timer(int64_t due_ns, task fn) {
  timer_handle h{due_ns, next_timer_++};
  timers_.emplace(std::make_pair(h.due_ns, h.seq), std::move(fn));
  return h;
}

void event_loop::cancel_timer(timer_handle handle) {
  if (handle)
    timers_.erase(std::make_pair(handle.due_ns, handle.seq));
}

int64_t event_loop::next_timer_ns() const {
  return timers_.empty() ? INT64_MAX : timers_.begin()->first.first;
}

void event_loop::post(task fn) {
  {
    std::lock_guard<std::mutex> guard{posted_mtx_};
    posted_.push_back(std::move(fn));
  }
  has_posted_.store(true);
  wake();
}

void event_loop::run_sync(const task& fn) {
  auto owner = owner_.load(std::memory_order_acquire);
  if (owner == std::thread::id{} || owner == std::this_thread::get_id()) {
    fn();
    return;
  }
  std::mutex mtx;
  std::condition_variable cv;
  bool done = false;
  post([&] {
    fn();
    std::lock_guard<std::mutex> guard{mtx};
    done = true;
    cv.notify_one();
  });
  std::unique_lock<std::mutex> guard{mtx};
  cv.wait(guard, [&] { return done; });
}

void event_loop::wake() {
  // Pairs with the seq_cst store of sleeping_ in wait(): either the loop sees
  // the work queued before this call, or this call sees it sleeping.
  if (sleeping_.exchange(false)) {
    wakes_.fetch_add(1, std::memory_order_relaxed);
    posix::signal_eventfd(wake_fd_);
  }
}

void event_loop::request_stop() {
  stop_.store(true, std::memory_order_release);
  sleeping_.store(true); // make wake() write even if the loop is busy
  wake();
}

void event_loop::run() {
  while (!stop_requested())
    run_once(INT64_MAX);
  leave_thread();
}

void event_loop::leave_thread() {
  owner_.store(std::thread::id{}, std::memory_order_release);
}

int event_loop::wait(int64_t max_wait_ns, epoll_event* events) {
  auto next = next_timer_ns();
  if (next != INT64_MAX) {
    auto now = now_ns();
    max_wait_ns = std::min(max_wait_ns, std::max<int64_t>(0, next - now));
  }
  if (max_wait_ns > 0) {
    sleeping_.store(true);
    if (has_posted_.load() || stop_requested()
        || (has_work_ && has_work_())) {
      sleeping_.store(false);
      max_wait_ns = 0;
    }
  }
  int n;
  if (max_wait_ns == 0) {
    n = ::epoll_wait(epoll_fd_, events, max_events, 0);
  } else {
    sleeps_.fetch_add(1, std::memory_order_relaxed);
    timespec ts{};
    timespec* tsp = nullptr;
    if (max_wait_ns != INT64_MAX) {
      ts.tv_sec = static_cast<time_t>(max_wait_ns / 1'000'000'000);
      ts.tv_nsec = static_cast<long>(max_wait_ns % 1'000'000'000);
      tsp = &ts;
    }
    n = ::epoll_pwait2(epoll_fd_, events, max_events, tsp, nullptr);
    sleeping_.store(false);
  }
  if (n < 0) {
    if (errno != EINTR) {
      std::fprintf(stderr, "herm: event loop: epoll failed: %s\n",
                   errno_text(errno).c_str());
      std::abort(); // only a broken epoll descriptor gets here
    }
    return 0;
  }
  return n;
}

size_t event_loop::dispatch_ready(const epoll_event* ready, int n) {
  size_t ran = 0;
  for (int i = 0; i < n; ++i) {
    auto id = ready[i].data.u64;
    if (id == 0) {
      uint64_t count;
      [[maybe_unused]] auto res = ::read(wake_fd_, &count, sizeof(count));
      continue;
    }
    auto w = watchers_.find(id);
    if (w == watchers_.end())
      continue; // unwatched by an earlier callback of this turn
    // A copy: the callback may unwatch itself.
    auto cb = w->second.cb;
    cb(ready[i].events);
    ++ran;
  }
  return ran;
}

size_t event_loop::run_due_timers() {
  size_t ran = 0;
  auto now = now_ns();
  while (!timers_.empty() && timers_.begin()->first.first <= now) {
    auto fn = std::move(timers_.begin()->second);
    timers_.erase(timers_.begin());
    fn();
    ++ran;
  }
  return ran;
}

size_t event_loop::run_posted() {
  if (!has_posted_.load())
    return 0;
  {
    std::lock_guard<std::mutex> guard{posted_mtx_};
    running_.swap(posted_);
    has_posted_.store(false);
  }
  auto ran = running_.size();
  for (auto& fn : running_)
    fn();
  running_.clear();
  return ran;
}

size_t event_loop::run_once(int64_t max_wait_ns) {
  auto self = std::this_thread::get_id();
  auto prev = owner_.exchange(self, std::memory_order_acq_rel);
  if (prev != self) {
    // First turn on this thread: precise timers (the emulated media pace
    // frames in microseconds).
    ::prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
  }
  epoll_event events[max_events];
  auto n = wait(max_wait_ns, events);
  auto ran = dispatch_ready(events, n);
  ran += run_due_timers();
  ran += run_posted();
  return ran;
}

// -- io_thread ----------------------------------------------------------------------

caf::expected<std::unique_ptr<io_thread>> io_thread::make() {
  auto loop = event_loop::make();
  if (!loop)
    return std::move(loop.error());
  std::unique_ptr<io_thread> result{new io_thread(std::move(*loop))};
  auto* lp = result->loop_.get();
  // Returns once the thread runs the loop, so that run_sync from here on
  // runs on it.
  std::promise<void> running;
  lp->post([&running] { running.set_value(); });
  if (auto why = posix::start_thread(result->thread_, "io", [lp] {
        pthread_setname_np(pthread_self(), "herm-io");
        lp->run();
      }))
    return make_error(ec::device_unavailable, *why);
  running.get_future().wait();
  return result;
}

io_thread::io_thread(std::unique_ptr<event_loop> loop)
  : loop_(std::move(loop)) {
}

io_thread::~io_thread() {
  loop_->request_stop();
  if (thread_.joinable())
    thread_.join();
}

// -- loop_owner ---------------------------------------------------------------------

loop_owner::~loop_owner() = default;

event_loop& shared_io_loop() {
  static auto shared = [] {
    auto t = io_thread::make();
    if (!t) {
      std::fprintf(stderr, "herm: %s\n", render(t.error()).c_str());
      std::abort();
    }
    return std::move(*t);
  }();
  return shared->loop();
}

event_loop& io_loop_of(caf::actor_system& sys) {
  if (auto* owner = dynamic_cast<loop_owner*>(&sys.scheduler()))
    return owner->io_loop();
  return shared_io_loop();
}

void schedule_lax(caf::actor_system& sys, caf::actor_clock::time_point t,
                  caf::actor_clock::time_point latest,
                  caf::strong_actor_ptr receiver,
                  caf::mailbox_element_ptr content) {
  if (auto* owner = dynamic_cast<loop_owner*>(&sys.scheduler()))
    owner->schedule_lax(t, latest, std::move(receiver), std::move(content));
  else
    sys.clock().schedule_message(t, std::move(receiver), std::move(content));
}

} // namespace herm
