#pragma once

// hermctl's views: each control reply's result (docs/protocol.md, "Control
// requests") printed for people as hermctl shows it ("Running hermctl" in
// docs/). Pure: they write only to the stream given, hold no state, and
// print "-" for a field the reply lacks rather than fail; each call is
// O(rows log rows) at most.

#include <iosfwd>
#include <string>

#include "apps/hermctl/format.hpp"

namespace hermctl {

/// "info": name, id, instance, uptime and one-line summaries.
void show_info(std::ostream& out, const json& r);

/// "channels": the Channel Table with counters, then a line per channel
/// that has a last error.
void show_channels(std::ostream& out, const json& r);

/// The routes of a "routes" reply to show: the selected ones of class 0,
/// or every row with `all`; ordered by destination, class, selected first.
json route_rows(const json& routes, bool all);

/// Rows from route_rows as a table; `all` adds the class, selected and
/// feasible columns.
void show_routes(std::ostream& out, const json& rows, bool all);

/// "neighbors": one line per neighbour, sorted.
void show_neighbors(std::ostream& out, const json& r);

/// "apps": local and discovered application objects.
void show_apps(std::ostream& out, const json& r);

/// "stats": a section of counters each for routing, apps, the control
/// socket (when the reply has one) and every channel.
void show_stats(std::ostream& out, const json& r);

/// "ping" to `target` (as hex) with `count` echoes: one line per echo and a
/// summary.
void show_ping(std::ostream& out, const json& r, const std::string& target,
               uint32_t count);

/// "link" of `device` to `state` ("up" or "down"): one line.
void show_link(std::ostream& out, const json& r, const std::string& device,
               const std::string& state);

/// "reload": "reloaded" and what the reply says, indented.
void show_reload(std::ostream& out, const json& r);

} // namespace hermctl
