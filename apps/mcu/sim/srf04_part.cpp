#include "apps/mcu/sim/srf04_part.hpp"

#include <utility>

#include "apps/mcu/sim/distance_script.hpp"

namespace herm::avr_sim {

srf04_part::srf04_part(avr_t* avr, char trig_port, int trig_bit, char echo_port,
                       int echo_bit, distance_fn distance)
  : avr_(avr), distance_(std::move(distance)) {
  trig_ = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(trig_port), trig_bit);
  echo_ = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(echo_port), echo_bit);
  if (trig_ != nullptr)
    avr_irq_register_notify(trig_, &srf04_part::on_trigger, this);
  if (echo_ != nullptr)
    avr_raise_irq(echo_, 0);
}

void srf04_part::on_trigger(avr_irq_t*, uint32_t value, void* param) {
  auto* self = static_cast<srf04_part*>(param);
  auto* avr = self->avr_;
  // The port raises its pin IRQs on every write: keep edges only.
  uint32_t level = value != 0 ? 1 : 0;
  if (level == self->trig_level_)
    return;
  self->trig_level_ = level;
  if (level == 1) {
    self->trig_rise_ = avr->cycle;
    return;
  }
  if (avr->cycle - self->trig_rise_ < avr_usec_to_cycles(avr, min_trigger_us)) {
    ++self->counters_.short_triggers;
    return;
  }
  if (self->busy_) {
    ++self->counters_.busy_triggers;
    return;
  }
  auto t_ms = static_cast<uint32_t>(avr->cycle / (avr->frequency / 1000u));
  self->echo_cycles_ = avr_usec_to_cycles(avr, echo_width_us(self->distance_(t_ms)));
  self->busy_ = true;
  avr_cycle_timer_register_usec(avr, burst_us, &srf04_part::echo_rise, self);
}

avr_cycle_count_t srf04_part::echo_rise(avr_t* avr, avr_cycle_count_t,
                                        void* param) {
  auto* self = static_cast<srf04_part*>(param);
  avr_raise_irq(self->echo_, 1);
  avr_cycle_timer_register(avr, self->echo_cycles_, &srf04_part::echo_fall, self);
  return 0;
}

avr_cycle_count_t srf04_part::echo_fall(avr_t*, avr_cycle_count_t, void* param) {
  auto* self = static_cast<srf04_part*>(param);
  avr_raise_irq(self->echo_, 0);
  self->busy_ = false;
  ++self->counters_.measurements;
  return 0;
}

} // namespace herm::avr_sim
