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
#include "caf/resumable.hpp"
#include "caf/settings.hpp"
#include "caf/scheduler/abstract_coordinator.hpp"

#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"
#include "channels/event_loop.hpp"

namespace herm {

namespace {

constexpr char busy_poll_key[] = "herm.busy-poll-us";

/// CAF's simple clock behind a mutex. The loop thread asks it for the next
/// due time before it sleeps and fires what is due after each wait; another
/// thread that sets a timeout wakes the loop so it recomputes its wait.
class loop_clock final : public caf::detail::simple_actor_clock {
public:
  using super = caf::detail::simple_actor_clock;

  explicit loop_clock(event_loop& loop) : loop_(loop) {
  }

  /// Nanoseconds until the loop must wake for a timeout (0 when one is
  /// due), or INT64_MAX. A request timeout may wait up to
  /// request_timeout_slack past its time for a wake the loop makes anyway
  /// (fire_due fires everything due after every wait): CAF 0.17 never
  /// cancels a request's timeout when the response comes, so every answered
  /// request leaves one that fires for nothing, and without the slack each
  /// would wake the loop on its own.
  int64_t wait_ns() {
    std::lock_guard<std::mutex> guard{mtx_};
    if (schedule_.empty())
      return std::numeric_limits<int64_t>::max();
    auto wake = schedule_.begin()->first;
    if (is_request_timeout(*schedule_.begin())) {
      wake += request_timeout_slack;
      // The first entry of another kind before that sets the wake; after
      // max_looked request timeouts in a row, the last one does (earlier
      // than needed, never later).
      size_t looked = 0;
      for (auto i = std::next(schedule_.begin());
           i != schedule_.end() && i->first < wake; ++i)
        if (!is_request_timeout(*i) || ++looked == max_looked) {
          wake = i->first;
          break;
        }
    }
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

  size_t fire_due() {
    std::lock_guard<std::mutex> guard{mtx_};
    return trigger_expired_timeouts();
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
    locked([&] { super::set_request_timeout(t, self, id); });
  }

  void cancel_ordinary_timeout(caf::abstract_actor* self,
                               caf::atom_value type) override {
    locked([&] { super::cancel_ordinary_timeout(self, type); }, false);
  }

  void cancel_request_timeout(caf::abstract_actor* self,
                              caf::message_id id) override {
    locked([&] { super::cancel_request_timeout(self, id); }, false);
  }

  void cancel_timeouts(caf::abstract_actor* self) override {
    locked([&] { super::cancel_timeouts(self); }, false);
  }

  void schedule_message(time_point t, caf::strong_actor_ptr receiver,
                        caf::mailbox_element_ptr content) override {
    locked([&] {
      super::schedule_message(t, std::move(receiver), std::move(content));
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
    locked([&] { super::cancel_all(); }, false);
  }

private:
  static constexpr auto request_timeout_slack = std::chrono::milliseconds(20);
  static constexpr size_t max_looked = 64;

  static bool is_request_timeout(const schedule_map::value_type& x) {
    return x.second->subtype == request_timeout_type;
  }

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
  if (auto* lc = dynamic_cast<loop_coordinator*>(&sys.scheduler()))
    return lc->stats();
  return {};
}

} // namespace herm
