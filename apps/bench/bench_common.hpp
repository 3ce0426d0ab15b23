// Pieces the link benchmarks (bench_can_efficiency, bench_emu_bandwidth,
// bench_serial_goodput) share: a monotonic clock in nanoseconds, a scratch
// directory for emulated media, opening the sending and the receiving
// station, and a frame handler that ignores everything.
// Header-only; every function is safe to call from any thread.

#pragma once

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <ftw.h>
#include <optional>
#include <stdlib.h>
#include <string>

#include <benchmark/benchmark.h>

#include "channels/drivers/posix.hpp"
#include "channels/error.hpp"
#include "channels/link_driver.hpp"

namespace herm::bench {

/// CLOCK_MONOTONIC in nanoseconds (the clock the drivers' threads and the
/// benchmark thread compare arrival times on).
using posix::now_ns;

/// A fresh directory `/tmp/<prefix>-XXXXXX` (mkdtemp) for an emulated
/// medium, removed with everything below it (depth first, never following a
/// symbolic link, errors ignored) when this goes away. Declare it before the
/// drivers that use it, so they close first. Not copyable.
class scratch_dir {
public:
  explicit scratch_dir(const std::string& prefix)
    : path_("/tmp/" + prefix + "-XXXXXX") {
    if (::mkdtemp(path_.data()) == nullptr)
      path_.clear();
  }

  scratch_dir(const scratch_dir&) = delete;
  scratch_dir& operator=(const scratch_dir&) = delete;

  ~scratch_dir() {
    if (path_.empty())
      return;
    auto remove_entry = [](const char* path, const struct stat*, int, FTW*) {
      return ::remove(path);
    };
    ::nftw(path_.c_str(), remove_entry, 16, FTW_DEPTH | FTW_PHYS);
  }

  /// The directory, or empty when mkdtemp failed.
  const std::string& path() const {
    return path_;
  }

  /// False, after skipping the benchmark, when mkdtemp failed.
  bool usable(benchmark::State& state) const {
    if (path_.empty())
      state.SkipWithError("mkdtemp failed");
    return !path_.empty();
  }

private:
  std::string path_;
};

/// The two stations of a link benchmark.
struct station_pair {
  link_driver_ptr tx;
  link_driver_ptr rx;
};

/// Opens the sending station from `tx_cfg`, then the receiving one from
/// `rx_cfg` (each config names its link kind, which must be known). Nothing,
/// after skipping the benchmark with the first error, when either fails.
inline std::optional<station_pair> open_stations(benchmark::State& state,
                                                 const device_config& tx_cfg,
                                                 const device_config& rx_cfg) {
  auto tx = find_link_kind(tx_cfg.kind)->open(tx_cfg);
  auto rx = tx ? find_link_kind(rx_cfg.kind)->open(rx_cfg) : tx;
  if (!tx || !rx) {
    state.SkipWithError(render(tx ? rx.error() : tx.error()).c_str());
    return std::nullopt;
  }
  return station_pair{std::move(*tx), std::move(*rx)};
}

/// A frame handler that ignores every callback: the sending station's, and
/// the base of counters that override only what they count.
class ignoring_handler : public frame_handler {
public:
  void on_frame(link_addr, const uint8_t*, size_t) override {
  }
  void on_malformed(link_addr, const char*) override {
  }
  void on_event(link_event_kind, link_addr, std::string) override {
  }
  void on_failure(caf::error) override {
  }
};

/// The base of the receiving side's counters: ignores link events, counts
/// malformed frames and remembers a device failure. Written by the driver's
/// thread, read by the benchmark thread (atomics).
class trouble_counting_handler : public ignoring_handler {
public:
  void on_malformed(link_addr, const char*) override {
    malformed_.fetch_add(1);
  }

  void on_failure(caf::error) override {
    failed_.store(true);
  }

  /// Malformed frames so far, plus 1 once the device failed: 0 while all is
  /// well.
  uint64_t trouble() const {
    return malformed_.load() + (failed_.load() ? 1 : 0);
  }

private:
  std::atomic<uint64_t> malformed_{0};
  std::atomic<bool> failed_{false};
};

} // namespace herm::bench
