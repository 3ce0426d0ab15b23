// The emulated CAN bus: the backend of link kind "can" for interface
// "emu:/path/to/bus-directory", for hosts without CAN. An emulated medium
// (channels/drivers/emu_medium.hpp): stations in any number of processes,
// each with a unix datagram socket <dir>/<node>.sock, and a shared mmapped
// file <dir>/bus holding the bus state: "busy until" (CLOCK_MONOTONIC ns)
// and one slot per node in which a station publishes the arbitration key
// and ready time of the frame it wants to send next. Arbitration: when the
// bus is idle, the frames that were ready at the first moment the bus was
// idle with something to send compete, and only the station with the
// lowest identifier among them may take the bus, by compare-and-swap of
// "busy until" (so exactly one station wins an idle period, and bus time is
// never handed out twice). The winner sends the frame (struct can_frame /
// canfd_frame bytes behind a small header, can_emu_wire.hpp) to every other
// station with the time its transmission ends; receivers hold frames until
// then, so all hear the bus in one order, and filter by destination like a
// controller. Frame times are real CAN frame lengths at the configured bit
// rate (can::frame_bits). See transmit_step and docs/protocol.md.
//
// Threads: none of its own. Receiving runs on the event loop given to
// start() (the station's readiness callback and loop timers,
// emu_medium.hpp), and so does transmitting: the emulated bus is a
// transmit step (transmit_step) that arbitrates, paces at the bit rate and
// fans out, and waits for the bus with loop timers instead of sleeping
// (emu_medium::tx_pump). The frame_handler is called on the loop thread
// only, on_failure at most once. send() never blocks beyond a mutex: on
// the loop thread the step runs within it, from another thread in the
// loop's next turn. stop() (any thread, idempotent, also from a handler)
// stops the step, unwatches and cancels on the loop and leaves the bus;
// no handler call follows its return. Frames sent before start wait for
// it (they take part in no arbitration until then).

#include "channels/drivers/can_emu.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

#include <linux/can.h>
#include <linux/can/error.h>

#include "channels/drivers/can_emu_wire.hpp"
#include "channels/drivers/can_id.hpp"
#include "channels/drivers/emu_medium.hpp"
#include "channels/drivers/medium_dir.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"
#include "channels/options.hpp"

namespace herm::can {

namespace {

using posix::now_ns;
using medium_dir::join_numbers;
using send_result = emu_medium::station::send_result;

// -- constants -------------------------------------------------------------------

/// Slots of the bus file, indexed by node id.
constexpr size_t bus_slots = 256;
constexpr uint32_t bus_magic = 0x4E414348; // "HCAN"
constexpr uint32_t bus_version = 1;

/// A station waiting for the bus refreshes its heartbeat at least this often.
constexpr int64_t heartbeat_period_ns = 100'000'000;
/// A published frame whose station has not shown a heartbeat for this long
/// belongs to a dead or stopped process: arbitration ignores it.
constexpr int64_t stale_ns = 1'000'000'000;
/// How long a station that lost arbitration waits before looking again (the
/// winner takes the bus within microseconds).
constexpr int64_t backoff_ns = 20'000;
/// Bits an error frame adds after a destroyed frame: error flag (6) plus
/// superposition (6), delimiter (8), intermission (3).
constexpr uint32_t error_frame_bits = 23;

// -- emulated bus: shared state ----------------------------------------------------

/// What a station wants to send next. Written by its own transmit path only.
struct bus_slot {
  /// 0: nothing; else 1 << 32 | can::arbitration_key of the frame.
  std::atomic<uint64_t> pending;
  /// When that frame was handed to the driver, CLOCK_MONOTONIC ns.
  std::atomic<int64_t> ready_at;
  /// Last sign of life of the station's transmit path, CLOCK_MONOTONIC ns.
  std::atomic<int64_t> heartbeat;
  std::atomic<int64_t> reserved;
};

/// Layout of <dir>/bus. Lives in MAP_SHARED memory of several processes:
/// only lock-free atomics, no pointers.
struct bus_layout {
  uint32_t magic;
  uint32_t version;
  /// Bit rate of the stations on the bus, bit/s.
  std::atomic<uint64_t> bitrate;
  /// Bumped whenever a station binds or unbinds, so transmitters rescan.
  std::atomic<uint32_t> generation;
  uint32_t reserved0;
  uint8_t reserved[40];
  /// The bus is occupied until then, CLOCK_MONOTONIC ns. Only grows.
  std::atomic<int64_t> busy_until;
  uint8_t reserved1[56];
  bus_slot slots[bus_slots];
};

static_assert(std::atomic<int64_t>::is_always_lock_free,
              "the bus file needs address-free 64-bit atomics");
static_assert(std::atomic<uint64_t>::is_always_lock_free,
              "the bus file needs address-free 64-bit atomics");
static_assert(std::atomic<uint32_t>::is_always_lock_free,
              "the bus file needs address-free 32-bit atomics");
static_assert(sizeof(bus_slot) == 32, "the bus file layout is shared");
static_assert(sizeof(bus_layout) == 128 + 32 * bus_slots,
              "the bus file layout is shared");


const emu_medium::medium_spec bus_spec{
  "bus",
  sizeof(bus_layout),
  bus_magic,
  bus_version,
  offsetof(bus_layout, generation),
  /*self_is_peer=*/true, // error frames reach the sender too
  /*rcvbuf=*/1 << 20,
  /*sndbuf=*/0,
  {"bus", "an emulated CAN bus file", "emulated CAN socket",
   "emulated CAN bus", "emulated CAN bus file", " was removed",
   " was replaced"},
};

// -- the driver ------------------------------------------------------------------

class emu_can_driver final : public can_driver, emu_medium::medium_client {
public:
  explicit emu_can_driver(can_config cfg)
    : can_driver(std::move(cfg)),
      station_(cfg_.interface, prefix_, bus_spec, *this),
      loss_(cfg_.loss),
      error_rate_(cfg_.error_rate),
      dice_(cfg_.seed) {
  }

  ~emu_can_driver() override {
    stop();
  }

  /// Joins the bus: directory, bus file, station socket.
  caf::error open() {
    return station_.open(cfg_.create);
  }

  // -- link_driver ---------------------------------------------------------------

  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop& loop) override {
    return life_.start(station_, std::move(handler), loop,
                       wire::header_size + CANFD_MTU,
                       [this] { transmit_step(); });
  }

  void stop() override {
    life_.stop(station_, gate_, [this] {
      if (station_.state() != nullptr) {
        auto& me = bus().slots[cfg_.node];
        me.pending.store(0);
        me.heartbeat.store(0);
      }
    });
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t priority) override {
    tx_frame f;
    auto n = build(dst, data, size, priority, f.frame);
    if (!n)
      return n.error();
    if (station_.failed())
      return fail(ec::device_failed, "the bus has failed");
    f.wire_size = *n;
    f.key = can::arbitration_key(f.frame.can_id);
    f.order = std::min(priority, can::max_priority);
    f.bits = can::frame_bits(cfg_.format, f.frame.len, cfg_.stuffing);
    f.enqueued_at = now_ns();
    {
      std::lock_guard<std::mutex> guard{gate_.mutex()};
      if (auto err = gate_.admit(queue_.size(), cfg_.queue, prefix_))
        return err;
      f.seq = next_seq_++;
      queue_.push_back(f);
      std::push_heap(queue_.begin(), queue_.end(), later);
      // Published before send() returns: from now on, the frame takes
      // part in every arbitration on the bus. Not before start: nothing
      // would transmit it.
      if (life_.pump().started())
        publish(queue_.front());
    }
    life_.pump().kick();
    return caf::none;
  }

  caf::error set_param(const std::string& key,
                       const std::string& value) override {
    device_config tmp{cfg_.name, "can", emu_scheme + cfg_.interface,
                      {{key, value}}};
    option_reader r{tmp};
    if (key == "loss")
      return read_into(loss_, r.real(key, 0, 0, 1));
    if (key == "error_rate")
      return read_into(error_rate_, r.real(key, 0, 0, 0.9));
    return fail(ec::invalid_parameter,
                "parameter '" + key
                  + "' cannot be changed on an emulated CAN bus (changeable: "
                    "loss, error_rate)");
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "backend")
      return std::string{"emu"};
    if (key == "loss")
      return format_double(loss_.load());
    if (key == "error_rate")
      return format_double(error_rate_.load());
    static constexpr counter_param<emu_can_driver> counters[] = {
      {"tx_lost", &emu_can_driver::tx_lost_},
      {"tx_errors", &emu_can_driver::tx_errors_},
      {"arbitration_lost", &emu_can_driver::arbitration_lost_},
    };
    if (auto value = read_counter(*this, counters, key))
      return *value;
    if (key == "tx_overruns")
      return std::to_string(station_.overruns());
    return can_driver::get_param(key);
  }

private:
  struct tx_frame {
    /// Arbitration key on the bus (can::arbitration_key).
    uint32_t key = 0;
    /// Order in our own queue: the priority (0..7).
    uint8_t order = 0;
    uint64_t seq = 0;
    int64_t enqueued_at = 0;
    uint32_t bits = 0;
    size_t wire_size = 0;
    canfd_frame frame;
  };

  /// std::*_heap comparator of the transmit queue: most urgent priority
  /// first, FIFO within a priority, so a control frame overtakes bulk
  /// frames queued before it. Receivers reassemble per lane (priority and
  /// broadcast, can::lane_of), so that costs no packet. (A controller whose
  /// mailboxes arbitrate by full identifier also lets unicasts overtake a
  /// broadcast of the same priority: another lane, also harmless.)
  static bool later(const tx_frame& x, const tx_frame& y) {
    return x.order != y.order ? x.order > y.order : x.seq > y.seq;
  }


  bus_layout& bus() const {
    return *static_cast<bus_layout*>(station_.state());
  }

  // -- medium_client: joining ----------------------------------------------------

  /// Checks the bus's bit rate and claims the node id.
  caf::expected<uint64_t> admit(void* state,
                                const std::vector<uint64_t>& live) override {
    auto& b = *static_cast<bus_layout*>(state);
    auto& dir = cfg_.interface;
    if (live.empty()) {
      // First station: it sets the bit rate; state of earlier users goes.
      b.bitrate.store(cfg_.bitrate);
      b.busy_until.store(0);
      for (auto& slot : b.slots) {
        slot.pending.store(0);
        slot.ready_at.store(0);
        slot.heartbeat.store(0);
      }
    } else if (b.bitrate.load() != cfg_.bitrate) {
      return fail(ec::device_unavailable,
                  "bus '" + dir + "' runs at "
                    + std::to_string(b.bitrate.load())
                    + " bit/s (nodes " + join_numbers(live)
                    + "), this device is configured for "
                    + std::to_string(cfg_.bitrate) + " bit/s");
    }
    if (std::find(live.begin(), live.end(), cfg_.node) != live.end())
      return fail(ec::already_exists, taken(cfg_.node));
    auto& me = b.slots[cfg_.node];
    me.pending.store(0);
    me.ready_at.store(0);
    me.heartbeat.store(now_ns());
    return uint64_t{cfg_.node};
  }

  std::string taken(uint64_t node) const override {
    return "node " + std::to_string(node) + " is already on bus '"
           + cfg_.interface + "'";
  }

  // -- arbitration and transmission ------------------------------------------------

  /// Makes `f` this station's published frame and shows a sign of life.
  /// Called with gate_.mutex() held.
  void publish(const tx_frame& f) {
    auto& me = bus().slots[cfg_.node];
    auto word = uint64_t{1} << 32 | f.key;
    me.heartbeat.store(now_ns());
    if (published_ != word || published_ready_ != f.enqueued_at) {
      me.ready_at.store(f.enqueued_at);
      me.pending.store(word);
      published_ = word;
      published_ready_ = f.enqueued_at;
    }
  }

  void unpublish() {
    bus().slots[cfg_.node].pending.store(0);
    published_ = 0;
  }

  /// The arbitration `mine` takes part in (emu_medium::arbitrate), with the
  /// bus idle since `busy` (<= now). Published frames of stations without a
  /// heartbeat for stale_ns (dead or stopped processes) do not count.
  emu_medium::arbitration arbitrate(const tx_frame& mine, int64_t busy,
                                    int64_t now) const {
    emu_medium::contender rivals[bus_slots];
    size_t count = 0;
    for (size_t n = 1; n < bus_slots - 1; ++n) {
      if (n == cfg_.node)
        continue;
      auto& slot = bus().slots[n];
      auto word = slot.pending.load();
      if (word == 0)
        continue;
      auto ready = slot.ready_at.load();
      if (now - slot.heartbeat.load() > stale_ns)
        continue;
      rivals[count++] = {static_cast<uint32_t>(word), ready};
    }
    return emu_medium::arbitrate({mine.key, mine.enqueued_at}, rivals, count,
                                 busy);
  }

  // Arbitration, one frame at a time, in transmit_step on the event loop:
  //  1. The lowest queued frame is published in our slot with its ready
  //     time (send() does that before it returns).
  //  2. While the bus is busy, wait (a loop timer) until it is idle.
  //  3. Decide the arbitration (emu_medium::arbitrate): the frames ready
  //     when the bus first was idle with something to send compete; the
  //     lowest key wins. A loser waits briefly and goes to 2 (the winner
  //     will have taken the bus).
  //  4. The winner's transmission starts at that arbitration point, or at
  //     now - max_credit_ns if the loop came later than that: frames
  //     queued back to back leave no gaps despite wake-up latency, and a
  //     stalled process cannot release an unbounded burst.
  //  5. Take the bus with compare_exchange(busy_until: idle -> start +
  //     frame time). Only one station succeeds per idle period, and busy
  //     periods never overlap, so the bus never carries more than its bit
  //     rate. A station that lost the exchange goes to 2.
  //  6. Send the frame to every other station, to be delivered when the
  //     transmission ends. A receiver whose queue is full gets it later
  //     (station::retry_stalled); meanwhile no further frame goes out.
  void transmit_step() {
    auto& busy_until = bus().busy_until;
    auto& pump = life_.pump();
    if (pump.held_back(station_))
      return;
    std::unique_lock<std::mutex> lk{gate_.mutex()};
    for (int sent = 0; !gate_.closed() && !queue_.empty();) {
      if (station_.failed())
        return;
      if (sent == emu_medium::max_frames_per_step) {
        pump.at(now_ns()); // the loop's other work first
        return;
      }
      auto& head = queue_.front();
      publish(head);
      auto now = now_ns();
      auto busy = busy_until.load();
      if (busy > now) {
        pump.at(std::min(busy, now + heartbeat_period_ns));
        return;
      }
      auto arb = arbitrate(head, busy, now);
      if (!arb.wins) {
        ++arbitration_lost_;
        pump.at(now + backoff_ns);
        return;
      }
      auto start = std::max(arb.point, now - emu_medium::max_credit_ns);
      bool destroyed = dice_.chance(error_rate_.load());
      auto bits = head.bits + (destroyed ? error_frame_bits : 0);
      auto end = start + bits_time_ns(bits, cfg_.bitrate);
      if (!busy_until.compare_exchange_strong(busy, end))
        continue; // somebody else took the bus first
      tx_frame f = head;
      if (!destroyed) {
        std::pop_heap(queue_.begin(), queue_.end(), later);
        queue_.pop_back();
        if (queue_.empty())
          unpublish();
        else
          publish(queue_.front());
      }
      lk.unlock();
      ++sent;
      if (destroyed)
        ++tx_errors_;
      else
        ++tx_frames_;
      if (!station_.failed() && !fan_out(f, end, destroyed, buf_))
        return;
      if (pump.held_back(station_))
        return;
      lk.lock();
    }
    if (gate_.closed())
      unpublish();
  }

  /// Sends one frame (or, when `destroyed`, an error frame) to the stations
  /// on the bus. False after a fatal error.
  bool fan_out(const tx_frame& f, int64_t end, bool destroyed,
               std::vector<uint8_t>& buf) {
    wire::header hdr;
    hdr.flags = destroyed ? wire::flag_error : 0;
    hdr.deliver_at_ns = end;
    wire::encode(hdr, buf.data());
    std::memcpy(buf.data() + wire::header_size, &f.frame, f.wire_size);
    auto size = wire::header_size + f.wire_size;
    auto loss = loss_.load();
    return station_.for_each_peer([&](uint64_t peer) {
      // Every station hears an error frame, the sender included; a data
      // frame goes to every other station (as with CAN_RAW_RECV_OWN_MSGS
      // off). Loss drops a frame for one receiver (not what CAN does, but
      // what the upper layers must survive).
      if ((peer == cfg_.node && !destroyed)
          || (!destroyed && dice_.chance(loss))) {
        if (peer != cfg_.node)
          ++tx_lost_;
        return send_result::ok;
      }
      return station_.send_to(peer, buf.data(), size);
    });
  }

  // -- medium_client: loop thread ------------------------------------------------

  bool accept(const uint8_t* data, size_t size, int64_t now,
              int64_t& deliver_at) override {
    wire::header hdr;
    auto st = wire::check(data, size, now, hdr);
    if (st != wire::status::ok) {
      malformed(*life_.handler(), 0,
                std::string{"emulated bus: "} + wire::to_string(st) + " ("
                  + std::to_string(size) + "-byte datagram)");
      return false;
    }
    deliver_at = hdr.deliver_at_ns;
    return true;
  }

  void deliver(const uint8_t* data, size_t size) override {
    auto hdr = wire::decode(data);
    if ((hdr.flags & wire::flag_error) != 0) {
      // The frame was destroyed on the bus: what arrives is the error.
      canfd_frame err{};
      err.can_id = CAN_ERR_FLAG | CAN_ERR_PROT;
      err.len = CAN_ERR_DLC;
      error_frame(*life_.handler(), err);
      return;
    }
    canfd_frame frame;
    auto nbytes = size - wire::header_size; // CAN_MTU or CANFD_MTU (checked)
    std::memset(&frame, 0, sizeof(frame));
    std::memcpy(&frame, data + wire::header_size, nbytes);
    // The copy keeps the handler alive should it stop the driver.
    dispatch(*life_.handler(), frame, nbytes);
  }

  void fail(caf::error err) override {
    life_.handler()->on_failure(std::move(err));
  }

  using can_driver::fail;

  // -- state ---------------------------------------------------------------------

  emu_medium::station station_;

  std::atomic<double> loss_;
  std::atomic<double> error_rate_;

  emu_medium::station_life life_;

  // Transmit queue (a heap, see `later`) and our slot, guarded by
  // gate_.mutex().
  emu_medium::tx_gate gate_;
  std::vector<tx_frame> queue_;
  uint64_t next_seq_ = 0;
  uint64_t published_ = 0;
  int64_t published_ready_ = 0;

  // The transmit step only (the loop thread).
  emu_medium::dice dice_;
  std::vector<uint8_t> buf_ = std::vector<uint8_t>(wire::header_size + CANFD_MTU);

  // Counters (get_param).
  std::atomic<uint64_t> tx_lost_{0};
  std::atomic<uint64_t> tx_errors_{0};
  std::atomic<uint64_t> arbitration_lost_{0};
};

} // namespace

caf::expected<link_driver_ptr> open_emulated_bus(can_config cfg) {
  auto driver = std::make_shared<emu_can_driver>(std::move(cfg));
  if (auto err = driver->open())
    return err;
  return link_driver_ptr{std::move(driver)};
}

} // namespace herm::can
