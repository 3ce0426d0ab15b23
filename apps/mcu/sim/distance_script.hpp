#pragma once

// The SRF04 part's distance over time: a script of `t_ms distance_mm` lines
// (herm-avr-sim --script FILE). Pure: text in, points out, no I/O.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace herm::avr_sim {

/// From board time `t_ms` (ms since reset) on, the obstacle is
/// `distance_mm` away, until the next point.
struct distance_point {
  uint32_t t_ms = 0;
  uint32_t distance_mm = 0;
};

struct distance_script {
  std::vector<distance_point> points;
  /// Empty when the text parsed; otherwise what was wrong, with its line.
  std::string error;
};

/// Most points a script may hold (a bound on what a file can make us keep).
inline constexpr size_t max_script_points = 100000;

/// Parses lines of two unsigned decimal numbers, `t_ms distance_mm`,
/// separated by blanks; blank lines and lines starting with `#` are skipped.
/// Times must not decrease. A bad line, or more than max_script_points,
/// gives an error naming the line (1-based) and no points.
distance_script parse_distance_script(std::string_view text);

/// The distance at `t_ms`: the last point whose time is at most t_ms, or
/// `before` when t_ms precedes the first point (or there are none).
uint32_t distance_at(const std::vector<distance_point>& points, uint32_t t_ms,
                     uint32_t before);

/// The SRF04's range: beyond it the sensor answers "nothing" (a 36 ms echo).
inline constexpr uint32_t srf04_range_mm = 4000;
inline constexpr uint32_t srf04_no_echo_us = 36000;

/// Echo pulse width, us, for an obstacle at `distance_mm`:
/// distance_mm * 2000 / 343 (docs/protocol.md, "SRF04 reading"), or
/// srf04_no_echo_us beyond srf04_range_mm.
uint32_t echo_width_us(uint32_t distance_mm);

} // namespace herm::avr_sim
