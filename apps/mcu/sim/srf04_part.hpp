#pragma once

// An SRF04 ultrasonic ranger wired to a simulated AVR: it watches the
// trigger pin and drives the echo pin, in simulated time (cycle timers), as
// the sensor does: a trigger pulse of at least 10 us starts a measurement;
// srf04_part::burst_us after the trigger's falling edge (the 40 kHz burst)
// the echo line rises, and it falls echo_width_us(distance) later. Triggers
// that come while a measurement is under way, or that are shorter than
// 10 us, are ignored and counted. Single-threaded: everything runs inside
// avr_run on the harness's thread.

#include <cstdint>
#include <functional>

#include "apps/mcu/sim/simavr.hpp"

namespace herm::avr_sim {

struct srf04_counters {
  uint64_t measurements = 0;   ///< echo pulses sent
  uint64_t short_triggers = 0; ///< pulses under 10 us, ignored
  uint64_t busy_triggers = 0;  ///< pulses during a measurement, ignored
};

class srf04_part {
public:
  /// Time from the trigger's falling edge to the echo's rising edge, us.
  static constexpr uint32_t burst_us = 100;
  static constexpr uint32_t min_trigger_us = 10;

  /// The obstacle's distance, mm, at board time t_ms.
  using distance_fn = std::function<uint32_t(uint32_t t_ms)>;

  /// Attaches to `avr`: trigger = port `trig_port` bit `trig_bit` (an output
  /// of the firmware), echo = port `echo_port` bit `echo_bit` (an input).
  /// `avr` must outlive the part; the part must not move (it is the
  /// callbacks' parameter). False from attached() when a pin is missing.
  srf04_part(avr_t* avr, char trig_port, int trig_bit, char echo_port,
             int echo_bit, distance_fn distance);

  srf04_part(const srf04_part&) = delete;
  srf04_part& operator=(const srf04_part&) = delete;

  bool attached() const {
    return echo_ != nullptr && trig_ != nullptr;
  }

  const srf04_counters& counters() const {
    return counters_;
  }

private:
  static void on_trigger(avr_irq_t* irq, uint32_t value, void* param);
  static avr_cycle_count_t echo_rise(avr_t* avr, avr_cycle_count_t when,
                                     void* param);
  static avr_cycle_count_t echo_fall(avr_t* avr, avr_cycle_count_t when,
                                     void* param);

  avr_t* avr_;
  avr_irq_t* trig_ = nullptr;
  avr_irq_t* echo_ = nullptr;
  distance_fn distance_;
  uint32_t trig_level_ = 0;
  avr_cycle_count_t trig_rise_ = 0;
  bool busy_ = false;
  avr_cycle_count_t echo_cycles_ = 0;
  srf04_counters counters_;
};

} // namespace herm::avr_sim
