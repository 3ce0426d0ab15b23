#include "apps/mcu/sim/stack_report.hpp"

namespace herm::avr_sim {

stack_use measure_stack(const uint8_t* data, uint32_t from, uint32_t ramend,
                        uint8_t paint) {
  stack_use result;
  if (from > ramend)
    return result;
  result.painted = data[from] == paint;
  uint32_t addr = from;
  while (addr <= ramend && data[addr] == paint)
    ++addr;
  result.headroom = addr - from;
  result.used = ramend + 1 - addr;
  return result;
}

} // namespace herm::avr_sim
