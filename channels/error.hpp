#pragma once

#include <cstdint>
#include <string>

#include "caf/error.hpp"

namespace herm {

// HERM's errors all travel in one CAF error category, "herm", and each layer
// owns a range of its codes: the Network Interface Layer the codes below
// `ec_end` (the generic ones every layer uses are among them), the Network
// Adaptation Layer from there (routing/error.hpp), the Application Support
// Layer after that (actors/runtime/error.hpp). A code is fixed once released:
// error replies carry it between modules (docs/protocol.md, "APO messages").

/// The Network Interface Layer's errors, and the generic ones.
enum class ec : uint8_t {
  none = 0,
  /// No device with that name is registered with the IO manager.
  unknown_device = 1,
  /// No link kind with that name is compiled in.
  unknown_link_kind = 2,
  /// A device or channel address does not parse for its link kind.
  invalid_address = 3,
  /// A parameter name is unknown or its value is impossible.
  invalid_parameter = 4,
  /// A device exists but cannot be opened now (errno text in the context).
  device_unavailable = 5,
  /// A device failed while in use (socket error, file removed, peer gone).
  device_failed = 6,
  /// The channel was closed by its owner.
  channel_closed = 7,
  /// No channel with that id is in the channel table.
  unknown_channel = 8,
  /// A packet is larger than the channel can carry, even fragmented.
  packet_too_large = 9,
  /// A bounded queue is full; the item was dropped.
  queue_full = 10,
  /// A name is already taken (device name, channel).
  already_exists = 11,
  /// A configuration file is invalid (file, line and field in the context).
  invalid_config = 12,
  /// A request did not complete in time.
  timeout = 13,
};

/// The first code after this layer's range: where routing/error.hpp starts.
constexpr uint8_t ec_end = 14;

/// Returns the enumerator's name, e.g. "unknown_device".
const char* to_string(ec x);

/// Creates a `caf::error` in the "herm" category with code `code` of any
/// layer, and a context message that says what was wrong.
caf::error make_herm_error(uint8_t code);
caf::error make_herm_error(uint8_t code, std::string context);

/// Returns true if `err` is in the "herm" category with code `code`.
bool is_herm_error(const caf::error& err, uint8_t code);

/// Creates a `caf::error` in the "herm" category.
inline caf::error make_error(ec x) {
  return make_herm_error(static_cast<uint8_t>(x));
}

/// Creates a `caf::error` in the "herm" category with a context message that
/// says what was wrong, e.g. "device 'can9': no such interface".
inline caf::error make_error(ec x, std::string context) {
  return make_herm_error(static_cast<uint8_t>(x), std::move(context));
}

/// Returns true if `err` is the HERM error `x`.
inline bool is(const caf::error& err, ec x) {
  return is_herm_error(err, static_cast<uint8_t>(x));
}

/// Names a code of the "herm" category, of whichever layer; a code no linked
/// layer has named yields "code_<n>".
const char* error_name(uint8_t code);

/// How a higher layer names its codes for `error_name` and `render`: each
/// layer's error.cpp adds its range once, during static initialisation.
using error_namer = const char* (*) (uint8_t code);
void add_error_names(uint8_t first, uint8_t end, error_namer namer);

/// Renders any error, HERM's or CAF's, as "category.name: context".
std::string render(const caf::error& err);

} // namespace herm
