// herm-avr-srf04: an emulated AVR ATmega128 board with an SRF04 ultrasonic
// sensor, as in the HERM paper's testbed (section 5.1). It sits on a serial
// line and sends one reading every period: an 8-byte record (sequence
// number, distance in mm, echo time in us; docs/protocol.md, "SRF04
// reading") in one HERM serial frame. Like a microcontroller, it runs no
// actors and no routing: the link driver and the fragment codec only, which
// is all a peer without CAF needs.
//
//   herm-avr-srf04 --device /dev/pts/5 [--baud 9600] [--period-ms 30000]
//                  [--count N]
//
// Prints "reading SEQ DISTANCE_MM" per reading. SIGTERM/SIGINT stop it.

#include <atomic>
#include <csignal>
#include <chrono>
#include <cmath>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>

#include "actors/runtime/error.hpp"
#include "apps/hermd/srf04.hpp"
#include "channels/fragmentation.hpp"
#include "channels/link_driver.hpp"

namespace {

// Set by SIGTERM/SIGINT, which may run on any thread (CAF's workers
// included): a lock-free atomic, not a volatile sig_atomic_t, which only
// the interrupted thread may read safely.
std::atomic<bool> stop{false};
static_assert(std::atomic<bool>::is_always_lock_free);

/// Ignores what the line brings (the board only talks).
class deaf : public herm::frame_handler {
public:
  void on_frame(herm::link_addr, const uint8_t*, size_t) override {}
  void on_malformed(herm::link_addr, const char*) override {}
  void on_event(herm::link_event_kind, herm::link_addr, std::string) override {}
  void on_failure(caf::error reason) override {
    std::cout << "line failed: " << herm::render(reason) << std::endl;
    stop = true;
  }
};

} // namespace

int main(int argc, char** argv) {
  CLI::App app{"herm-avr-srf04: an emulated AVR board with an SRF04 sensor"};
  std::string device;
  uint64_t baud = 9600;
  uint64_t period_ms = 30000;
  uint64_t count = 0;
  app.add_option("--device", device, "the serial line")->required();
  app.add_option("--baud", baud, "line rate");
  app.add_option("--period-ms", period_ms, "one reading every this many ms");
  app.add_option("--count", count, "stop after N readings (0: never)");
  CLI11_PARSE(app, argc, argv);
  std::signal(SIGTERM, [](int) { stop = true; });
  std::signal(SIGINT, [](int) { stop = true; });

  auto* kind = herm::find_link_kind("serial");
  auto drv = kind->open(herm::device_config{
    "avr", "serial", device, {{"baud", std::to_string(baud)}}});
  if (!drv) {
    std::cout << "error " << herm::render(drv.error()) << std::endl;
    return 2;
  }
  if (auto err = (*drv)->start(std::make_shared<deaf>())) {
    std::cout << "error " << herm::render(err) << std::endl;
    return 2;
  }
  herm::fragmenter frag{(*drv)->profile().mtu};
  std::cout << "ready device=" << device << " baud=" << baud
            << " period_ms=" << period_ms << std::endl;
  auto next = std::chrono::steady_clock::now();
  for (uint16_t seq = 1; !stop && (count == 0 || seq <= count); ++seq) {
    next += std::chrono::milliseconds(period_ms);
    // An obstacle drifting between 0.3 and 2.5 m.
    auto mm = static_cast<uint16_t>(1400 + 1100 * std::sin(seq * 0.35));
    herm::hermd::srf04_reading r{seq, mm, static_cast<uint32_t>(mm * 2000 / 343)};
    auto bytes = herm::hermd::encode(r);
    frag.split(bytes.data(), bytes.size(), [&](const uint8_t* f, size_t n) {
      if (auto err = (*drv)->send(herm::broadcast_addr, f, n, herm::prio_normal))
        std::cout << "send failed: " << herm::render(err) << std::endl;
    });
    std::cout << "reading " << seq << " " << mm << std::endl;
    while (!stop && std::chrono::steady_clock::now() < next)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  (*drv)->stop();
  return 0;
}
