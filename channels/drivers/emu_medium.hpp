#pragma once

// The emulated medium: what the link kind "emu" (channels/drivers/emu.cpp)
// and the can kind's emulated bus (channels/drivers/can_emu.cpp) share.
//
// A medium is a directory (channels/drivers/medium_dir.hpp): every station
// binds an AF_UNIX datagram socket <dir>/<N>.sock (N in 1..254), and a
// shared, mmapped state file in the directory (its layout belongs to the
// kind of medium) holds what all stations must agree on, in CLOCK_MONOTONIC
// ns (system-wide, so every process agrees). Joining serialises on
// flock(state file).
//
// Two layers:
//  * pure parts (dice, copies/fate_of_copy, reserve, arbitrate, hold_queue):
//    no clock, no I/O; time and random draws go in as arguments, so they are
//    tested table-driven (tests/channels/emu_medium_test.cpp);
//  * `station`: one station's I/O on the medium (directory, state file,
//    station claim, sockets, fan-out to peers, receiving on the module's
//    event loop with its hold queue, liveness of its files). What differs
//    between kinds of medium (state file layout, who may join, datagram
//    codec, delivery) is asked of a `medium_client` the driver implements.
//
// Threads: receiving runs on the module's event loop (channels/
// event_loop.hpp): the station watches its receive socket there and keeps
// two loop timers, one for the earliest held datagram (latency, jitter,
// end of transmission) and one for the liveness check of its files; it
// owns no receive thread. Transmitting runs on the loop too: each driver's
// transmit step (tx_pump; send_to, for_each_peer, retry_stalled) is the
// emulated wire. It never sleeps: it waits out frame times at the
// medium's bandwidth and, on the CAN bus, a busy bus and arbitration
// back-offs with loop timers, and it never blocks on a receiver's full
// queue (the datagram stalls and is retried). A fatal transmit error
// reaches the loop with event_loop::post. start_receiving, stop_receiving,
// request_stop, failed and counters may be called from any thread; open
// and leave by the driver's life cycle only (leave: after the transmit
// step stopped and stop_receiving returned).

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <caf/expected.hpp>

#include "channels/event_loop.hpp"

#include <sys/types.h>
#include <sys/un.h>

#include "channels/drivers/emu_wire.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"
#include "channels/link_driver.hpp"

namespace herm::emu_medium {

// -- limits -------------------------------------------------------------------

/// Station numbers on every emulated medium (the file names N.sock).
constexpr uint64_t min_station = 1;
constexpr uint64_t max_station = 254;

/// How often a receiving station checks that its files still exist when it
/// cannot watch the medium's directory with inotify (the per-user limit of
/// inotify instances, fs.inotify.max_user_instances, is reached). With
/// inotify an idle station checks only when a file of the medium changes.
constexpr int64_t liveness_period_ns = 100'000'000;
/// Peers are rescanned at least this often (and whenever a station joins
/// or leaves through a driver: the state file's generation counter).
constexpr int64_t rescan_period_ns = 100'000'000;
/// Grace period a transmitter gives a receiver whose socket queue is full
/// before the frame counts as an overrun (station::retry_stalled).
constexpr int64_t overrun_wait_ns = 25'000'000;
/// Datagrams a station keeps for receivers whose queues are full
/// (station::send_to); beyond, they are overruns.
constexpr size_t max_stalled = 512;
/// How often such a station retries them.
constexpr int64_t stall_retry_ns = 200'000;
/// Frames one transmit step sends at most (a burst on credit) before the
/// loop's other work, receiving included, gets its turn.
constexpr int max_frames_per_step = 16;
/// Bound of the back-to-back credit (see reserve, emu::transmission_start).
constexpr int64_t max_credit_ns = 50'000'000;
/// Datagrams a receiver holds for later delivery; above this, the earliest
/// is handed up early rather than dropped.
constexpr size_t max_held_frames = 4096;
/// Datagrams read, and held datagrams delivered, per loop callback: one
/// busy medium cannot starve the other descriptors on the loop (epoll is
/// level-triggered, so what is left is handled in the next turn).
constexpr int max_reads_per_wakeup = 64;

// -- pure parts: impairments ---------------------------------------------------

/// The medium's random decisions from one seeded generator. The sequence of
/// draws is part of what a seed reproduces, so each function states what it
/// draws. Not thread-safe: one owner (a transmit step).
class dice {
public:
  explicit dice(uint64_t seed) : rng_(seed) {
  }

  /// True with probability `p` (in [0, 1]). Draws one number only when
  /// p > 0: a medium without an impairment leaves later draws unchanged.
  bool chance(double p) {
    return p > 0 && std::uniform_real_distribution<double>{0.0, 1.0}(rng_) < p;
  }

  /// Uniform in [0, max]; draws only when max > 0 (else 0).
  int64_t up_to(int64_t max) {
    return max > 0 ? std::uniform_int_distribution<int64_t>{0, max}(rng_) : 0;
  }

  /// Uniform bit index in [0, bits); one draw. bits > 0.
  size_t bit_of(size_t bits) {
    return std::uniform_int_distribution<size_t>{0, bits - 1}(rng_);
  }

private:
  std::mt19937_64 rng_;
};

/// What a medium does to each frame for each receiver. Probabilities in
/// [0, 1], times in ns (>= 0).
struct impairments {
  double loss = 0;
  double duplicate = 0;
  double corrupt = 0;
  int64_t latency_ns = 0;
  int64_t jitter_ns = 0;
};

/// How many copies of a frame reach one receiver: 0 (lost with probability
/// loss), else 2 with probability duplicate, else 1. Draws: loss, then (when
/// not lost) duplicate, each only when its probability is > 0.
int copies(dice& d, const impairments& imp);

/// One copy of a frame as it reaches its receiver.
struct copy_fate {
  /// end of transmission + latency + a jitter in [0, jitter_ns].
  int64_t deliver_at_ns = 0;
  /// The payload bit the medium flipped (byte bit / 8, mask 1 << bit % 8),
  /// or -1.
  int64_t flipped_bit = -1;
};

/// The fate of one copy of a `payload`-byte frame whose transmission ends
/// at `end_ns`. Draws: jitter (if > 0), then, for a non-empty payload,
/// corrupt (if > 0) and, when it hits, the bit.
copy_fate fate_of_copy(dice& d, const impairments& imp, int64_t end_ns,
                       size_t payload);

// -- pure parts: medium access -------------------------------------------------

/// Reserves `frame_ns` of medium time on a shared "busy until" word (ns) for
/// a frame handed to the driver at `enqueued_at`: the transmission starts at
/// emu::transmission_start(busy, enqueued_at, now(), max_credit_ns).
/// Returns its end. Lock-free; reservations never overlap, as each starts
/// at or after the busy time it replaces. `now` is called once per attempt.
template <class Clock>
int64_t reserve(std::atomic<int64_t>& busy_until, int64_t enqueued_at,
                int64_t frame_ns, Clock&& now) {
  auto busy = busy_until.load();
  int64_t end = 0;
  do {
    end = emu::transmission_start(busy, enqueued_at, now(), max_credit_ns)
          + frame_ns;
  } while (!busy_until.compare_exchange_weak(busy, end));
  return end;
}

/// A frame waiting for a contended bus: its arbitration key (lower wins)
/// and when it was ready (ns).
struct contender {
  uint32_t key = 0;
  int64_t ready_at = 0;
};

struct arbitration {
  /// `mine` may take the bus.
  bool wins = false;
  /// When the arbitration happened: max(busy, earliest ready time).
  int64_t point = 0;
};

/// Decides the arbitration `mine` takes part in on a bus idle since `busy`:
/// it happens at the first moment the bus was idle and some frame was
/// ready; every frame ready by then competes and the lowest key wins (ties
/// go to `mine`: keys on a bus are unique). `mine` loses when it was not
/// ready yet at that point. O(rivals).
arbitration arbitrate(contender mine, const contender* rivals, size_t count,
                      int64_t busy);

// -- pure parts: the hold queue ------------------------------------------------

/// A copy of `size` bytes of `data` in the last buffer of `spare`, taken out
/// of it so that its capacity is reused (steady traffic allocates nothing),
/// or in a new buffer when `spare` is empty. O(size).
inline std::vector<uint8_t>
copy_reusing(std::vector<std::vector<uint8_t>>& spare, const uint8_t* data,
             size_t size) {
  std::vector<uint8_t> result;
  if (!spare.empty()) {
    result = std::move(spare.back());
    spare.pop_back();
  }
  result.assign(data, data + size);
  return result;
}

/// Received datagrams held until their delivery time, earliest first, in
/// arrival order among equal times. Capacity is the caller's to enforce
/// (full(): deliver the earliest early). Loop thread only.
/// Memory: the datagrams held plus at most `spare_buffers` recycled ones.
class hold_queue {
public:
  static constexpr size_t spare_buffers = 64;

  explicit hold_queue(size_t capacity) : capacity_(capacity) {
  }

  bool empty() const {
    return heap_.empty();
  }

  size_t size() const {
    return heap_.size();
  }

  bool full() const {
    return heap_.size() >= capacity_;
  }

  /// Earliest delivery time (ns). Precondition: !empty().
  int64_t next_due() const {
    return heap_.front().deliver_at;
  }

  /// Whether the earliest datagram is due at `now`.
  bool due(int64_t now) const {
    return !heap_.empty() && heap_.front().deliver_at <= now;
  }

  /// Copies `size` bytes of `data`. Precondition: !full(). O(log n).
  void push(int64_t deliver_at, const uint8_t* data, size_t size);

  /// Removes the earliest datagram and returns its bytes; hand them back
  /// with recycle() when done. Precondition: !empty(). O(log n).
  std::vector<uint8_t> pop();

  /// Keeps `buf` for a later push (up to spare_buffers).
  void recycle(std::vector<uint8_t> buf);

private:
  struct held {
    int64_t deliver_at = 0;
    uint64_t seq = 0;
    std::vector<uint8_t> bytes;
  };

  /// std::*_heap order for a min-heap by (deliver_at, seq).
  static bool later(const held& x, const held& y) {
    return x.deliver_at != y.deliver_at ? x.deliver_at > y.deliver_at
                                        : x.seq > y.seq;
  }

  size_t capacity_;
  uint64_t next_seq_ = 0;
  std::vector<held> heap_;
  std::vector<std::vector<uint8_t>> spare_;
};

// -- the transmit hand-over -----------------------------------------------------

/// The hand-over between send() (any thread) and a driver's transmit step:
/// the mutex that guards the driver's queue (FIFO, priority heap: the
/// driver's own) and the closed flag. Members marked "lock held" need
/// mutex() held by the caller.
class tx_gate {
public:
  std::mutex& mutex() {
    return mtx_;
  }

  /// send(), lock held: ec::device_failed once closed, ec::queue_full when
  /// `queued` frames already wait (`capacity` at most); texts start with
  /// `prefix`.
  caf::error admit(size_t queued, size_t capacity,
                   const std::string& prefix) const;

  /// Lock held.
  bool closed() const {
    return closed_;
  }

  /// Any thread, lock not held: refuses further frames; the transmit step
  /// takes none any more.
  void close() {
    std::lock_guard<std::mutex> guard{mtx_};
    closed_ = true;
  }

private:
  std::mutex mtx_;
  bool closed_ = false;
};

// -- transmitting on the event loop ---------------------------------------------

/// Runs a driver's transmit step on the module's event loop: the emulated
/// wire without a thread of its own. The step sends what the medium lets
/// it send now and, when it must wait (the bus is busy, arbitration lost,
/// a receiver's queue full), asks to run again at a time (at); it never
/// sleeps. send() kicks it: on the loop thread the step runs within the
/// call, from another thread in the loop's next turn.
///
/// Threading: start, kick and stop from any thread; at from the step only.
/// After stop returns no step runs (a task posted earlier finds the flag;
/// the timer is cancelled on the loop).
class station;

class tx_pump {
public:
  tx_pump() = default;
  tx_pump(const tx_pump&) = delete;
  tx_pump& operator=(const tx_pump&) = delete;

  /// Once: the step runs on `loop` from now on, a first time in the loop's
  /// next turn (for frames queued before).
  void start(event_loop& loop, std::function<void()> step);

  bool started() const {
    return loop_.load() != nullptr;
  }

  /// The step runs soon, unless a timer already will run it. No effect
  /// before start or after stop.
  void kick();

  /// From the step: runs it again at `due_ns` (CLOCK_MONOTONIC); the
  /// earliest time asked for wins.
  void at(int64_t due_ns);

  /// From the step: retries `st`'s stalled datagrams (station::retry_stalled)
  /// and, while some remain, runs the step again in stall_retry_ns. True
  /// then: the step sends no further frame.
  bool held_back(station& st);

  /// Idempotent. Not from within the step. Must not be called while
  /// holding anything a loop callback waits for (event_loop::run_sync).
  void stop();

private:
  struct flags {
    std::atomic<bool> stopped{false};
    std::atomic<bool> posted{false};
  };
  void run();

  std::shared_ptr<flags> flags_ = std::make_shared<flags>();
  std::atomic<event_loop*> loop_{nullptr};
  std::function<void()> step_;
  // Loop thread only.
  bool running_ = false;
  event_loop::timer_handle timer_;
  int64_t timer_at_ = 0;
};

// -- one station on a medium ---------------------------------------------------

/// The words naming a kind of medium in errors (users and tests read them).
struct medium_texts {
  /// "medium": "medium directory 'D'", "medium path", "medium file 'F'".
  const char* noun;
  /// "an emu medium file": "'F' is not an emu medium file".
  const char* file_kind;
  /// "emulated link socket": "cannot receive on emulated link socket P".
  const char* socket_noun;
  /// "emulated link": "cannot send on emulated link D".
  const char* link_noun;
  /// "emulated link file": "emulated link file P removed".
  const char* file_noun;
  /// Appended to "<file_noun> P" when the file is gone / replaced.
  const char* removed;
  const char* replaced;
};

/// A kind of medium: its state file and the knobs of its sockets.
struct medium_spec {
  /// Name of the state file in the directory.
  const char* state_file;
  /// Size of the state file in bytes. Its first 8 bytes are a uint32 magic
  /// and a uint32 version (0 and 0: a new file, written on first open).
  size_t state_size;
  uint32_t magic;
  uint32_t version;
  /// Offset of the std::atomic<uint32_t> that counts joins and leaves.
  size_t generation_offset;
  /// Whether the station is among its own peers (for_each_peer).
  bool self_is_peer;
  /// SO_RCVBUF of the receive socket, SO_SNDBUF of the transmit socket;
  /// 0: the system's default. Best effort (capped by net.core.*mem_max).
  int rcvbuf;
  int sndbuf;
  medium_texts texts;
};

/// What a driver decides for its kind of medium. Each call names its thread.
class medium_client {
public:
  virtual ~medium_client();

  /// open(), under the state file's lock: `live` are the stations on the
  /// medium now (ascending). Checks that this station fits the medium
  /// (resetting the shared state when `live` is empty) and returns its
  /// number in [min_station, max_station], or the error to show.
  virtual caf::expected<uint64_t> admit(void* state,
                                        const std::vector<uint64_t>& live)
    = 0;

  /// open(): "station N is already taken on medium 'D'" for a live station.
  virtual std::string taken(uint64_t station) const = 0;

  /// Loop thread: checks a datagram of `size` bytes (the real size; the
  /// buffer holds min(size, its capacity)). True with `deliver_at` (ns) set,
  /// or false after the client reported it as malformed.
  virtual bool accept(const uint8_t* data, size_t size, int64_t now,
                      int64_t& deliver_at)
    = 0;

  /// Loop thread: a datagram accepted earlier is due.
  virtual void deliver(const uint8_t* data, size_t size) = 0;

  /// Loop thread: a fatal error (receive side, liveness or a transmit
  /// error posted by the transmit step); receiving ends right before.
  /// Called at most once, never after request_stop.
  virtual void fail(caf::error err) = 0;
};

class station {
public:
  enum class send_result {
    ok,   ///< sent, or lost at the receiver (overrun) or not for us
    gone, ///< nobody there (any more)
    fatal ///< reported through report_tx_failure
  };

  /// `dir` without trailing '/', short enough for <dir>/254.sock in a
  /// sockaddr_un; `prefix` starts every error text ("device 'X': ").
  /// `client` must outlive the station.
  station(std::string dir, std::string prefix, const medium_spec& spec,
          medium_client& client);

  /// Unmaps the state file. No thread may use the station any more, and
  /// stop_receiving must have returned (the driver's stop does both).
  ~station();

  station(const station&) = delete;
  station& operator=(const station&) = delete;

  /// Joins the medium: the directory (created when `create`), the state
  /// file (created, sized, checked), the station (client.admit, stale
  /// socket files of dead processes removed) and its sockets. Errors:
  /// ec::device_unavailable (or what admit returns, or ec::already_exists
  /// when the socket is taken), with the paths in the text.
  caf::error open(bool create);

  /// The mapped state file (spec.state_size bytes); null before open().
  void* state() const {
    return state_;
  }

  uint64_t number() const {
    return number_;
  }

  const std::string& dir() const {
    return dir_;
  }

  caf::error fail(ec code, const std::string& what) const;

  // -- transmit side (the driver's transmit step) --------------------------------

  /// Sends one datagram to station `dst` (1..254); never blocks. A datagram
  /// that the receiver's full queue refuses waits in the station (stalled),
  /// and later datagrams to that receiver queue behind it, until
  /// retry_stalled sends them or, after overrun_wait_ns, drops them as
  /// overruns. A receiver that overran once gets no grace period until it
  /// takes a datagram again, so a stuck station cannot stall the medium.
  send_result send_to(uint64_t dst, const uint8_t* data, size_t size);

  /// Calls `f(peer)` (returning send_result) for every station on the
  /// medium (rescanned when one joined or left, or every
  /// rescan_period_ns); peers that are gone are dropped until the next
  /// rescan. False as soon as `f` returns fatal.
  template <class F>
  bool for_each_peer(F&& f) {
    refresh_peers();
    for (size_t i = 0; i < peers_.size();) {
      auto result = f(peers_[i]);
      if (result == send_result::fatal)
        return false;
      if (result == send_result::gone)
        peers_.erase(peers_.begin() + static_cast<ptrdiff_t>(i));
      else
        ++i;
    }
    return true;
  }

  /// Whether datagrams wait for a receiver (send_to).
  bool stalled() const {
    return !stalled_.empty();
  }

  /// Sends the stalled datagrams that receivers take now, in order per
  /// receiver; drops the rest as overruns once the oldest has waited
  /// overrun_wait_ns without any of them going out. True when none is left.
  /// O(stalled); memory: at most max_stalled datagrams.
  bool retry_stalled(int64_t now);

  /// Marks the station failed and hands a fatal transmit error to the
  /// loop (event_loop::post), which reports it through client.fail unless
  /// receiving ended first; the first error wins. Before start_receiving
  /// the error waits for it.
  void report_tx_failure(caf::error err);

  // -- receiving on the event loop (any thread) -------------------------------

  /// Starts receiving on `loop`, which must outlive stop_receiving: watches
  /// the receive socket (readiness callback: reads up to
  /// max_reads_per_wakeup datagrams of up to `max_datagram` bytes, has the
  /// client accept them, delivers the due ones and holds the others), arms
  /// a loop timer for the earliest held datagram (max_held_frames), and
  /// checks that the socket and state files are still ours whenever an
  /// entry of the medium's directory is removed, renamed or created
  /// (inotify, watched on the loop), or every liveness_period_ns where
  /// inotify is unavailable. Registers through loop.run_sync; starts no thread.
  /// Once per station. Errors: ec::device_failed after request_stop,
  /// ec::device_unavailable when the loop refuses the socket.
  caf::error start_receiving(event_loop& loop, size_t max_datagram);

  /// request_stop, then unwatches the socket and cancels both timers on the
  /// loop (run_sync; waits for a callback in progress on another thread).
  /// Idempotent. After it returns the client is called no more. Called
  /// from a client call (the loop thread), the callback that made that call
  /// notices request_stop as soon as the call returns and touches neither
  /// the station nor its descriptors again, so the driver may leave (even
  /// destroy the station) at once.
  void stop_receiving();

  /// The loop calls the client no more once the callback in progress
  /// returns; report_tx_failure posts nothing that would.
  void request_stop();

  bool stopping() const {
    return stop_->load();
  }

  /// After a fatal error (transmit or receive side).
  bool failed() const {
    return failed_.load();
  }

  /// Datagrams lost because a receiver's queue was full.
  uint64_t overruns() const {
    return overruns_.load();
  }

  // -- life cycle ---------------------------------------------------------------

  /// Leaves the medium once the transmit step has stopped and
  /// stop_receiving returned: removes our socket file (unless somebody
  /// else's replaced it), tells transmitters, closes both sockets.
  void leave();

private:
  caf::error open_directory(bool create);
  caf::error open_state(posix::unique_fd& lock_fd);
  caf::error claim();
  void refresh_peers();
  std::atomic<uint32_t>& generation() const;
  caf::error check_files() const;
  caf::error attach(event_loop& loop, size_t max_datagram);
  void detach();
  void on_readable(const std::atomic<bool>& stop);
  bool deliver_due(const std::atomic<bool>& stop);
  bool deliver_front(const std::atomic<bool>& stop);
  void on_hold_timer(const std::atomic<bool>& stop);
  void arm_hold_timer();
  void on_liveness_timer();
  void arm_liveness_timer();
  bool watch_files(event_loop& loop);
  void on_files_changed();
  void on_tx_failure();
  void report_failure(caf::error err);

  const std::string dir_;
  const std::string prefix_; // "device 'NAME': "
  const medium_spec spec_;
  const std::string state_path_;
  medium_client& client_;

  void* state_ = nullptr;
  uint64_t number_ = 0;
  std::string sock_path_;
  dev_t state_dev_ = 0;
  ino_t state_ino_ = 0;
  dev_t sock_dev_ = 0;
  ino_t sock_ino_ = 0;
  posix::unique_fd rx_fd_;
  posix::unique_fd tx_fd_;

  /// request_stop's flag, shared with every callback and posted task, which
  /// check it before touching the station: a station destroyed on the loop
  /// thread (stop from a handler) leaves them harmless.
  std::shared_ptr<std::atomic<bool>> stop_
    = std::make_shared<std::atomic<bool>>(false);
  std::atomic<bool> failed_{false};
  /// The loop given to start_receiving (null before).
  std::atomic<event_loop*> loop_{nullptr};
  std::atomic<uint64_t> overruns_{0};

  // Transmit side only (the transmit step).
  send_result stall(uint64_t dst, const uint8_t* data, size_t size);
  struct stalled_datagram {
    uint64_t dst = 0;
    std::vector<uint8_t> bytes;
  };
  std::vector<stalled_datagram> stalled_;
  int64_t stall_since_ = 0;
  sockaddr_un peer_addrs_[max_station + 1] = {};
  bool congested_[max_station + 1] = {};
  std::vector<uint64_t> peers_;
  bool peers_valid_ = false;
  uint32_t peers_generation_ = 0;
  int64_t peers_scanned_at_ = 0;

  // Failure handed from the transmit step to the loop; post_to_ is the
  // loop while receiving (set and cleared on the loop thread).
  std::mutex failure_mtx_;
  caf::error tx_failure_;
  event_loop* post_to_ = nullptr;

  // Loop thread only.
  bool receiving_ = false; // socket watched, timers armed when due
  std::vector<uint8_t> rx_buf_;
  hold_queue held_{max_held_frames};
  event_loop::timer_handle hold_timer_;
  int64_t hold_timer_at_ = 0;
  event_loop::timer_handle liveness_timer_;
  posix::unique_fd notify_fd_; // inotify on dir_, while receiving
};

// -- a driver's life cycle over its station -----------------------------------

/// The start/stop life cycle both emulated drivers (emu, the emulated CAN
/// bus) share: opened, then started (receiving on the module's event loop),
/// then stopped for good. It owns the lock, the state, the frame handler
/// and the transmit step's pump; the driver owns the station and the
/// transmit gate.
///
/// Errors agree with the descriptor drivers (loop_watch.hpp): a null handler
/// is ec::invalid_parameter ("start needs a frame handler"), a second start
/// ec::device_unavailable ("already started"), a start after stop
/// ec::device_unavailable ("already stopped"); texts start with the
/// station's "device 'NAME': ".
///
/// The handler and stop from inside a handler call: stop drops the handler
/// at once, so every client callback that calls the handler holds a copy of
/// handler() for the duration of the call (as the descriptor drivers'
/// readiness callbacks do); nothing is posted to the loop, which may be
/// gone by then.
///
/// Threading: start and stop from any thread, stop also from a handler
/// call; neither holds the lock while station::start_receiving,
/// stop_receiving or the pump wait for the loop thread (whose handlers may
/// call stop).
class station_life {
public:
  /// Refuses as above, then keeps `handler`, starts receiving on `loop`
  /// datagrams of up to `max_datagram` bytes and runs `step` (the driver's
  /// transmit step) on `loop` through pump(). If start_receiving fails its
  /// error is returned and the handler dropped.
  caf::error start(station& st, std::shared_ptr<frame_handler> handler,
                   event_loop& loop, size_t max_datagram,
                   std::function<void()> step);

  /// Idempotent. Stops the transmit step, closes `gate` (no frame is taken
  /// any more), ends delivery (station::stop_receiving), then, the first
  /// time only and under the lock: `teardown` (clear what the station
  /// published), station::leave, and drops the handler. No handler call
  /// and no step starts after it returns.
  void stop(station& st, tx_gate& gate, const std::function<void()>& teardown);

  /// What runs the driver's transmit step (kick from send(), at and
  /// held_back from the step).
  tx_pump& pump() {
    return pump_;
  }

  /// The handler while started; null before and after. Loop thread (client
  /// callbacks): keep the copy while calling it.
  std::shared_ptr<frame_handler> handler() const {
    return handler_;
  }

private:
  std::mutex mtx_;
  bool started_ = false;
  bool stopped_ = false;
  /// Written under mtx_ before receiving starts and after it ended; read
  /// by the loop thread in between only.
  std::shared_ptr<frame_handler> handler_;
  tx_pump pump_;
};

} // namespace herm::emu_medium
