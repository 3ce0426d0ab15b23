#pragma once

// The stack high-water mark of a firmware that paints its free RAM at boot
// (apps/mcu/firmware/srf04/stack_paint.c): pure, over a copy of data memory.

#include <cstdint>

namespace herm::avr_sim {

inline constexpr uint8_t stack_paint_byte = 0xC5;

struct stack_use {
  bool painted = false;  ///< the first painted byte still holds the paint
  uint32_t used = 0;     ///< bytes from the deepest use up to ramend
  uint32_t headroom = 0; ///< painted bytes never touched (below the deepest use)
};

/// Scans data[from..ramend] (data-space addresses): the first byte that no
/// longer holds `paint` is the deepest the stack reached. `painted` is false
/// when data[from] is not paint: the firmware did not paint, or the stack
/// (or a heap) reached its bottom, so `used` is then a lower bound.
stack_use measure_stack(const uint8_t* data, uint32_t from, uint32_t ramend,
                        uint8_t paint = stack_paint_byte);

} // namespace herm::avr_sim
