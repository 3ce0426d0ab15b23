#pragma once

// Rendering a DOT graph with graphviz's `dot`, for "hermctl topology --svg
// / --png". Blocking: runs a child process and waits for it; call from the
// command-line thread only.

#include <optional>
#include <string>

namespace hermctl {

/// True if `dot` is an executable file in a directory of $PATH.
bool have_dot();

/// Runs `dot -T<format> -o <file>` with `graph` on its stdin and waits for
/// it; nullopt on success, else one line saying what failed (no pipe or
/// process, or dot did not exit with 0).
std::optional<std::string> render_dot(const std::string& graph,
                                      const std::string& format,
                                      const std::string& file);

} // namespace hermctl
