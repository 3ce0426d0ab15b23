// herm-bench-rtt's cases (see cases.hpp).

#include "apps/bench/peers/cases.hpp"

#include <algorithm>
#include <thread>

#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

/// "sharing:1" -> "sharing scheduler, 1 worker".
std::string policy_label(const std::string& policy) {
  auto [name, threads] = split_policy(policy);
  if (name == "loop")
    return threads == 0
             ? "loop scheduler (one thread runs the actors and the sockets)"
             : "loop scheduler, busy-polling " + std::to_string(threads) + " us";
  if (threads == 0)
    return name + " scheduler, one worker per core ("
           + std::to_string(std::thread::hardware_concurrency()) + ")";
  return name + " scheduler, " + std::to_string(threads)
         + (threads == 1 ? " worker" : " workers");
}

bool has(const std::vector<std::string>& xs, const std::string& x) {
  return std::find(xs.begin(), xs.end(), x) != xs.end();
}

/// The variants a mode measures, of the families selected.
std::vector<variant> variants_for(const mode& m, const std::vector<std::string>& families,
                                  const std::vector<std::string>& policies) {
  std::vector<variant> out;
  auto actor = [&](const std::string& family, const std::string& what) {
    for (auto& pol : policies)
      out.push_back({family + "/" + pol, family, pol, what + ", " + policy_label(pol)});
  };
  if (m.kind == "inprocess") {
    if (has(families, "herm")) {
      actor("herm", "HERM in one process: proxy bound by name on the same module "
                    "(a local match: the APO itself)");
      actor("herm-rebind", "HERM in one process: rebinding proxy bound by name on the "
                           "same module (through the application support actor)");
    }
    if (has(families, "caf"))
      actor("caf-local", "plain CAF request to the echo actor in one process");
    return out;
  }
  if (m.kind == "router") {
    if (has(families, "herm"))
      actor("herm", "HERM APO request across a router module (udp A-R, R-B)");
    return out;
  }
  bool oneway = m.kind == "oneway";
  for (auto& f : families) {
    if (f == "udp") {
      if (oneway) {
        out.push_back({"udp", "udp", "", "raw UDP, one blocking socket, send loop (the floor)"});
        out.push_back({"udp/sendmmsg", "udp", "",
                       "raw UDP, one blocking socket, sendmmsg batches of up to 64", true});
      } else {
        out.push_back({"udp", "udp", "", "raw UDP, blocking sockets (the floor)"});
      }
    } else if (f == "herm") {
      actor("herm", oneway ? "HERM one-way send through a proxy to a counting APO, udp link"
                           : "HERM APO request through a proxy, udp link");
    } else if (f == "caf") {
      actor("caf", oneway ? "CAF 0.17 io::middleman remote actor (TCP), one-way send"
                          : "CAF 0.17 io::middleman remote actor (TCP)");
    } else if (f == "zmq") {
      out.push_back({"zmq", "zmq", "", oneway ? "ZeroMQ PUSH/PULL (TCP)" : "ZeroMQ REQ/REP (TCP)"});
    } else if (f == "dds") {
      out.push_back({"dds", "dds", "",
                     oneway ? "Cyclone DDS, reliable, keep-all" : "Cyclone DDS, reliable, keep-last 1"});
    }
  }
  return out;
}

} // namespace herm::bench
