#include "routing/module_id.hpp"

#include <cstdio>
#include <cctype>
#include <cstdlib>

namespace herm {

namespace {

struct category_row {
  module_category category;
  const char* name;
  module_range range;
};

// The static pool. main_controller starts at 0x4E as in the paper's testbed.
constexpr category_row categories[] = {
  {module_category::main_controller, "main_controller", {0x4E, 0x4F}},
  {module_category::left_arm, "left_arm", {0x10, 0x1F}},
  {module_category::right_arm, "right_arm", {0x20, 0x2F}},
  {module_category::vision, "vision", {0x30, 0x3F}},
  {module_category::sensor, "sensor", {0x40, 0x4D}},
  {module_category::mobile, "mobile", {0x50, 0x5F}},
  {module_category::manipulator, "manipulator", {0x60, 0x6F}},
  {module_category::power, "power", {0x70, 0x7F}},
  {module_category::other, "other", {0x80, 0xFF}},
};

} // namespace

const char* to_string(module_category x) {
  for (auto& row : categories)
    if (row.category == x)
      return row.name;
  return "other";
}

std::optional<module_category> parse_module_category(const std::string& str) {
  for (auto& row : categories)
    if (str == row.name)
      return row.category;
  return std::nullopt;
}

module_range static_pool(module_category x) {
  for (auto& row : categories)
    if (row.category == x)
      return row.range;
  return {0x80, 0xFF};
}

std::string to_hex(module_id x) {
  char buf[8];
  std::snprintf(buf, sizeof(buf), "0x%02X", static_cast<unsigned>(x));
  return buf;
}

std::optional<module_id> parse_module_id(const std::string& str) {
  if (str.empty() || str.size() > 8)
    return std::nullopt;
  int base = 10;
  size_t start = 0;
  if (str.size() > 2 && str[0] == '0' && (str[1] == 'x' || str[1] == 'X')) {
    base = 16;
    start = 2;
  }
  for (size_t i = start; i < str.size(); ++i) {
    auto c = str[i];
    bool ok = base == 16 ? std::isxdigit(static_cast<unsigned char>(c)) != 0
                         : (c >= '0' && c <= '9');
    if (!ok)
      return std::nullopt;
  }
  auto val = std::strtoul(str.c_str() + start, nullptr, base);
  if (val > 0xFFFF)
    return std::nullopt;
  return static_cast<module_id>(val);
}

} // namespace herm
