#pragma once

// herm-bench-rtt's child processes: the orchestrator (role "run") runs each
// repetition of each case in fresh processes of this same executable (a
// router, a server, a client, as the mode needs) and reads the client's
// result line. Called from the orchestrator's one thread only.

#include <string>
#include <variant>

#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

/// The path of this executable (/proc/self/exe), to re-execute it in a role.
std::string self_exe();

/// One repetition of one case: picks free ports (or a DDS domain and tag),
/// starts the helpers `p.mode` needs (router, server) and then the client,
/// each `exe --role ...`, waits up to 30 s for each helper's ready line and
/// for the client's result line within a budget of 60 s plus the round
/// trips' time, then stops them all. The client's figures, or a text saying
/// what failed.
std::variant<client_result, std::string> run_pair(const std::string& exe, endpoint_params p);

} // namespace herm::bench
