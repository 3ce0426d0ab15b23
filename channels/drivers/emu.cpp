// Link kind "emu": an emulated medium for interfaces without hardware here
// (IEEE 1394, USB, CAN without kernel support) and for building topologies
// across processes on one machine.
//
// A medium is a directory of stations (channels/drivers/emu_medium.hpp:
// one AF_UNIX datagram socket <dir>/<station>.sock each). <dir>/medium is
// the shared, mmapped state file whose slots hold "medium busy until" times
// in CLOCK_MONOTONIC ns. A bus shares slot 0 among all stations, a
// point-to-point link gives each of its two stations its own slot (full
// duplex).
//
// Threads: none of its own; everything runs on the event loop given to
// start(). Receiving: the station's readiness callback and loop timers
// (emu_medium.hpp) validate datagrams, hold them until their delivery
// time, check that the socket file still exists and call the
// frame_handler, on the loop thread only, on_failure at most once.
// Transmitting: a transmit step (emu_medium::tx_pump) paces frames at the
// medium's bandwidth, waiting out frame times with loop timers, applies
// loss, duplication, corruption and jitter and sends the datagrams. send()
// is non-blocking (a queue behind a mutex), from any thread: on the loop
// thread the step runs within it, from another in the loop's next turn.
//
// Life cycle: open (joins the medium), start (registers the socket and
// timers with the loop through run_sync, starts the transmit step; once),
// stop (any thread, idempotent, also from a handler: stops the step,
// unwatches and cancels on the loop, leaves the medium; no handler call
// after it returns). Frames sent before start wait for it.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <deque>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <sys/un.h>

#include "channels/error.hpp"
#include "channels/drivers/emu_medium.hpp"
#include "channels/drivers/emu_wire.hpp"
#include "channels/drivers/medium_dir.hpp"
#include "channels/drivers/params.hpp"
#include "channels/drivers/posix.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"

namespace herm {

namespace {

using posix::now_ns;
using medium_dir::join_numbers;
using medium_dir::station_file;

// -- the medium file -------------------------------------------------------------

constexpr uint32_t medium_magic = 0x48454d55; // "HEMU"
constexpr uint32_t medium_version = 1;
constexpr size_t medium_slots = 256;

enum medium_form : uint32_t { form_unset = 0, form_bus = 1, form_p2p = 2 };

/// Layout of <dir>/medium. Lives in MAP_SHARED memory of several processes:
/// only lock-free atomics, no pointers.
struct medium_layout {
  uint32_t magic;
  uint32_t version;
  /// medium_form of the stations currently on the medium.
  std::atomic<uint32_t> form;
  /// Bumped whenever a station binds or unbinds, so transmitters rescan.
  std::atomic<uint32_t> generation;
  uint8_t reserved[48];
  /// "Busy until" per slot, CLOCK_MONOTONIC ns.
  std::atomic<int64_t> busy_until[medium_slots];
};

static_assert(std::atomic<int64_t>::is_always_lock_free,
              "the medium file needs address-free 64-bit atomics");
static_assert(std::atomic<uint32_t>::is_always_lock_free,
              "the medium file needs address-free 32-bit atomics");
static_assert(sizeof(medium_layout) == 64 + 8 * medium_slots,
              "the medium file layout is part of the wire format");

const emu_medium::medium_spec medium_spec{
  "medium",
  sizeof(medium_layout),
  medium_magic,
  medium_version,
  offsetof(medium_layout, generation),
  /*self_is_peer=*/false,
  /*rcvbuf=*/0,
  /*sndbuf=*/4 << 20,
  {"medium", "an emu medium file", "emulated link socket", "emulated link",
   "emulated link file", " removed", " removed (replaced)"},
};

// -- configuration ---------------------------------------------------------------

struct emu_config {
  std::string name;
  std::string dir;
  link_profile profile;
  uint64_t station = 0; // 0: lowest free
  bool p2p = false;
  uint64_t latency_us = 0;
  uint64_t jitter_us = 0;
  double loss = 0;
  double duplicate = 0;
  double corrupt = 0;
  uint64_t seed = 0;
  uint64_t queue = 256;
  bool create = true;
  /// Like Ethernet's FCS and the CRCs of IEEE 1394 and USB: a frame the
  /// medium corrupted is dropped by the receiver and counted as malformed.
  /// false: delivered as it is (to test what the layers above catch).
  bool frame_check = true;
};

caf::expected<emu_config> read_config(const device_config& cfg) {
  option_reader r{cfg};
  emu_config result;
  result.name = cfg.name;
  if (auto err = read_into(result.profile, r.profile("ieee1394a")))
    return err;
  if (r.has("station")) {
    if (auto err = read_into(result.station,
                             r.u64("station", 0, emu::min_station,
                                   emu::max_station)))
      return err;
  }
  auto form = r.str("form", result.profile.multi_access ? "bus" : "p2p");
  if (form != "bus" && form != "p2p")
    return r.fail(ec::invalid_parameter,
                  "option 'form' expects bus or p2p, got '" + form + "'");
  result.p2p = form == "p2p";
  if (auto err = read_into(result.latency_us,
                           r.u64("latency_us", 0, 0, emu::max_latency_us)))
    return err;
  if (auto err = read_into(result.jitter_us,
                           r.u64("jitter_us", 0, 0, emu::max_jitter_us)))
    return err;
  for (auto [key, dst] : {std::pair{"loss", &result.loss},
                          std::pair{"duplicate", &result.duplicate},
                          std::pair{"corrupt", &result.corrupt}}) {
    auto x = r.real(key, 0.0, 0.0, 1.0);
    if (!x)
      return x.error();
    *dst = *x;
  }
  if (r.has("seed")) {
    if (auto err = read_into(result.seed, r.u64("seed", 0, 0, UINT64_MAX)))
      return err;
  } else {
    std::random_device rd;
    result.seed = (uint64_t{rd()} << 32) ^ rd();
  }
  if (auto err = read_into(result.queue, r.u64("queue", 256, 1, 65'536)))
    return err;
  if (auto err = read_into(result.create, r.flag("create", true)))
    return err;
  if (auto err = read_into(result.frame_check, r.flag("frame_check", true)))
    return err;
  if (auto err = r.finish())
    return err;
  result.dir = cfg.interface;
  while (result.dir.size() > 1 && result.dir.back() == '/')
    result.dir.pop_back();
  if (result.dir.empty())
    return r.fail(ec::invalid_parameter,
                  "no medium directory given (the interface of an emu device "
                  "is a directory path)");
  // Longest socket path: <dir>/254.sock.
  auto longest = result.dir.size() + 1 + station_file(254).size();
  if (longest >= sizeof(sockaddr_un::sun_path))
    return r.fail(ec::invalid_parameter,
                  "medium directory '" + result.dir + "' is too long: socket "
                    + "paths in it would take " + std::to_string(longest)
                    + " bytes, unix sockets allow "
                    + std::to_string(sizeof(sockaddr_un::sun_path) - 1));
  return result;
}


// -- the driver ------------------------------------------------------------------

class emu_driver final : public link_driver, emu_medium::medium_client {
public:
  explicit emu_driver(emu_config cfg)
    : cfg_(std::move(cfg)),
      prefix_("device '" + cfg_.name + "': "),
      station_(cfg_.dir, prefix_, medium_spec, *this),
      loss_(cfg_.loss),
      latency_ns_(int64_t(cfg_.latency_us) * 1000),
      jitter_ns_(int64_t(cfg_.jitter_us) * 1000),
      bandwidth_(cfg_.profile.bandwidth_bps),
      dice_(cfg_.seed) {
  }

  ~emu_driver() override {
    stop();
  }

  /// Joins the medium: directory, medium file, station, socket.
  caf::error open() {
    return station_.open(cfg_.create);
  }

  // -- link_driver ---------------------------------------------------------------

  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop& loop) override {
    return life_.start(station_, std::move(handler), loop,
                       emu::wire_header_size + cfg_.profile.mtu,
                       [this] { transmit_step(); });
  }

  void stop() override {
    life_.stop(station_, gate_, [] {});
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > cfg_.profile.mtu)
      return make_error(ec::packet_too_large,
                        prefix_ + "frame of " + std::to_string(size)
                          + " bytes exceeds the MTU of "
                          + std::to_string(cfg_.profile.mtu) + " bytes");
    if (dst != broadcast_addr
        && (dst < emu::min_station || dst > emu::max_station))
      return make_error(ec::invalid_address,
                        prefix_ + "no station " + std::to_string(dst)
                          + " on an emu link (stations are 1..254)");
    if (station_.failed())
      return make_error(ec::device_failed, prefix_ + "the link has failed");
    auto enqueued_at = now_ns();
    {
      std::lock_guard<std::mutex> guard{gate_.mutex()};
      if (auto err = gate_.admit(queue_.size(), cfg_.queue, prefix_))
        return err;
      tx_frame f;
      f.bytes = emu_medium::copy_reusing(spare_, data, size);
      f.dst = dst;
      f.enqueued_at = enqueued_at;
      queue_.push_back(std::move(f));
    }
    life_.pump().kick();
    return caf::none;
  }

  const link_profile& profile() const override {
    return cfg_.profile;
  }

  link_addr local_addr() const override {
    return station_.number();
  }

  std::string format_addr(link_addr addr) const override {
    if (addr == broadcast_addr)
      return "*";
    return std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    auto n = medium_dir::parse_number(str, emu::min_station, emu::max_station);
    if (n == 0)
      return make_error(ec::invalid_address,
                        prefix_ + "'" + str
                          + "' is not an emu station (expected 1..254)");
    return n;
  }

  caf::error set_param(const std::string& key,
                       const std::string& value) override {
    // Parse through option_reader so errors read like option errors.
    device_config tmp{cfg_.name, "emu", cfg_.dir, {{key, value}}};
    option_reader r{tmp};
    if (key == "loss")
      return read_into(loss_, r.real(key, 0, 0, 1));
    if (key == "bandwidth")
      return read_into(bandwidth_, r.u64(key, 0, 1, 100'000'000'000ull));
    if (key == "latency_us") {
      auto x = r.u64(key, 0, 0, emu::max_latency_us);
      if (!x)
        return x.error();
      latency_ns_.store(int64_t(*x) * 1000);
    } else if (key == "jitter_us") {
      auto x = r.u64(key, 0, 0, emu::max_jitter_us);
      if (!x)
        return x.error();
      jitter_ns_.store(int64_t(*x) * 1000);
    } else {
      return make_error(ec::invalid_parameter,
                        prefix_ + "parameter '" + key
                          + "' cannot be changed on an emu link (changeable: "
                            "loss, latency_us, jitter_us, bandwidth)");
    }
    return caf::none;
  }

  caf::expected<std::string> get_param(const std::string& key) const override {
    if (key == "bandwidth")
      return std::to_string(bandwidth_.load());
    if (key == "loss")
      return format_double(loss_.load());
    if (key == "latency_us")
      return std::to_string(latency_ns_.load() / 1000);
    if (key == "jitter_us")
      return std::to_string(jitter_ns_.load() / 1000);
    if (key == "duplicate")
      return format_double(cfg_.duplicate);
    if (key == "corrupt")
      return format_double(cfg_.corrupt);
    if (key == "station")
      return std::to_string(station_.number());
    if (key == "form")
      return std::string{cfg_.p2p ? "p2p" : "bus"};
    if (key == "medium")
      return cfg_.dir;
    // Counters, for tests and diagnostics.
    static constexpr counter_param<emu_driver> counters[] = {
      {"tx_frames", &emu_driver::tx_frames_},
      {"tx_lost", &emu_driver::tx_lost_},
      {"rx_frames", &emu_driver::rx_frames_},
      {"rx_malformed", &emu_driver::rx_malformed_},
    };
    if (auto value = read_counter(*this, counters, key))
      return *value;
    if (key == "tx_overruns")
      return std::to_string(station_.overruns());
    return link_driver::get_param(key);
  }

private:
  struct tx_frame {
    int64_t enqueued_at = 0;
    link_addr dst = 0;
    std::vector<uint8_t> bytes;
  };

  using send_result = emu_medium::station::send_result;

  medium_layout& medium() const {
    return *static_cast<medium_layout*>(station_.state());
  }

  caf::error fail(ec code, const std::string& what) const {
    return station_.fail(code, what);
  }

  // -- medium_client: joining ----------------------------------------------------

  /// Checks the medium's form and picks the station number.
  caf::expected<uint64_t> admit(void* state,
                                const std::vector<uint64_t>& live) override {
    auto& m = *static_cast<medium_layout*>(state);
    auto my_form = cfg_.p2p ? form_p2p : form_bus;
    if (live.empty()) {
      // First station on the medium: it defines the form, and busy times
      // left behind by earlier users (maybe at another bandwidth) go away.
      m.form.store(my_form);
      for (auto& slot : m.busy_until)
        slot.store(0);
    } else if (m.form.load() != my_form) {
      return fail(ec::device_unavailable,
                  "medium '" + cfg_.dir + "' is in use as a "
                    + (cfg_.p2p ? "bus" : "point-to-point link")
                    + " (stations " + join_numbers(live)
                    + "), this device is configured as a "
                    + (cfg_.p2p ? "point-to-point link" : "bus"));
    }
    if (cfg_.p2p && live.size() >= 2)
      return fail(ec::device_unavailable,
                  "medium '" + cfg_.dir
                    + "' is a point-to-point link and already has two "
                      "stations ("
                    + join_numbers(live) + ")");
    auto is_live = [&](uint64_t n) {
      return std::find(live.begin(), live.end(), n) != live.end();
    };
    uint64_t station = 0;
    if (cfg_.station != 0) {
      if (is_live(cfg_.station))
        return fail(ec::already_exists, taken(cfg_.station));
      station = cfg_.station;
    } else {
      for (auto n = emu::min_station; n <= emu::max_station && station == 0;
           ++n)
        if (!is_live(n))
          station = n;
      if (station == 0)
        return fail(ec::device_unavailable,
                    "medium '" + cfg_.dir + "' has no free station");
    }
    if (cfg_.p2p)
      m.busy_until[station].store(0);
    return station;
  }

  std::string taken(uint64_t station) const override {
    return "station " + std::to_string(station)
           + " is already taken on medium '" + cfg_.dir + "'";
  }

  // -- transmit step (the event loop) --------------------------------------------

  /// The emulated wire, on the event loop: takes the next frame, reserves
  /// its time on the medium (emu_medium::reserve: after the frames before
  /// it, back to back on credit) and puts it on the medium when its
  /// transmission ends, waiting for that with a loop timer. At most
  /// emu_medium::max_frames_per_step frames per call; a receiver whose
  /// queue is full holds the next frame back (station::retry_stalled).
  void transmit_step() {
    auto& pump = life_.pump();
    if (pump.held_back(station_))
      return;
    auto& slot = medium().busy_until[cfg_.p2p ? station_.number() : 0];
    for (int sent = 0; !station_.failed();) {
      if (in_flight_) {
        if (now_ns() < in_flight_end_) {
          pump.at(in_flight_end_);
          return;
        }
        auto f = std::move(*in_flight_);
        in_flight_.reset();
        if (!transmit(f, in_flight_end_, buf_))
          return;
        {
          std::lock_guard<std::mutex> guard{gate_.mutex()};
          if (spare_.size() < std::min<uint64_t>(cfg_.queue, 64))
            spare_.push_back(std::move(f.bytes));
        }
        if (pump.held_back(station_))
          return;
        if (++sent == emu_medium::max_frames_per_step) {
          pump.at(now_ns()); // the loop's other work first
          return;
        }
      }
      {
        std::lock_guard<std::mutex> guard{gate_.mutex()};
        if (gate_.closed() || queue_.empty())
          return;
        in_flight_ = std::move(queue_.front());
        queue_.pop_front();
      }
      auto frame_ns = emu::frame_time_ns(in_flight_->bytes.size(),
                                         cfg_.profile.frame_overhead_bits,
                                         bandwidth_.load());
      in_flight_end_ = emu_medium::reserve(slot, in_flight_->enqueued_at,
                                           frame_ns, now_ns);
    }
  }

  /// Puts one frame on the medium. False after a fatal error.
  bool transmit(const tx_frame& f, int64_t end, std::vector<uint8_t>& buf) {
    ++tx_frames_;
    if (f.dst != broadcast_addr)
      return f.dst == station_.number()
             || transmit_to(f.dst, f, end, buf, 0) != send_result::fatal;
    return station_.for_each_peer([&](uint64_t peer) {
      return transmit_to(peer, f, end, buf, emu::flag_broadcast);
    });
  }

  /// Sends the copies of `f` that reach `dst` (loss, duplication,
  /// corruption, latency and jitter decided per receiver).
  send_result transmit_to(uint64_t dst, const tx_frame& f, int64_t end,
                          std::vector<uint8_t>& buf, uint8_t flags) {
    emu_medium::impairments imp;
    imp.loss = loss_.load();
    imp.duplicate = cfg_.duplicate;
    imp.corrupt = cfg_.corrupt;
    imp.latency_ns = latency_ns_.load();
    imp.jitter_ns = jitter_ns_.load();
    auto copies = emu_medium::copies(dice_, imp);
    if (copies == 0) {
      ++tx_lost_;
      return send_result::ok;
    }
    auto size = f.bytes.size();
    for (int copy = 0; copy < copies; ++copy) {
      auto fate = emu_medium::fate_of_copy(dice_, imp, end, size);
      emu::wire_header hdr;
      hdr.flags = static_cast<uint8_t>(flags
                                       | (copy > 0 ? emu::flag_duplicate : 0));
      hdr.src = static_cast<uint16_t>(station_.number());
      hdr.deliver_at_ns = fate.deliver_at_ns;
      if (size > 0)
        std::memcpy(buf.data() + emu::wire_header_size, f.bytes.data(), size);
      if (fate.flipped_bit >= 0) {
        auto bit = static_cast<size_t>(fate.flipped_bit);
        buf[emu::wire_header_size + bit / 8] ^= uint8_t(1u << (bit % 8));
        hdr.flags |= emu::flag_corrupted;
      }
      emu::encode(hdr, buf.data());
      auto result = station_.send_to(dst, buf.data(),
                                     emu::wire_header_size + size);
      if (result != send_result::ok)
        return result;
    }
    return send_result::ok;
  }

  // -- medium_client: loop thread ------------------------------------------------

  bool accept(const uint8_t* data, size_t size, int64_t now,
              int64_t& deliver_at) override {
    emu::wire_header hdr;
    hdr.src = 0;
    auto status = emu::check(data, size, cfg_.profile.mtu, now, hdr);
    if (status != emu::wire_status::ok) {
      ++rx_malformed_;
      auto src = hdr.src >= emu::min_station && hdr.src <= emu::max_station
                   ? link_addr{hdr.src}
                   : link_addr{0};
      auto why = std::string{"emu: "} + emu::to_string(status) + " ("
                 + std::to_string(size) + "-byte datagram, MTU "
                 + std::to_string(cfg_.profile.mtu) + ")";
      life_.handler()->on_malformed(src, why.c_str());
      return false;
    }
    if ((hdr.flags & emu::flag_corrupted) != 0 && cfg_.frame_check) {
      // The receiving interface's frame check fails: the frame never
      // reaches software, as on the real medium.
      ++rx_malformed_;
      life_.handler()->on_malformed(hdr.src,
                                    "emu: frame check failed (a bit was "
                                    "flipped on the medium)");
      return false;
    }
    deliver_at = hdr.deliver_at_ns;
    return true;
  }

  void deliver(const uint8_t* data, size_t size) override {
    auto hdr = emu::decode(data);
    ++rx_frames_;
    // The copy keeps the handler alive should it stop the driver.
    life_.handler()->on_frame(hdr.src, data + emu::wire_header_size,
                              size - emu::wire_header_size);
  }

  void fail(caf::error err) override {
    life_.handler()->on_failure(std::move(err));
  }

  // -- state ---------------------------------------------------------------------

  const emu_config cfg_;
  const std::string prefix_; // "device 'NAME': "
  emu_medium::station station_;

  // Run-time parameters (set_param).
  std::atomic<double> loss_;
  std::atomic<int64_t> latency_ns_;
  std::atomic<int64_t> jitter_ns_;
  std::atomic<uint64_t> bandwidth_;

  emu_medium::station_life life_;

  // Transmit queue, guarded by gate_.mutex().
  emu_medium::tx_gate gate_;
  std::deque<tx_frame> queue_;
  std::vector<std::vector<uint8_t>> spare_;

  // The transmit step only (the loop thread): the frame on the medium now
  // and when its transmission ends.
  emu_medium::dice dice_;
  std::optional<tx_frame> in_flight_;
  int64_t in_flight_end_ = 0;
  std::vector<uint8_t> buf_
    = std::vector<uint8_t>(emu::wire_header_size + cfg_.profile.mtu);

  // Counters (get_param).
  std::atomic<uint64_t> tx_frames_{0};
  std::atomic<uint64_t> tx_lost_{0};
  std::atomic<uint64_t> rx_frames_{0};
  std::atomic<uint64_t> rx_malformed_{0};
};

caf::expected<link_driver_ptr> open_emu(const device_config& cfg) {
  auto conf = read_config(cfg);
  if (!conf)
    return conf.error();
  auto driver = std::make_shared<emu_driver>(std::move(*conf));
  if (auto err = driver->open())
    return err;
  return link_driver_ptr{std::move(driver)};
}

caf::error check_emu(const device_config& cfg) {
  auto x = read_config(cfg);
  return x ? caf::error{} : std::move(x.error());
}

} // namespace

const link_kind& emu_link_kind() {
  static const link_kind kind{
    "emu",
    "emulated medium between processes on this machine: a directory of unix "
    "datagram sockets with bandwidth pacing, MTU, latency, jitter and loss",
    open_emu, check_emu};
  return kind;
}

} // namespace herm
