#pragma once

// hermctl's text for people: control-reply fields as text, bit rates and
// durations, aligned tables and key/value lists, and the bit-rate syntax of
// --bandwidth. Pure: no I/O but the stream a caller passes, no state; every
// call is O(size of its input). What these print is hermctl's documented
// output ("Running hermctl" in docs/): changing a format changes it.

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace hermctl {

using json = nlohmann::json;

/// A field as text: strings as they are, booleans as yes/no, null as "-",
/// numbers (and anything else) as compact JSON.
std::string text(const json& v);

/// Field `key` of object `obj` as text; "-" when absent.
std::string text(const json& obj, const char* key);

/// A cost field: "inf" for null (unreachable), else text(v).
std::string cost_text(const json& v);

/// `x` as an ostream prints it by default (6 significant digits).
std::string number(double x);

/// "1 Gbit/s", "12 Mbit/s", "19.2 kbit/s", "300 bit/s".
std::string bandwidth_text(uint64_t bps);

/// Milliseconds as "2d 3h 4m 5s", leading zero units left out ("5s").
std::string duration_text(uint64_t ms);

/// "1000000", "1M", "12Mbit", "19.2k", "400M", "1.5G" (bit/s, optional
/// suffix bit/s, bps, bit or b/s) as bit/s; nullopt for anything else, for
/// zero or less and above 1e15.
std::optional<uint64_t> parse_bandwidth(const std::string& s);

/// A module id field ("0x4E") as a number for sorting; 0x10000 (after every
/// id) when it is not one.
uint32_t mid_number(const json& v);

/// `s` for a double-quoted DOT string: quotes and backslashes escaped,
/// newlines dropped.
std::string dot_escape(const std::string& s);

using row = std::vector<std::string>;

/// Columns separated by two spaces, each as wide as its widest cell (the
/// last cell of a line is not padded); cells past the header's are dropped.
void print_table(std::ostream& out, const row& header,
                 const std::vector<row>& rows);

/// "key  value" lines, keys aligned, each line prefixed by `indent`.
void print_pairs(std::ostream& out,
                 const std::vector<std::pair<std::string, std::string>>& pairs,
                 const std::string& indent = "");

/// `j` indented by two, invalid UTF-8 replaced, and a newline.
void print_json(std::ostream& out, const json& j);

} // namespace hermctl
