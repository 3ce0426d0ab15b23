#pragma once

// hermd's log of what changes in the network: one line per link (neighbour)
// coming up or going down and per change of a destination's selected route,
// never one per hello; at a bounded rate, what the bound holds back summed
// up in one line. Pure: text and a token bucket with time passed in; the
// route logger actor in main.cpp feeds them events and writes the lines.

#include <chrono>
#include <cstdint>
#include <string>

#include "routing/routing_agent.hpp"

namespace herm::hermd {

/// "link to 0x22 up on eth0 (Ethernet, peer 127.0.0.1:47001)", with
/// " after a restart" for a neighbour's new instance; "link to 0x22 down on
/// eth0 (Ethernet, peer 127.0.0.1:47001): goodbye" (or "hellos lost",
/// "channel closed").
std::string link_line(const herm::neighbour_event& e);

/// One route event as a line:
///   "route to 0x40: cost 12 via 0x21 on eth0, 2 hops, path Ethernet-CAN2.0
///    (was 20 via 0x22 on eth1)"           a changed route
///   "... (new)"                           a destination reachable again
///   "route to 0x40 withdrawn: unreachable (was 20 via 0x22 on eth1)"
/// A next hop whose module id is unknown shows as its link address.
std::string route_line(const herm::reachability& r);

/// A token bucket for log lines: `burst` lines at once, then `rate` a
/// second; what it refuses is counted until taken by held_back(). Time is
/// passed in (monotonic).
class line_budget {
public:
  using time_point = std::chrono::steady_clock::time_point;

  line_budget(double burst, double rate, time_point now)
    : burst_(burst), rate_(rate), tokens_(burst), refilled_(now) {
    // nop
  }

  /// True if a line may be written at `now` (and spends it); false counts
  /// one held back.
  bool take(time_point now);

  /// Lines held back since the last call; resets the count.
  uint64_t held_back();

  double rate() const {
    return rate_;
  }

private:
  double burst_;
  double rate_;
  double tokens_;
  time_point refilled_;
  uint64_t held_back_ = 0;
};

/// "3 route changes and 40 link changes not logged (at most 20 lines a
/// second each; hermctl routes and hermctl neighbors show the tables)",
/// leaving out a kind with 0; "" when both are 0.
std::string held_back_line(uint64_t routes, uint64_t links, double rate);

} // namespace herm::hermd
