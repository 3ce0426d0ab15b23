#pragma once

// Module addresses (MId). 16 bits: enough for real robots and for
// simulations of thousands of modules; printed in hex like the paper's 0x42
// and 0x4E.

#include <cstdint>
#include <optional>
#include <string>

namespace herm {

using module_id = uint16_t;

/// No address yet (a module still claiming one).
constexpr module_id no_module = 0x0000;

/// Every module.
constexpr module_id broadcast_module = 0xFFFF;

/// Static pool: every category's range, inclusive. Ids below
/// `first_dynamic_module` are static; dynamic addressing picks from
/// [first_dynamic_module, last_dynamic_module].
constexpr module_id first_dynamic_module = 0x0100;
constexpr module_id last_dynamic_module = 0xFFFE;

/// Module categories of the static pool (section 4.2 of the paper).
enum class module_category : uint8_t {
  main_controller,
  left_arm,
  right_arm,
  vision,
  sensor,
  mobile,
  manipulator,
  power,
  other,
};

/// Name of a category ("main_controller", ...).
const char* to_string(module_category x);

/// Parses a category name.
std::optional<module_category> parse_module_category(const std::string& str);

/// The static pool's range for a category; the first id is the category's
/// default (main_controller: 0x4E, as in the paper's testbed).
struct module_range {
  module_id first;
  module_id last;
};

module_range static_pool(module_category x);

/// "0x4E" (upper case, at least two hex digits).
std::string to_hex(module_id x);

/// Parses "0x4E", "0X4e", "78"; nullopt on anything else or out of range.
std::optional<module_id> parse_module_id(const std::string& str);

/// True for an id a module may hold (not no_module, not broadcast).
constexpr bool is_unicast(module_id x) {
  return x != no_module && x != broadcast_module;
}

} // namespace herm
