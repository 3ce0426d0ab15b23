// Goodput of the "serial" link kind (RS232C) through HERM's port stack.
//
// Two serial drivers sit on the two ends of the paced null-modem cable of
// channels/testing/null_modem.hpp (pseudo-terminals, a relay that clocks bytes
// out at exactly baud / 10 bytes/s for 8N1). The sender pushes packets
// through make_port(driver, reassembly_limits{}) (a fragmenting_port over a
// frame_port: 1 header byte per 32-byte frame, CRC-32 per fragmented
// packet); the receiver feeds every frame into a second port's receive() and
// counts the packets that come out complete and unaltered. The sender keeps
// about 250 ms of data queued, so the line never idles and the kernel never
// holds an unbounded backlog.
//
// Manual time of an iteration: from the first send to the last packet
// delivered. Counters:
//   goodput_Bps     packet payload bytes delivered per second
//   line_Bps        what the line carries: baud / 10 bytes/s (1,920 at 19,200)
//   ratio           goodput_Bps / line_Bps (the issue requires >= 0.80)
//   wire_eff        payload bytes / bytes on the wire (framing overhead only)
//   line_busy       bytes on the wire / (line_Bps * time): how busy the
//                   sender kept the line; ratio = wire_eff * line_busy
//   frames_per_pkt  frames per packet after fragmentation
//   packets         packets delivered
//
// Run: build/bin/bench_serial_goodput   (about 10 s: each case ~3 s of line
// time)

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <thread>

#include "actors/runtime/error.hpp"
#include "apps/bench/bench_common.hpp"
#include "channels/link_driver.hpp"
#include "channels/port.hpp"
#include "channels/testing/null_modem.hpp"

using namespace herm;

namespace {

using clock_type = std::chrono::steady_clock;

/// Line time each case aims for, seconds.
constexpr double case_seconds = 3.0;

/// Data the sender keeps queued ahead of the receiver, seconds of line time.
constexpr double queue_seconds = 0.25;

byte_buffer make_payload(size_t size) {
  byte_buffer result(size);
  for (size_t i = 0; i < size; ++i)
    result[i] = static_cast<uint8_t>(i * 29 + 7); // includes zeros
  return result;
}

/// Reassembles on the receiving driver's IO thread; counted from outside.
class packet_counter : public bench::trouble_counting_handler {
public:
  packet_counter(std::unique_ptr<packet_port> port, byte_buffer expected)
    : port_(std::move(port)), expected_(std::move(expected)) {
  }

  void on_frame(link_addr src, const uint8_t* data, size_t size) override {
    auto now = clock_type::now();
    if (port_->receive(src, data, size, now, out_) != packet_port::rx::packet)
      return;
    if (out_ != expected_)
      altered_.fetch_add(1);
    bytes_.fetch_add(out_.size());
    last_.store(now.time_since_epoch().count());
    packets_.fetch_add(1, std::memory_order_release);
  }

  uint64_t packets() const {
    return packets_.load(std::memory_order_acquire);
  }
  uint64_t bytes() const {
    return bytes_.load();
  }
  clock_type::time_point last() const {
    return clock_type::time_point{clock_type::duration{last_.load()}};
  }
  /// Altered packets, malformed frames, plus 1 once the device failed.
  uint64_t trouble() const {
    return altered_.load() + trouble_counting_handler::trouble();
  }

private:
  std::unique_ptr<packet_port> port_;
  byte_buffer expected_;
  byte_buffer out_;
  std::atomic<uint64_t> packets_{0};
  std::atomic<uint64_t> bytes_{0};
  std::atomic<clock_type::rep> last_{0};
  std::atomic<uint64_t> altered_{0};
};

void serial_goodput(benchmark::State& state) {
  auto packet_size = static_cast<size_t>(state.range(0));
  auto baud = static_cast<uint64_t>(state.range(1));
  test::null_modem::config cable_cfg;
  cable_cfg.baud = baud;
  cable_cfg.bits_per_char = 10;
  std::string error;
  auto cable = test::null_modem::open(cable_cfg, error);
  if (!cable) {
    state.SkipWithError(("no pseudo-terminals: " + error).c_str());
    return;
  }
  option_map opts{{"baud", std::to_string(baud)}, {"mtu", "32"}};
  auto stations = bench::open_stations(
    state, {"tx0", "serial", cable->path_a(), opts},
    {"rx0", "serial", cable->path_b(), opts});
  if (!stations)
    return;
  auto tx = stations->tx;
  auto rx = stations->rx;
  auto tx_port = make_port(tx, reassembly_limits{});
  auto rx_port = make_port(rx, reassembly_limits{});
  if (!tx_port || !rx_port) {
    state.SkipWithError("make_port failed");
    return;
  }
  auto payload = make_payload(packet_size);
  auto counter = std::make_shared<packet_counter>(std::move(*rx_port), payload);
  // Stops both drivers on every way out (the receiver's handler holds a
  // port that holds the driver: stop() breaks that cycle).
  struct stopper {
    link_driver_ptr a;
    link_driver_ptr b;
    ~stopper() {
      a->stop();
      b->stop();
    }
  } guard{tx, rx};
  rx->start(counter);
  tx->start(std::make_shared<bench::ignoring_handler>());
  auto line_Bps = double(baud) / cable_cfg.bits_per_char;
  auto frames = (*tx_port)->frames_for(packet_size);
  // Bytes on the wire per packet, roughly: frame + CRC + COBS + delimiter.
  auto wire_guess = double(packet_size + frames * (1 + 2 + 1 + 1));
  auto per_case = std::max<uint64_t>(
    4, static_cast<uint64_t>(std::ceil(case_seconds * line_Bps / wire_guess)));
  auto window = std::max<uint64_t>(
    2, static_cast<uint64_t>(queue_seconds * line_Bps / wire_guess));
  auto give_up = std::chrono::duration<double>(
    3 * per_case * wire_guess / line_Bps + 5);
  double seconds = 0;
  uint64_t bytes = 0;
  uint64_t delivered = 0;
  uint64_t wire = 0;
  for (auto _ : state) {
    auto base_packets = counter->packets();
    auto base_bytes = counter->bytes();
    auto base_wire = cable->a_to_b().written;
    auto start = clock_type::now();
    uint64_t sent = 0;
    for (;;) {
      auto done = counter->packets() - base_packets;
      if (done >= per_case)
        break;
      while (sent < per_case && sent - done < window) {
        auto res = (*tx_port)->send(1, prio_bulk, payload.data(),
                                    payload.size());
        if (!res) {
          state.SkipWithError(render(res.error()).c_str());
          return;
        }
        ++sent;
      }
      if (clock_type::now() - start > give_up || counter->trouble() > 0) {
        state.SkipWithError("packets lost or altered on a clean line");
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    auto elapsed = std::chrono::duration<double>(counter->last() - start);
    state.SetIterationTime(elapsed.count());
    seconds += elapsed.count();
    bytes += counter->bytes() - base_bytes;
    delivered += counter->packets() - base_packets;
    wire += cable->a_to_b().written - base_wire;
  }
  auto goodput = double(bytes) / seconds;
  state.counters["goodput_Bps"] = goodput;
  state.counters["line_Bps"] = line_Bps;
  state.counters["ratio"] = goodput / line_Bps;
  state.counters["wire_eff"] = double(bytes) / double(wire);
  state.counters["line_busy"] = double(wire) / (line_Bps * seconds);
  state.counters["frames_per_pkt"] = double(frames);
  state.counters["packets"] = double(delivered);
  state.SetLabel(std::to_string(packet_size) + " B packets, "
                 + std::to_string(baud) + " baud 8N1, MTU 32");
}

} // namespace

// Args: packet payload bytes, baud. 1000 B: long packets (33 frames); 31 B:
// the largest packet that fits one 32-byte frame; 8 B: a small packet.
BENCHMARK(serial_goodput)
  ->ArgNames({"packet", "baud"})
  ->Args({1000, 19200})
  ->Args({31, 19200})
  ->Args({8, 19200})
  ->UseManualTime()
  ->Iterations(1)
  ->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
