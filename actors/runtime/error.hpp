#pragma once

#include "routing/error.hpp"

namespace herm {

/// The Application Support Layer's errors: codes from `routing_ec_end` of
/// the "herm" category (channels/error.hpp says how the layers share it).
/// Including this header gives every layer's errors.
enum class app_ec : uint8_t {
  /// A message names a type this module does not know (an APO payload whose
  /// type name is not in the receiving module's type-ID blocks).
  unknown_type = routing_ec_end,
  /// The remote application object exited, or its module restarted.
  apo_gone,
  /// Nothing matched (discovery found no application object).
  not_found,
  /// The receiver refuses the request from where it came: remote control
  /// that did not arrive signed in a keyed network, or reached a module
  /// without a key that does not allow unsigned remote control
  /// (docs/user-guide.md, "auth").
  unauthorized,
  /// A core actor of a module (IO manager, routing agent, application
  /// support) has stopped: nothing will serve the request.
  unavailable,
};

/// The first code after this layer's range.
constexpr uint8_t app_ec_end = static_cast<uint8_t>(app_ec::unavailable) + 1;

/// Returns the enumerator's name, e.g. "apo_gone".
const char* to_string(app_ec x);

/// This layer's codes; gives its enum make_error() and is()
/// (channels/error.hpp).
template <>
inline constexpr error_range error_range_of<app_ec>{routing_ec_end,
                                                  app_ec_end};

/// HERM's typed error for `err`: CAF's own codes become HERM's
/// (request_timeout: ec::timeout; request_receiver_down: app_ec::apo_gone;
/// unexpected_message: ec::invalid_parameter; any other system.* code:
/// app_ec::unavailable with CAF's rendering as its context); HERM's errors
/// and none pass through. The one mapping: the control service and the
/// embedding helpers (actors/embed.hpp) use it, so a user never sees a
/// `system.*` code from them.
caf::error typed_error(const caf::error& err);

} // namespace herm
