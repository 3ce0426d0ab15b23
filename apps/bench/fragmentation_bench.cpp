// Fragmentation throughput: split, reassemble, and both in a pipeline, for
// packet sizes 64, 1024 and 65536 bytes at MTUs 8 (CAN 2.0), 32 (RS-232 in
// Table 1) and 1472 (UDP over Ethernet).
//
// bytes_per_second counts payload bytes. `efficiency` is payload bytes /
// (frames * mtu), the share of the link's frame capacity that carries
// payload; `frames` is frames per packet. Run:
//   bench_fragmentation --benchmark_min_time=0.2

#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <vector>

#include "channels/fragmentation.hpp"

using namespace herm;

namespace {

// -- helpers -----------------------------------------------------------------------

byte_buffer make_packet(size_t size) {
  byte_buffer out(size);
  uint32_t x = 12345;
  for (auto& b : out) {
    x = x * 1664525u + 1013904223u;
    b = static_cast<uint8_t>(x >> 24);
  }
  return out;
}

/// The frames of one packet, contiguous, prepared outside the timed loop.
struct frame_list {
  byte_buffer bytes;
  std::vector<std::pair<size_t, size_t>> frames; // offset, size
};

frame_list split_once(uint32_t mtu, const byte_buffer& packet) {
  fragmenter f{mtu};
  frame_list out;
  f.split(packet.data(), packet.size(), [&](const uint8_t* p, size_t n) {
    out.frames.emplace_back(out.bytes.size(), n);
    out.bytes.insert(out.bytes.end(), p, p + n);
  });
  return out;
}

void report(benchmark::State& state, size_t size, uint32_t mtu) {
  fragmenter f{mtu};
  auto frames = f.frames_for(size);
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations())
                          * static_cast<int64_t>(size));
  state.counters["frames"] = static_cast<double>(frames);
  state.counters["efficiency"] = static_cast<double>(size)
                                 / static_cast<double>(frames * mtu);
}

const auto fixed_now = std::chrono::steady_clock::time_point{} + std::chrono::hours{1};

// -- benchmarks ----------------------------------------------------------------------

void split(benchmark::State& state) {
  auto size = static_cast<size_t>(state.range(0));
  auto mtu = static_cast<uint32_t>(state.range(1));
  auto packet = make_packet(size);
  fragmenter f{mtu};
  size_t sink = 0;
  std::function<void(const uint8_t*, size_t)> emit
    = [&](const uint8_t* p, size_t n) { sink += p[n - 1]; };
  for (auto _ : state)
    f.split(packet.data(), packet.size(), emit);
  benchmark::DoNotOptimize(sink);
  report(state, size, mtu);
}

void reassemble(benchmark::State& state) {
  auto size = static_cast<size_t>(state.range(0));
  auto mtu = static_cast<uint32_t>(state.range(1));
  auto packet = make_packet(size);
  auto list = split_once(mtu, packet);
  reassembler r;
  byte_buffer out;
  for (auto _ : state)
    for (auto& [offset, n] : list.frames)
      r.push(1, list.bytes.data() + offset, n, fixed_now, out);
  if (r.stats().packets != static_cast<uint64_t>(state.iterations())
      || out != packet)
    state.SkipWithError("reassembly lost or corrupted a packet");
  report(state, size, mtu);
}

void split_and_reassemble(benchmark::State& state) {
  auto size = static_cast<size_t>(state.range(0));
  auto mtu = static_cast<uint32_t>(state.range(1));
  auto packet = make_packet(size);
  fragmenter f{mtu};
  reassembler r;
  byte_buffer out;
  std::function<void(const uint8_t*, size_t)> emit
    = [&](const uint8_t* p, size_t n) { r.push(1, p, n, fixed_now, out); };
  for (auto _ : state)
    f.split(packet.data(), packet.size(), emit);
  if (r.stats().packets != static_cast<uint64_t>(state.iterations())
      || out != packet)
    state.SkipWithError("reassembly lost or corrupted a packet");
  report(state, size, mtu);
}

void configurations(benchmark::internal::Benchmark* b) {
  b->ArgNames({"size", "mtu"});
  b->ArgsProduct({{64, 1024, 65536}, {8, 32, 1472}});
}

} // namespace

BENCHMARK(split)->Apply(configurations);
BENCHMARK(reassemble)->Apply(configurations);
BENCHMARK(split_and_reassemble)->Apply(configurations);

BENCHMARK_MAIN();
