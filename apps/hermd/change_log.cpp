// hermd's change log lines (apps/hermd/change_log.hpp).

#include "apps/hermd/change_log.hpp"

#include <algorithm>
#include <cstdio>

#include "routing/module_id.hpp"

namespace herm::hermd {

namespace {

/// "0x21 on eth0", or "127.0.0.1:47001 on eth0" when the next hop's module
/// id is not known.
std::string via(herm::module_id next, const std::string& address,
                const std::string& device) {
  auto hop = next != herm::no_module ? herm::to_hex(next)
                                     : (address.empty() ? "?" : address);
  return hop + " on " + (device.empty() ? "?" : device);
}

/// "(was 20 via 0x22 on eth1)", or "(new)" without a previous route.
std::string was(const herm::reachability& r) {
  if (!r.was_reachable)
    return "(new)";
  return "(was " + std::to_string(r.old_cost) + " via "
         + via(r.old_next, "", r.old_device) + ")";
}

std::string plural(uint64_t n, const char* one, const char* many) {
  return std::to_string(n) + " " + (n == 1 ? one : many);
}

} // namespace

std::string link_line(const herm::neighbour_event& e) {
  auto text = "link to " + herm::to_hex(e.id) + (e.up ? " up" : " down")
              + " on " + (e.device.empty() ? "?" : e.device) + " ("
              + (e.link_kind.empty() ? "?" : e.link_kind) + ", peer "
              + (e.link_address.empty() ? "?" : e.link_address) + ")";
  if (e.up)
    return e.reason == "restarted" ? text + " after a restart" : text;
  return text + ": " + e.reason;
}

std::string route_line(const herm::reachability& r) {
  auto dst = "route to " + herm::to_hex(r.id);
  if (!r.reachable)
    return dst + " withdrawn: unreachable " + was(r);
  return dst + ": cost " + std::to_string(r.cost) + " via "
         + via(r.next, r.link_address, r.device) + ", "
         + plural(r.hops, "hop", "hops") + ", path "
         + (r.path.empty() ? "-" : r.path) + " " + was(r);
}

bool line_budget::take(time_point now) {
  std::chrono::duration<double> dt = now - refilled_;
  refilled_ = std::max(refilled_, now);
  tokens_ = std::min(burst_, tokens_ + std::max(0.0, dt.count()) * rate_);
  if (tokens_ < 1) {
    ++held_back_;
    return false;
  }
  tokens_ -= 1;
  return true;
}

uint64_t line_budget::held_back() {
  auto n = held_back_;
  held_back_ = 0;
  return n;
}

std::string held_back_line(uint64_t routes, uint64_t links, double rate) {
  if (routes == 0 && links == 0)
    return "";
  std::string what;
  if (routes > 0)
    what = plural(routes, "route change", "route changes");
  if (links > 0)
    what += (what.empty() ? "" : " and ")
            + plural(links, "link change", "link changes");
  char r[32];
  std::snprintf(r, sizeof(r), "%g", rate);
  return what + " not logged (at most " + r
         + " lines a second each; hermctl routes and hermctl neighbors show "
           "the tables)";
}

} // namespace herm::hermd
