// Bandwidth of the emulated medium (link kind "emu") as a receiver sees it.
//
// For each profile, one station sends back-to-back MTU-sized frames to
// another through the real driver (two drivers, sockets, and an event loop
// each, as in two modules). Each
// iteration is one burst; its manual time is the medium time the receiver
// observed, from the first frame's arrival to the last one's, so the
// reported time and rates are the medium's, not the sender's loop.
//
// Counters:
//   configured_bps  the profile's bandwidth (bit/s)
//   delivered_bps   (frames - 1) * (MTU * 8 + frame_overhead_bits) / elapsed,
//                   summed over iterations: bits on the medium per second
//   ratio           delivered_bps / configured_bps (the issue asks for 0.95..1.05)
//                   A few 1e-3 above 1 is measurement noise: a late wake-up
//                   of the receiver for the first frame shortens `elapsed`.
//   frame_us        medium time of one frame
//   frames, lost    frames received / not received (receiver overruns)
//
// Run: build/bin/bench_emu_bandwidth  (about 10 s; rs232c alone takes ~1.5 s)
// Only the five profiles:
//   build/bin/bench_emu_bandwidth --benchmark_filter='can2_0|usb1_1|ethernet/|ieee1394a|rs232c'

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>

#include <time.h>
#include <unistd.h>

#include "actors/runtime/error.hpp"
#include "apps/bench/bench_common.hpp"
#include "channels/drivers/emu_wire.hpp"
#include "channels/event_loop.hpp"
#include "channels/link_driver.hpp"

using namespace herm;

namespace {

using bench::now_ns;

/// Counts frames and remembers when the first and the last arrived. Called
/// by the receiving driver's thread only; read by the benchmark thread.
class arrival_counter : public bench::trouble_counting_handler {
public:
  void reset() {
    count_.store(0);
    first_ns_.store(0);
    last_ns_.store(0);
  }

  void on_frame(link_addr, const uint8_t*, size_t) override {
    auto t = now_ns();
    if (count_.load(std::memory_order_relaxed) == 0)
      first_ns_.store(t, std::memory_order_relaxed);
    last_ns_.store(t, std::memory_order_relaxed);
    count_.fetch_add(1, std::memory_order_release);
  }

  uint64_t count() const {
    return count_.load(std::memory_order_acquire);
  }
  int64_t first_ns() const {
    return first_ns_.load(std::memory_order_relaxed);
  }
  int64_t last_ns() const {
    return last_ns_.load(std::memory_order_relaxed);
  }
  bool failed() const {
    return trouble() > 0;
  }

private:
  std::atomic<uint64_t> count_{0};
  std::atomic<int64_t> first_ns_{0};
  std::atomic<int64_t> last_ns_{0};
};

void emu_bandwidth(benchmark::State& state, const char* profile,
                   double burst_seconds, const char* bandwidth = nullptr) {
  bench::scratch_dir dir{"herm-emu-bench"};
  if (!dir.usable(state))
    return;
  device_config tx_cfg{"tx0", "emu", dir.path() + "/medium",
                       {{"profile", profile}, {"station", "1"}}};
  device_config rx_cfg{"rx0", "emu", dir.path() + "/medium",
                       {{"profile", profile}, {"station", "2"}}};
  if (bandwidth != nullptr) {
    tx_cfg.options["bandwidth"] = bandwidth;
    rx_cfg.options["bandwidth"] = bandwidth;
  }
  auto stations = bench::open_stations(state, tx_cfg, rx_cfg);
  if (!stations)
    return;
  auto tx = stations->tx;
  auto rx = stations->rx;
  // Each station on an event loop of its own, as in two modules: the
  // sender's transmit step and the receiver's reading run in parallel.
  auto tx_io = io_thread::make();
  auto rx_io = io_thread::make();
  if (!tx_io || !rx_io) {
    state.SkipWithError("cannot start the event loops");
    return;
  }
  auto counter = std::make_shared<arrival_counter>();
  rx->start(counter, (*rx_io)->loop());
  tx->start(std::make_shared<arrival_counter>(), (*tx_io)->loop());
  auto& prof = tx->profile();
  auto frame_bits = double(prof.mtu) * 8 + prof.frame_overhead_bits;
  auto frame_ns = emu::frame_time_ns(prof.mtu, prof.frame_overhead_bits,
                                     prof.bandwidth_bps);
  auto frames = std::max<uint64_t>(
    16, static_cast<uint64_t>(burst_seconds * 1e9 / double(frame_ns)));
  // While the transmit queue is full, nap for a fraction of its content.
  auto nap = std::chrono::nanoseconds{
    std::clamp<int64_t>(frame_ns * 16, 20'000, 2'000'000)};
  byte_buffer payload(prof.mtu, 0x55);
  double bits = 0;
  double seconds = 0;
  uint64_t received = 0;
  uint64_t lost = 0;
  for (auto _ : state) {
    counter->reset();
    for (uint64_t sent = 0; sent < frames;) {
      auto err = tx->send(2, payload.data(), payload.size(), prio_bulk);
      if (!err) {
        ++sent;
      } else if (is(err, ec::queue_full)) {
        std::this_thread::sleep_for(nap);
      } else {
        state.SkipWithError(render(err).c_str());
        break;
      }
    }
    // Wait for the burst to drain; give up after 1 s without progress.
    uint64_t seen = 0;
    auto progress_at = now_ns();
    while (counter->count() < frames && now_ns() - progress_at < 1'000'000'000) {
      if (counter->count() != seen) {
        seen = counter->count();
        progress_at = now_ns();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds{1});
    }
    auto got = counter->count();
    if (got < 2 || counter->failed()) {
      state.SkipWithError("the receiver got (almost) nothing or failed");
      break;
    }
    auto elapsed = double(counter->last_ns() - counter->first_ns()) / 1e9;
    state.SetIterationTime(elapsed);
    bits += double(got - 1) * frame_bits;
    seconds += elapsed;
    received += got;
    lost += frames - got;
  }
  tx->stop();
  rx->stop();
  if (seconds <= 0)
    return;
  auto delivered = bits / seconds;
  state.SetBytesProcessed(static_cast<int64_t>(received) * prof.mtu);
  state.counters["configured_bps"] = double(prof.bandwidth_bps);
  state.counters["delivered_bps"] = delivered;
  state.counters["ratio"] = delivered / double(prof.bandwidth_bps);
  state.counters["frame_us"] = double(frame_ns) / 1e3;
  state.counters["frames"] = double(received);
  state.counters["lost"] = double(lost);
}

/// The cases, registered in this order as emu_bandwidth/<name>: bursts of
/// about 0.5 s (rs232c: one burst of 1.5 s, about 112 frames).
struct emu_case {
  const char* name;
  const char* profile;
  double burst_seconds;
  int64_t iterations;
  const char* bandwidth; // bit/s instead of the profile's; nullptr: the profile's
};

constexpr emu_case emu_cases[] = {
  {"can2_0", "can2.0", 0.5, 2, nullptr},
  {"usb1_1", "usb1.1", 0.5, 2, nullptr},
  {"ethernet", "ethernet", 0.5, 2, nullptr},
  {"ieee1394a", "ieee1394a", 0.5, 2, nullptr},
  {"rs232c", "rs232c", 1.5, 1, nullptr},
  // The other built-in profiles: usb2.0 is the highest frame rate of Table 1
  // (1024-byte frames at 480 Mbit/s, about 58,000 frames/s).
  {"ieee1394b", "ieee1394b", 0.5, 2, nullptr},
  {"usb2_0", "usb2.0", 0.5, 2, nullptr},
  // Ceiling probes: pacing holds while the per-frame cost (a send, a receive,
  // two thread wake-ups) fits in a frame time. Ethernet at 1 Gbit/s is 80,000
  // frames/s and holds; at 2 Gbit/s (160,000 frames/s) the ratio shows how
  // much a 2-core machine can move, not a pacing error.
  {"ceiling_ethernet_1g", "ethernet", 0.5, 2, "1000000000"},
  {"ceiling_ethernet_2g", "ethernet", 0.5, 2, "2000000000"},
};

[[maybe_unused]] const bool registered = [] {
  for (const auto& c : emu_cases)
    benchmark::RegisterBenchmark(("emu_bandwidth/" + std::string{c.name}).c_str(),
                                 emu_bandwidth, c.profile, c.burst_seconds,
                                 c.bandwidth)
      ->UseManualTime()
      ->Iterations(c.iterations)
      ->Unit(benchmark::kMillisecond);
  return true;
}();

} // namespace

BENCHMARK_MAIN();
