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

// Out of line, so that whoever makes or tests these errors links the
// names error_name() and render() give them.
caf::error make_error(routing_ec x);
caf::error make_error(routing_ec x, std::string context);
bool is(const caf::error& err, routing_ec x);

} // namespace herm
