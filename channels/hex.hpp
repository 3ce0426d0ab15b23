#pragma once

// Hex digits, for the text forms of byte strings: key files
// (routing/auth.cpp) and payloads in JSON (actors/text_form.cpp).

namespace herm {

/// The value of hex digit `c` (either case), or -1 if it is none.
constexpr int hex_digit(char c) {
  if (c >= '0' && c <= '9')
    return c - '0';
  if (c >= 'a' && c <= 'f')
    return c - 'a' + 10;
  if (c >= 'A' && c <= 'F')
    return c - 'A' + 10;
  return -1;
}

} // namespace herm
