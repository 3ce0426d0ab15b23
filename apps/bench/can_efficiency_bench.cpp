// Efficiency of HERM's fragmentation over CAN, on the emulated 1 Mbit/s bus
// (link kind "can", interface emu:DIR).
//
// One station sends long packets through HERM's port stack (make_port:
// fragmenting_port over frame_port, 8-byte frames with a 1-byte fragment
// header) to another; the receiver feeds every frame into its own port stack
// and counts complete packets. Each iteration sends `packets` packets back
// to back; its manual time runs from the first send to the last packet's
// completion at the receiver, so it is bus time, not the sender's loop.
//
// Counters:
//   payload_eff    payload bytes delivered / (frames * 8): the share of the
//                  CAN data field that carries packet bytes (>= 0.87 needed)
//   wire_eff       payload bits / bus bits (frame bits incl. CAN overhead)
//   frames_per_s   CAN frames per second the receiver saw
//   limit_fps      physical limit: 1 s / time of one 8-byte frame (9,009 with
//                  11-bit ids, 7,633 with 29-bit, 6,250 with 29-bit and worst
//                  case bit stuffing)
//   mix_limit_fps  the limit for this packet's frame mix: its last frame is
//                  shorter than 8 bytes, so slightly above limit_fps
//   bus_load       bus bits carried / (elapsed * bit rate), the frames' exact
//                  lengths counted; cannot exceed 1 (the emulated bus never
//                  carries more than its bit rate)
//   goodput_Bps    packet payload bytes per second
//   frames_per_pkt frames one packet takes
//
// Run (about 15 s):
//   build/bin/bench_can_efficiency
// or one row:
//   build/bin/bench_can_efficiency --benchmark_filter='ext29/2000'

#include <benchmark/benchmark.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>

#include <time.h>
#include <unistd.h>

#include "actors/runtime/error.hpp"
#include "apps/bench/bench_common.hpp"
#include "channels/drivers/can_id.hpp"
#include "channels/link_driver.hpp"
#include "channels/port.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using bench::now_ns;

/// Receiving side: feeds frames into a port stack and counts what comes
/// out. Called by the receiving driver's thread only; read by the
/// benchmark thread through atomics.
class packet_counter : public bench::trouble_counting_handler {
public:
  explicit packet_counter(std::unique_ptr<packet_port> port)
    : port_(std::move(port)) {
  }

  void reset() {
    frames_.store(0);
    packets_.store(0);
    bytes_.store(0);
    last_ns_.store(0);
  }

  void on_frame(link_addr src, const uint8_t* data, size_t size) override {
    frames_.fetch_add(1, std::memory_order_relaxed);
    if (port_->receive(src, data, size, std::chrono::steady_clock::now(), out_)
        == packet_port::rx::packet) {
      bytes_.fetch_add(out_.size(), std::memory_order_relaxed);
      last_ns_.store(now_ns(), std::memory_order_relaxed);
      packets_.fetch_add(1, std::memory_order_release);
    }
  }

  uint64_t frames() const {
    return frames_.load();
  }
  uint64_t packets() const {
    return packets_.load(std::memory_order_acquire);
  }
  uint64_t bytes() const {
    return bytes_.load();
  }
  int64_t last_ns() const {
    return last_ns_.load();
  }
  bool failed() const {
    return trouble() > 0;
  }

private:
  std::unique_ptr<packet_port> port_;
  byte_buffer out_;
  std::atomic<uint64_t> frames_{0};
  std::atomic<uint64_t> packets_{0};
  std::atomic<uint64_t> bytes_{0};
  std::atomic<int64_t> last_ns_{0};
};

void can_efficiency(benchmark::State& state, const char* id_format,
                    bool stuffing) {
  auto packet_size = static_cast<size_t>(state.range(0));
  // About half a second of bus time per iteration.
  auto packets = static_cast<uint64_t>(state.range(1));
  bench::scratch_dir dir{"herm-can-bench"};
  if (!dir.usable(state))
    return;
  option_map common{{"id_format", id_format},
                    {"stuffing", stuffing ? "true" : "false"},
                    {"bitrate", "1000000"}};
  auto tx_opts = common;
  tx_opts["node"] = "1";
  auto rx_opts = common;
  rx_opts["node"] = "2";
  auto bus = "emu:" + dir.path() + "/bus";
  auto stations = bench::open_stations(state, {"tx0", "can", bus, tx_opts},
                                       {"rx0", "can", bus, rx_opts});
  if (!stations)
    return;
  auto tx = stations->tx;
  auto rx = stations->rx;
  auto rx_port = make_port(rx, reassembly_limits{});
  // The channel queues frames when the driver's queue is full; so does this
  // writer, by waiting a few frame times.
  auto tx_driver = tx;
  frame_writer writer = [tx_driver](link_addr dst, uint8_t prio,
                                    const uint8_t* data, size_t size) {
    for (;;) {
      auto err = tx_driver->send(dst, data, size, prio);
      if (!err || !is(err, ec::queue_full))
        return err;
      std::this_thread::sleep_for(500us);
    }
  };
  auto tx_port = make_port(tx, reassembly_limits{}, writer);
  if (!rx_port || !tx_port) {
    state.SkipWithError("make_port failed");
    return;
  }
  auto counter = std::make_shared<packet_counter>(std::move(*rx_port));
  rx->start(counter);
  tx->start(std::make_shared<bench::ignoring_handler>());
  auto format = std::string{id_format} == "11bit" ? can::id_format::std11
                                                   : can::id_format::ext29;
  auto full_frame_ns = can::bits_time_ns(can::frame_bits(format, 8, stuffing),
                                         1'000'000);
  auto limit_fps = 1e9 / double(full_frame_ns);
  byte_buffer payload(packet_size);
  for (size_t i = 0; i < packet_size; ++i)
    payload[i] = static_cast<uint8_t>(i * 7);
  auto frames_per_packet = (*tx_port)->frames_for(packet_size);
  double seconds = 0;
  uint64_t frames = 0;
  uint64_t delivered = 0;
  uint64_t bytes = 0;
  for (auto _ : state) {
    counter->reset();
    auto t0 = now_ns();
    for (uint64_t i = 0; i < packets; ++i) {
      auto res = (*tx_port)->send(2, prio_bulk, payload.data(),
                                  payload.size());
      if (!res) {
        state.SkipWithError(render(res.error()).c_str());
        break;
      }
    }
    auto deadline = std::chrono::steady_clock::now() + 60s;
    while (counter->packets() < packets && !counter->failed()
           && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(1ms);
    if (counter->packets() < packets || counter->failed()) {
      state.SkipWithError("packets lost or link failed");
      break;
    }
    auto elapsed = double(counter->last_ns() - t0) / 1e9;
    state.SetIterationTime(elapsed);
    seconds += elapsed;
    frames += counter->frames();
    delivered += counter->packets();
    bytes += counter->bytes();
  }
  tx->stop();
  rx->stop();
  if (frames == 0 || seconds <= 0)
    return;
  // Exact bus bits of one packet: its frames, replayed through a fragmenter.
  fragmenter frag{8};
  double packet_bits = 0;
  frag.split(payload.data(), payload.size(), [&](const uint8_t*, size_t len) {
    packet_bits += can::frame_bits(format, len, stuffing);
  });
  auto bus_bits = packet_bits * double(delivered);
  auto fps = double(frames) / seconds;
  state.counters["payload_eff"] = double(bytes) / (double(frames) * 8);
  state.counters["wire_eff"] = double(bytes) * 8 / bus_bits;
  state.counters["frames_per_s"] = fps;
  state.counters["limit_fps"] = limit_fps;
  state.counters["mix_limit_fps"] = double(frames_per_packet) * 1e6
                                    / packet_bits;
  state.counters["bus_load"] = bus_bits / (seconds * 1e6);
  state.counters["goodput_Bps"] = double(bytes) / seconds;
  state.counters["frames_per_pkt"] = double(frames_per_packet);
  state.SetBytesProcessed(static_cast<int64_t>(bytes));
}

/// The cases, registered in this order as can_efficiency/<name>: packets
/// per iteration of 2000 and of 4000 bytes, about half a second of bus time.
struct can_case {
  const char* name;
  const char* id_format;
  bool stuffing;
  int64_t packets_2000;
  int64_t packets_4000;
};

constexpr can_case can_cases[] = {
  {"ext29", "29bit", false, 14, 7},
  {"std11", "11bit", false, 16, 8},
  {"ext29_stuffed", "29bit", true, 12, 6},
};

[[maybe_unused]] const bool registered = [] {
  for (const auto& c : can_cases)
    benchmark::RegisterBenchmark(("can_efficiency/" + std::string{c.name}).c_str(),
                                 can_efficiency, c.id_format, c.stuffing)
      ->ArgNames({"bytes", "packets"})
      ->Args({2000, c.packets_2000})
      ->Args({4000, c.packets_4000})
      ->UseManualTime()
      ->Unit(benchmark::kMillisecond)
      ->Iterations(3);
  return true;
}();

} // namespace

BENCHMARK_MAIN();
