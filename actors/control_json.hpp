#pragma once

// The JSON side of the control service (actors/control.hpp): reply lines,
// HERM's tables and counters as JSON objects, and the fields a request
// carries. Pure: no actors, no I/O, no clock; every function is a plain
// conversion, O(size of its input), and safe to call from any thread.
// The field names are the control protocol (docs/protocol.md, "Control
// requests"): renaming one is a protocol change.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "caf/error.hpp"

#include "actors/module.hpp"

namespace herm::control_json {

using json = nlohmann::json;

// -- replies ---------------------------------------------------------------------------

/// One line of compact JSON; invalid UTF-8 in names is replaced, never thrown.
std::string dump(const json& j);

/// {"ok": true, "result": result}.
std::string ok_reply(json result);

/// {"ok": false, "error": {"code": code, "message": message}}.
std::string error_reply(const std::string& code, const std::string& message);

/// An error reply for `err`: HERM's codes by name ("no_route"), CAF's request
/// timeout as "timeout", a stopped core actor as "unavailable", any other
/// CAF code as "system.NAME"; the message is the error's sentence if it has
/// one, else its rendering.
std::string error_reply(const caf::error& err);

// -- HERM's types ------------------------------------------------------------------------

/// A cost as a number, or null when it is infinite (unreachable).
json cost_json(uint64_t cost);

json to_json(const link_profile& p);
json to_json(const channel_stats& s);
/// A Channel Table row; "stats" is null (filled in by whoever asks the channel).
json to_json(const channel_entry& e);
json to_json(const routing_stats& s);
json to_json(const app_support_stats& s);
json to_json(const neighbour_info& n);
json to_json(const apo_info& a);

/// A route row, completed with what the neighbour table `ns` says about its
/// next hop (its module, link kind and direct cost in the row's class);
/// null there when no neighbour matches. O(size of ns).
json to_json(const route_info& r, const std::vector<neighbour_info>& ns);

/// Each row of `rows` through to_json, as a JSON array.
template <class Row>
json rows_json(const std::vector<Row>& rows) {
  json out = json::array();
  for (auto& r : rows)
    out.push_back(to_json(r));
  return out;
}

// -- request fields ----------------------------------------------------------------------

/// A module id given as "0x4E", "78" or 78; nullopt for anything else.
std::optional<module_id> module_field(const json& v);

/// The unsigned field `key` of `req` in [lo, hi], `fallback` when absent;
/// nullopt when present but not such a number.
std::optional<uint32_t> uint_field(const json& req, const char* key,
                                   uint32_t fallback, uint32_t lo, uint32_t hi);

/// True for a reply line's JSON that says {"ok": true}; false for anything
/// else, whatever its shape (replies may come from other modules: never
/// throws).
bool is_ok_reply(const json& reply);

/// The string field `key` of `req`; empty when absent or not a string.
std::string string_field(const json& req, const char* key);

} // namespace herm::control_json
