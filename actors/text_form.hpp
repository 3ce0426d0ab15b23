#pragma once

// The text form of APO payloads: one JSON value per message, for every
// built-in type and every described type (actors/type_description.hpp).
// What hermctl prints (topic echo, call, record --info) and reads (topic
// pub, call). docs/user-guide.md, "The text form of values", documents it.
//
// Pure: no actors, no I/O. Total and bounded on any input: decoding never
// reads past the payload, nests at most max_depth levels, and its output is
// O(payload size); encoding refuses values that do not fit their type with
// a sentence naming the field.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "caf/expected.hpp"

#include "channels/messages.hpp"

namespace herm {

using ordered_json = nlohmann::ordered_json;

/// A payload as text.
struct text_value {
  /// One element: its value. Several: an array of their values. None: null.
  ordered_json value;
  /// The type name of each element, in order.
  std::vector<std::string> types;
  /// Named types met without a description: their value, and everything
  /// after it, shows as {"@type": name, "@bytes": "hex"}.
  std::vector<std::string> undescribed;
};

/// Decodes an APO payload (docs/protocol.md, "APO payloads") into its text
/// form with the descriptions this process knows. Errors
/// (ec::invalid_parameter): not version 1, truncated, trailing bytes.
caf::expected<text_value> payload_to_text(const uint8_t* data, size_t size);

/// Encodes `value` as a payload of one element of type `types[0]`, or of
/// several when `types` has more (then `value` is an array of as many
/// values). Errors (ec::invalid_parameter): a type outside the grammar or
/// without a description, a value that does not fit ("field 'a': 300 does
/// not fit @u8").
caf::expected<byte_buffer> text_to_payload(const ordered_json& value,
                                           const std::vector<std::string>& types);

/// The type a value takes when none is given: @str for a string, bool,
/// @i64 for an integer, double for a number, "" for anything else.
std::string default_type(const ordered_json& value);

/// Lower-case hex of `size` bytes.
std::string to_hex_bytes(const uint8_t* data, size_t size);

/// Bytes from hex (either case); nullopt-like error when not hex.
caf::expected<byte_buffer> from_hex_bytes(const std::string& hex);

/// The element type names of a payload without decoding its values past
/// the first element's name: the first name, or "" if malformed.
std::string first_type_name(const uint8_t* data, size_t size);

} // namespace herm
