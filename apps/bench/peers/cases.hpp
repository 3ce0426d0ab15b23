#pragma once

// herm-bench-rtt's cases: the transports as measured (a family and, for the
// actor transports, a scheduler policy) and the modes, and which variants a
// mode measures. Pure: no I/O.

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace herm::bench {

/// One transport as measured: a family (the server and client functions)
/// and, for the actor transports, a scheduler policy.
struct variant {
  std::string name;   // "herm/loop"
  std::string family; // "herm"
  std::string policy; // "loop", "sharing:1", "sharing", "stealing" or empty
  std::string label;  // for people
  bool batch = false; // udp oneway: sendmmsg
};

struct mode {
  std::string name; // "back-to-back", "gap-10ms", "oneway", "inprocess", "router"
  std::string kind; // what the endpoints do: "rtt", "oneway", "inprocess", "router"
  std::chrono::microseconds gap;
  uint32_t count;
  uint32_t warmup;
  bool latency() const {
    return kind != "oneway";
  }
};

/// "sharing:1" -> "sharing scheduler, 1 worker".
std::string policy_label(const std::string& policy);

/// True when `x` is one of `xs`.
bool has(const std::vector<std::string>& xs, const std::string& x);

/// The variants a mode measures, of the families selected, for each policy
/// of the actor transports.
std::vector<variant> variants_for(const mode& m, const std::vector<std::string>& families,
                                  const std::vector<std::string>& policies);

} // namespace herm::bench
