#include "apps/mcu/sim/distance_script.hpp"

#include <algorithm>
#include <charconv>

namespace herm::avr_sim {

namespace {

bool is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r';
}

std::string_view skip_blanks(std::string_view s) {
  while (!s.empty() && is_blank(s.front()))
    s.remove_prefix(1);
  return s;
}

/// Reads one unsigned decimal number (32 bits) off the front of `s`.
bool take_u32(std::string_view& s, uint32_t& out) {
  s = skip_blanks(s);
  auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  if (ec != std::errc{} || end == s.data())
    return false;
  s.remove_prefix(static_cast<size_t>(end - s.data()));
  return s.empty() || is_blank(s.front());
}

} // namespace

distance_script parse_distance_script(std::string_view text) {
  distance_script result;
  size_t line_no = 0;
  while (!text.empty()) {
    ++line_no;
    auto nl = text.find('\n');
    auto line = text.substr(0, nl);
    text.remove_prefix(nl == std::string_view::npos ? text.size() : nl + 1);
    auto rest = skip_blanks(line);
    if (rest.empty() || rest.front() == '#')
      continue;
    distance_point p;
    if (!take_u32(rest, p.t_ms) || !take_u32(rest, p.distance_mm)
        || !skip_blanks(rest).empty()) {
      result.error = "line " + std::to_string(line_no)
                     + ": expected `t_ms distance_mm` (two unsigned numbers)";
      result.points.clear();
      return result;
    }
    if (!result.points.empty() && p.t_ms < result.points.back().t_ms) {
      result.error = "line " + std::to_string(line_no) + ": time "
                     + std::to_string(p.t_ms) + " ms goes back";
      result.points.clear();
      return result;
    }
    if (result.points.size() == max_script_points) {
      result.error = "line " + std::to_string(line_no) + ": more than "
                     + std::to_string(max_script_points) + " points";
      result.points.clear();
      return result;
    }
    result.points.push_back(p);
  }
  return result;
}

uint32_t distance_at(const std::vector<distance_point>& points, uint32_t t_ms,
                     uint32_t before) {
  auto it = std::upper_bound(points.begin(), points.end(), t_ms,
                             [](uint32_t t, const distance_point& p) {
                               return t < p.t_ms;
                             });
  return it == points.begin() ? before : std::prev(it)->distance_mm;
}

uint32_t echo_width_us(uint32_t distance_mm) {
  if (distance_mm > srf04_range_mm)
    return srf04_no_echo_us;
  return distance_mm * 2000u / 343u;
}

} // namespace herm::avr_sim
