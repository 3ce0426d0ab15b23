#pragma once

#include <cstdint>
#include <string>

#include "caf/error.hpp"

namespace herm {

/// Every error HERM reports, as one enum registered with CAF under the
/// category atom "herm". Errors travel as `caf::error` with a human-readable
/// context string that names the device, address or field at fault.
enum class ec : uint8_t {
  none = 0,
  /// No device with that name is registered with the IO manager.
  unknown_device,
  /// No link kind with that name is compiled in.
  unknown_link_kind,
  /// A device or channel address does not parse for its link kind.
  invalid_address,
  /// A parameter name is unknown or its value is impossible.
  invalid_parameter,
  /// A device exists but cannot be opened now (errno text in the context).
  device_unavailable,
  /// A device failed while in use (socket error, file removed, peer gone).
  device_failed,
  /// The channel was closed by its owner.
  channel_closed,
  /// No channel with that id is in the channel table.
  unknown_channel,
  /// A packet is larger than the channel can carry, even fragmented.
  packet_too_large,
  /// A bounded queue is full; the item was dropped.
  queue_full,
  /// A name is already taken (device name, channel).
  already_exists,
  /// A configuration file is invalid (file, line and field in the context).
  invalid_config,
  /// A request did not complete in time.
  timeout,
  /// No route to the destination module.
  no_route,
  /// A message names a type this module does not know (an APO payload whose
  /// type name is not in the receiving module's type-ID blocks).
  unknown_type,
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

/// Returns the enumerator's name, e.g. "unknown_device".
const char* to_string(ec x);

/// Creates a `caf::error` in the "herm" category.
caf::error make_error(ec x);

/// Creates a `caf::error` in the "herm" category with a context message that
/// says what was wrong, e.g. "device 'can9': no such interface".
caf::error make_error(ec x, std::string context);

/// Returns true if `err` is the HERM error `x`.
bool is(const caf::error& err, ec x);

/// Renders any error, HERM's or CAF's, as "category.name: context".
std::string render(const caf::error& err);

} // namespace herm
