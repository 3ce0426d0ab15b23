#pragma once

// herm-bench-rtt's child processes: the orchestrator (role "run") runs each
// repetition of each case in fresh processes of this same executable (a
// router, a server, a client, as the mode needs) and reads the client's
// result line. Called from the orchestrator's one thread only.

#include <string>
#include <variant>

#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

/// Where the processes of a case run: a vCPU for each (-1: unpinned).
struct placement {
  std::string name; // "one-cpu", "per-cpu"
  int client_cpu = -1;
  int server_cpu = -1;
  int router_cpu = -1;
};

/// The path of this executable (/proc/self/exe), to re-execute it in a role.
std::string self_exe();

/// One repetition of one case: picks free ports (or a DDS domain and tag),
/// starts the helpers `p.mode` needs (router, server) and then the client,
/// each `exe --role ...` pinned as `where` says (in the child, before it
/// runs), with a fresh shared counter page and the helpers' pids passed to
/// the client; waits up to 30 s for each helper's ready line and for the
/// client's result line within a budget of 60 s plus the round trips' time,
/// then stops them all. The client's figures (with `counts` from its timed
/// part), or a text saying what failed.
std::variant<client_result, std::string> run_pair(const std::string& exe, endpoint_params p,
                                                  const placement& where);

/// Parses a client's result line: "rtt N t1 .. tN [counts W V A S x3]" or
/// "oneway SENT RECEIVED ELAPSED_NS STALLS CLIENT_ALLOCS SERVER_ALLOCS";
/// anything else is the client's error text.
std::variant<client_result, std::string> parse_result(const std::string& line);

/// The "counts ..." suffix of a result line for `c` (see parse_result):
/// wake-ups, voluntary switches, allocations and syscalls of the client,
/// the server and the router, -1 where not measured.
std::string format_counts(const case_counts& c);

} // namespace herm::bench
