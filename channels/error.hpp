#pragma once

#include <cstdint>
#include <string>
#include <type_traits>

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

/// Names a code of the "herm" category, of whichever layer; a code no linked
/// layer has named yields "code_<n>".
const char* error_name(uint8_t code);

/// How a layer names its codes for `error_name` and `render`: each layer's
/// names are added once, during static initialisation (see error_names).
using error_namer = const char* (*) (uint8_t code);
void add_error_names(uint8_t first, uint8_t end, error_namer namer);

/// Renders any error, HERM's or CAF's, as "category.name: context".
std::string render(const caf::error& err);

/// The codes [first, end) of the "herm" category that a layer's error enum
/// holds.
struct error_range {
  uint8_t first;
  uint8_t end;
};

/// A layer's error enum `E` declares its range by specialising this next to
/// the enum (and declaring `const char* to_string(E)`); that is what gives
/// `E` the make_error() and is() below. Other types have an empty range.
template <class E>
inline constexpr error_range error_range_of{0, 0};

template <>
inline constexpr error_range error_range_of<ec>{0, ec_end};

namespace detail {

template <class E>
using if_error_enum = std::enable_if_t<(error_range_of<E>.end > 0)>;

/// Adds the names of `E`'s range for error_name() and render() when the
/// program starts. Odr-used by make_error() and is(), so every binary that
/// makes or tests one of E's errors adds E's names (and links to_string(E));
/// initialised once however many translation units use it.
template <class E>
struct error_names {
  static const bool added;
};

template <class E>
const bool error_names<E>::added
  = (add_error_names(error_range_of<E>.first, error_range_of<E>.end,
                     [](uint8_t code) {
                       return to_string(static_cast<E>(code));
                     }),
     true);

} // namespace detail

/// Creates a `caf::error` in the "herm" category from any layer's error
/// enum.
template <class E, class = detail::if_error_enum<E>>
caf::error make_error(E x) {
  (void) detail::error_names<E>::added;
  return make_herm_error(static_cast<uint8_t>(x));
}

/// Creates a `caf::error` in the "herm" category with a context message that
/// says what was wrong, e.g. "device 'can9': no such interface".
template <class E, class = detail::if_error_enum<E>>
caf::error make_error(E x, std::string context) {
  (void) detail::error_names<E>::added;
  return make_herm_error(static_cast<uint8_t>(x), std::move(context));
}

/// Returns true if `err` is the HERM error `x`, of any layer.
template <class E, class = detail::if_error_enum<E>>
bool is(const caf::error& err, E x) {
  (void) detail::error_names<E>::added;
  return is_herm_error(err, static_cast<uint8_t>(x));
}

} // namespace herm
