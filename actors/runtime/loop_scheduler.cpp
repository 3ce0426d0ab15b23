#include "actors/runtime/loop_scheduler.hpp"

#include <pthread.h>

#include <atomic>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <limits>
#include <mutex>
#include <thread>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/detail/simple_actor_clock.hpp"
#include "caf/execution_unit.hpp"
#include "caf/mailbox_element.hpp"
#include "caf/resumable.hpp"
#include "caf/settings.hpp"
#include "caf/scheduler/abstract_coordinator.hpp"

#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"
#include "channels/event_loop.hpp"

namespace herm {

namespace {

constexpr char busy_poll_key[] = "herm.busy-poll-us";

/// Timers in a binary heap over a vector, the earliest at the front: no
/// allocation per timer once the vector has grown, unlike CAF's maps (two
/// or three per timer). Timers due at the same time come out in the order
/// they were set. Any entry can be removed in O(log n).
class timer_heap {
public:
  using time_point = caf::actor_clock::time_point;

  /// A delayed message (content set) or a request's timeout (content null:
  /// `target` gets the error sec::request_timeout as the response `id`).
  struct entry {
    time_point due;
    uint64_t seq = 0;
    caf::strong_actor_ptr target;
    caf::message_id id;
    caf::mailbox_element_ptr content;
    /// A lax timer's latest time (loop_clock::schedule_lax).
    time_point latest = time_point::max();
  };

  bool empty() const {
    return xs_.empty();
  }

  size_t size() const {
    return xs_.size();
  }

  const entry& front() const {
    return xs_.front();
  }

  void push(entry x) {
    x.seq = next_seq_++;
    xs_.push_back(std::move(x));
    sift_up(xs_.size() - 1);
  }

  /// The earliest `latest` of all entries, or time_point::max(). O(n).
  time_point earliest_latest() const {
    auto result = time_point::max();
    for (auto& x : xs_)
      result = std::min(result, x.latest);
    return result;
  }

  /// Moves every entry due at `t` to `out`, earliest first.
  void take_due(time_point t, std::vector<entry>& out) {
    while (!xs_.empty() && xs_.front().due <= t) {
      out.push_back(std::move(xs_.front()));
      remove(0);
    }
  }

  /// Removes the request timeout of `target` for `id` if it is among the
  /// last `scan` entries (where one set recently usually is). True if so.
  bool remove_request(const caf::actor_control_block* target,
                      caf::message_id id, size_t scan) {
    for (size_t k = 0; k < xs_.size() && k < scan; ++k) {
      auto i = xs_.size() - 1 - k;
      auto& x = xs_[i];
      if (!x.content && x.id == id && x.target.get() == target) {
        remove(i);
        return true;
      }
    }
    return false;
  }

  template <class Pred>
  void remove_if(Pred pred) {
    auto end = std::remove_if(xs_.begin(), xs_.end(), pred);
    if (end == xs_.end())
      return;
    xs_.erase(end, xs_.end());
    std::make_heap(xs_.begin(), xs_.end(), later);
  }

private:
  static bool later(const entry& x, const entry& y) {
    return x.due != y.due ? x.due > y.due : x.seq > y.seq;
  }

  void remove(size_t i) {
    auto last = xs_.size() - 1;
    if (i != last) {
      xs_[i] = std::move(xs_[last]);
      xs_.pop_back();
      sift_up(sift_down(i));
    } else {
      xs_.pop_back();
    }
  }

  size_t sift_down(size_t i) {
    for (;;) {
      auto first = i;
      for (auto c : {2 * i + 1, 2 * i + 2})
        if (c < xs_.size() && later(xs_[first], xs_[c]))
          first = c;
      if (first == i)
        return i;
      std::swap(xs_[i], xs_[first]);
      i = first;
    }
  }

  void sift_up(size_t i) {
    while (i > 0) {
      auto parent = (i - 1) / 2;
      if (!later(xs_[parent], xs_[i]))
        return;
      std::swap(xs_[i], xs_[parent]);
      i = parent;
    }
  }

  std::vector<entry> xs_;
  uint64_t next_seq_ = 0;
};

/// The actor clock of the loop, behind a mutex. The loop thread asks it for
/// the next due time before it sleeps and fires what is due after each
/// wait; another thread that sets a timeout wakes the loop so it recomputes
/// its wait. Delayed messages, lax ones (channels/lax_timer.hpp) and
/// request timeouts, nearly all of the timers, are in heaps of its own
/// (timer_heap); the rare rest (receive and stream timeouts, delayed group
/// messages) in CAF's simple clock.
class loop_clock final : public caf::detail::simple_actor_clock {
public:
  using super = caf::detail::simple_actor_clock;

  explicit loop_clock(event_loop& loop) : loop_(loop) {
  }

  /// Nanoseconds until the loop must wake for a timeout (0 when one is
  /// due), or INT64_MAX. A request timeout may wait up to
  /// request_timeout_slack past its time for a wake the loop makes anyway
  /// (fire_due fires everything due after every wait): CAF 0.17 never
  /// cancels a request's timeout when the response comes, so every request
  /// answered by an actor other than application support (which cancels:
  /// request_answered) leaves one that fires for nothing, and without the
  /// slack each would wake the loop on its own.
  int64_t wait_ns() {
    std::lock_guard<std::mutex> guard{mtx_};
    auto wake = time_point::max();
    if (!schedule_.empty())
      wake = schedule_.begin()->first;
    if (!messages_.empty())
      wake = std::min(wake, messages_.front().due);
    if (!requests_.empty())
      wake = std::min(wake, requests_.front().due + request_timeout_slack);
    wake = std::min(wake, lax_.earliest_latest());
    if (wake == time_point::max())
      return std::numeric_limits<int64_t>::max();
    auto d = wake - now();
    auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(d).count();
    return ns < 0 ? 0 : ns;
  }

  /// Whether another thread changed the timeouts since the last call. The
  /// loop asks after announcing that it sleeps: a timeout set between its
  /// wait_ns() and that announcement found it awake (wake() did nothing),
  /// and the loop must recompute its wait instead of sleeping the old one.
  bool take_changed() {
    return changed_.exchange(false);
  }

  /// Fires what is due (loop thread only); returns how many.
  size_t fire_due() {
    size_t fired = 0;
    {
      std::lock_guard<std::mutex> guard{mtx_};
      fired = trigger_expired_timeouts();
      auto t = now();
      messages_.take_due(t, due_);
      lax_.take_due(t, due_);
      requests_.take_due(t, due_);
    }
    // Shipped outside the lock, as simple_actor_clock::ship would.
    for (auto& x : due_) {
      if (x.content)
        x.target->enqueue(std::move(x.content), nullptr);
      else
        x.target->get()->eq_impl(x.id, x.target, nullptr,
                                 caf::sec::request_timeout);
    }
    fired += due_.size();
    due_.clear();
    return fired;
  }

  /// Drops the timeout of `self`'s request whose response id is `id`, if
  /// it is among the last max_scanned set (where a request still waiting
  /// usually is); one further back fires for nothing, as CAF's would.
  /// O(max_scanned + log n), no allocation.
  void request_answered(caf::abstract_actor* self, caf::message_id id) {
    std::lock_guard<std::mutex> guard{mtx_};
    requests_.remove_request(self->ctrl(), id, max_scanned);
  }

  /// Request timeouts waiting (tests).
  size_t requests_waiting() {
    std::lock_guard<std::mutex> guard{mtx_};
    return requests_.size();
  }

  void set_ordinary_timeout(time_point t, caf::abstract_actor* self,
                            caf::atom_value type, uint64_t id) override {
    locked([&] { super::set_ordinary_timeout(t, self, type, id); });
  }

  void set_multi_timeout(time_point t, caf::abstract_actor* self,
                         caf::atom_value type, uint64_t id) override {
    locked([&] { super::set_multi_timeout(t, self, type, id); });
  }

  void set_request_timeout(time_point t, caf::abstract_actor* self,
                           caf::message_id id) override {
    locked([&] {
      requests_.push({t, 0, caf::strong_actor_ptr{self->ctrl()}, id, nullptr});
    });
  }

  void cancel_ordinary_timeout(caf::abstract_actor* self,
                               caf::atom_value type) override {
    locked([&] { super::cancel_ordinary_timeout(self, type); }, false);
  }

  void cancel_request_timeout(caf::abstract_actor* self,
                              caf::message_id id) override {
    locked([&] {
      requests_.remove_if([&](const timer_heap::entry& x) {
        return x.id == id && x.target.get() == self->ctrl();
      });
    }, false);
  }

  /// Delayed messages stay: CAF's clock keeps them too.
  void cancel_timeouts(caf::abstract_actor* self) override {
    locked([&] {
      super::cancel_timeouts(self);
      requests_.remove_if([&](const timer_heap::entry& x) {
        return x.target.get() == self->ctrl();
      });
    }, false);
  }

  void schedule_message(time_point t, caf::strong_actor_ptr receiver,
                        caf::mailbox_element_ptr content) override {
    locked([&] {
      messages_.push({t, 0, std::move(receiver), caf::message_id{},
                      std::move(content)});
    });
  }

  /// A delayed message due at `t` that may wait until `latest` for a wake
  /// the loop makes anyway (channels/lax_timer.hpp).
  void schedule_lax(time_point t, time_point latest,
                    caf::strong_actor_ptr receiver,
                    caf::mailbox_element_ptr content) {
    locked([&] {
      lax_.push({t, 0, std::move(receiver), caf::message_id{},
                 std::move(content), latest});
    });
  }

  void schedule_message(time_point t, caf::group target,
                        caf::strong_actor_ptr sender,
                        caf::message content) override {
    locked([&] {
      super::schedule_message(t, std::move(target), std::move(sender),
                              std::move(content));
    });
  }

  void cancel_all() override {
    // Destroyed after the lock is released: the last handle to an actor may
    // go with them, and its cleanup cancels its timeouts here.
    timer_heap messages;
    timer_heap lax;
    timer_heap requests;
    locked([&] {
      super::cancel_all();
      std::swap(messages, messages_);
      std::swap(lax, lax_);
      std::swap(requests, requests_);
    }, false);
  }

private:
  static constexpr auto request_timeout_slack = std::chrono::milliseconds(20);
  static constexpr size_t max_scanned = 64;

  /// Runs `f` under the mutex. A new timeout set by another thread may be
  /// earlier than the loop's wait: wake it (free when it is awake).
  template <class F>
  void locked(F f, bool adds = true) {
    {
      std::lock_guard<std::mutex> guard{mtx_};
      f();
    }
    if (adds && !loop_.in_loop_thread()) {
      changed_.store(true); // before wake(): pairs with sleeping_ (Dekker)
      loop_.wake();
    }
  }

  std::mutex mtx_;
  event_loop& loop_;
  std::atomic<bool> changed_{false};
  timer_heap messages_;
  /// Delayed messages due at their time, fired at their latest time at
  /// the latest (schedule_lax); a few per module.
  timer_heap lax_;
  timer_heap requests_;
  /// What fire_due ships (loop thread only), kept for its capacity.
  std::vector<timer_heap::entry> due_;
};

class loop_coordinator final : public caf::scheduler::abstract_coordinator,
                               public loop_owner,
                               public caf::execution_unit {
public:
  using super = caf::scheduler::abstract_coordinator;

  static caf::actor_system::module* make(caf::actor_system& sys,
                                         caf::detail::type_list<>) {
    auto loop = event_loop::make();
    if (!loop) {
      std::fprintf(stderr, "herm: %s\n", render(loop.error()).c_str());
      std::abort(); // no epoll: nothing of the module can run
    }
    return new loop_coordinator(sys, std::move(*loop));
  }

  loop_coordinator(caf::actor_system& sys, std::unique_ptr<event_loop> loop)
    : super(sys),
      caf::execution_unit(&sys),
      loop_(std::move(loop)),
      clock_(*loop_) {
  }

  // -- loop_owner ------------------------------------------------------------------

  event_loop& io_loop() override {
    return *loop_;
  }

  void schedule_lax(caf::actor_clock::time_point t,
                    caf::actor_clock::time_point latest,
                    caf::strong_actor_ptr receiver,
                    caf::mailbox_element_ptr content) override {
    clock_.schedule_lax(t, latest, std::move(receiver), std::move(content));
  }

  // -- abstract_coordinator ---------------------------------------------------------

  caf::actor_clock& clock() noexcept override {
    return clock_;
  }

  void enqueue(caf::resumable* job) override {
    if (loop_->in_loop_thread()) {
      ready_.push_back(job);
      return;
    }
    {
      std::lock_guard<std::mutex> guard{foreign_mtx_};
      foreign_.push_back(job);
    }
    foreign_count_.fetch_add(1);
    foreign_enqueues_.fetch_add(1, std::memory_order_relaxed);
    loop_->wake();
  }

  void init(caf::actor_system_config& cfg) override {
    super::init(cfg);
    num_workers_ = 1;
    busy_poll_ns_ = static_cast<int64_t>(
                      caf::get_or(cfg, busy_poll_key, size_t{0}))
                    * 1000;
    if (!caf::get_if<size_t>(&static_cast<const caf::actor_system_config&>(cfg),
                             "scheduler.max-throughput"))
      max_throughput_ = default_throughput;
  }

  void start() override {
    thread_ = std::thread{[this] { run(); }};
    super::start(); // the printer (a detached utility actor)
  }

  void stop() override {
    stop_actors();
    loop_->request_stop();
    if (thread_.joinable())
      thread_.join();
    // Whatever is still queued never runs again.
    drain_foreign();
    for (auto* job : ready_)
      cleanup_and_release(job);
    ready_.clear();
    clock_.cancel_all();
  }

  // -- execution_unit ---------------------------------------------------------------

  void exec_later(caf::resumable* job) override {
    ready_.push_back(job); // only ever called by a job this thread runs
  }

  loop_clock& herm_clock() noexcept {
    return clock_;
  }

  loop_stats stats() const {
    loop_stats s;
    s.resumes = resumes_.load(std::memory_order_relaxed);
    s.foreign_enqueues = foreign_enqueues_.load(std::memory_order_relaxed);
    s.sleeps = loop_->sleeps();
    s.wakes = loop_->wakes();
    s.busy_polls = busy_polls_.load(std::memory_order_relaxed);
    return s;
  }

private:
  static constexpr size_t default_throughput = 64;

  /// Actor turns between two looks at the descriptors while actors are ready.
  static constexpr size_t turns_per_poll = 256;

  void run() {
    pthread_setname_np(pthread_self(), "herm-loop");
    super::system().thread_started();
    loop_->set_has_work([this] {
      return foreign_count_.load() > 0 || clock_.take_changed();
    });
    while (!loop_->stop_requested()) {
      drain_foreign();
      run_ready();
      drain_foreign();
      auto wait = ready_.empty() ? clock_.wait_ns() : 0;
      if (wait > 0 && busy_poll_ns_ > 0 && busy_poll())
        wait = 0;
      loop_->run_once(wait);
      clock_.fire_due();
    }
    loop_->leave_thread();
    super::system().thread_terminates();
  }

  /// Polls the descriptors and the foreign queue without sleeping for up to
  /// busy_poll_ns_ (or until a timer is due), so that a packet arriving
  /// soon after the last one finds the thread awake. Returns whether work
  /// turned up. Spins only while fewer loops of this process spin than
  /// there are cores.
  bool busy_poll() {
    static std::atomic<unsigned> spinning{0};
    static const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
    if (spinning.fetch_add(1) >= cores) {
      spinning.fetch_sub(1);
      return false;
    }
    auto until = posix::now_ns() + std::min(busy_poll_ns_, clock_.wait_ns());
    bool found = false;
    while (!found && posix::now_ns() < until && !loop_->stop_requested()) {
      found = loop_->run_once(0) > 0 || foreign_count_.load() > 0
              || !ready_.empty();
      busy_polls_.fetch_add(1, std::memory_order_relaxed);
    }
    spinning.fetch_sub(1);
    return found;
  }

  void drain_foreign() {
    if (foreign_count_.load() == 0)
      return;
    std::lock_guard<std::mutex> guard{foreign_mtx_};
    foreign_count_.store(0);
    for (auto* job : foreign_)
      ready_.push_back(job);
    foreign_.clear();
  }

  void run_ready() {
    for (size_t n = 0; n < turns_per_poll && !ready_.empty(); ++n) {
      auto* job = ready_.front();
      ready_.pop_front();
      resumes_.fetch_add(1, std::memory_order_relaxed);
      switch (job->resume(this, max_throughput_)) {
        case caf::resumable::resume_later:
          ready_.push_back(job); // keeps its reference
          break;
        case caf::resumable::done:
        case caf::resumable::awaiting_message:
          intrusive_ptr_release(job);
          break;
        case caf::resumable::shutdown_execution_unit:
          break; // not used by this scheduler
      }
    }
  }

  std::unique_ptr<event_loop> loop_;
  loop_clock clock_;
  std::thread thread_;

  // Loop thread.
  std::deque<caf::resumable*> ready_;

  // Any thread.
  std::mutex foreign_mtx_;
  std::vector<caf::resumable*> foreign_;
  std::atomic<size_t> foreign_count_{0};
  std::atomic<uint64_t> foreign_enqueues_{0};
  std::atomic<uint64_t> resumes_{0};
  std::atomic<uint64_t> busy_polls_{0};
  int64_t busy_poll_ns_ = 0;
};

} // namespace

void load_loop_scheduler(caf::actor_system_config& cfg, size_t busy_poll_us) {
  cfg.load<loop_coordinator>();
  // Straight into the settings: CAF refuses set() for undeclared options.
  caf::put(cfg.content, busy_poll_key, busy_poll_us);
}

loop_stats loop_stats_of(caf::actor_system& sys) {
  if (auto* lc = dynamic_cast<loop_coordinator*>(&sys.scheduler())) {
    auto s = lc->stats();
    s.request_timeouts = lc->herm_clock().requests_waiting();
    return s;
  }
  return {};
}

void request_answered(caf::actor_system& sys, caf::abstract_actor* requester,
                      caf::message_id response_id) {
  if (auto* lc = dynamic_cast<loop_coordinator*>(&sys.scheduler()))
    lc->herm_clock().request_answered(requester, response_id);
}

} // namespace herm
