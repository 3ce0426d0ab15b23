#pragma once

#include "channels/error.hpp"

namespace herm {

/// The Network Adaptation Layer's errors: codes from `ec_end` of the "herm"
/// category (channels/error.hpp says how the layers share it).
enum class routing_ec : uint8_t {
  /// No route to the destination module.
  no_route = ec_end,
};

/// The first code after this layer's range: where actors/runtime/error.hpp
/// starts.
constexpr uint8_t routing_ec_end = ec_end + 1;

/// Returns the enumerator's name, e.g. "no_route".
const char* to_string(routing_ec x);

/// This layer's codes; gives its enum make_error() and is()
/// (channels/error.hpp).
template <>
inline constexpr error_range error_range_of<routing_ec>{ec_end, routing_ec_end};

} // namespace herm
