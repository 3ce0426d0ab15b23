// hermctl's views (apps/hermctl/views.hpp).

#include "apps/hermctl/views.hpp"

#include <algorithm>
#include <ostream>
#include <sstream>
#include <tuple>
#include <vector>

namespace hermctl {

namespace {

/// One table row per element of `items`, made by `to_row`.
template <class F>
std::vector<row> rows_of(const json& items, F to_row) {
  std::vector<row> rows;
  for (auto& x : items)
    rows.push_back(to_row(x));
  return rows;
}

std::string neighbour_text(const json& route) {
  auto mod = route.value("neighbour_module", json{});
  if (mod.is_string())
    return mod.get<std::string>() + " (link " + text(route, "neighbour") + ")";
  return "link " + text(route, "neighbour");
}

/// Every section of "stats" but a channel's identity fields.
void print_section(std::ostream& out, const std::string& title, const json& obj) {
  out << title << '\n';
  std::vector<std::pair<std::string, std::string>> pairs;
  for (auto& [k, v] : obj.items())
    if (k != "id" && k != "device" && k != "state")
      pairs.emplace_back(k, text(v));
  print_pairs(out, pairs, "  ");
}

} // namespace

void show_info(std::ostream& out, const json& r) {
  auto inst = r.value("instance", uint64_t{0});
  std::ostringstream instance;
  instance << "0x" << std::hex << inst;
  auto apps = r.value("apps", json::object());
  auto channels = r.value("channels", json::object());
  print_pairs(out, {
    {"module", text(r, "name") + " (" + text(r, "module") + ")"},
    {"instance", instance.str()},
    {"uptime", duration_text(r.value("uptime_ms", uint64_t{0}))},
    {"routing", text(r, "reachable") + " modules reachable, "
                  + text(r, "neighbours") + " neighbours"},
    {"channels", text(channels, "up") + " up of " + text(channels, "total")},
    {"apps", text(apps, "local") + " local, " + text(apps, "known_remote")
               + " known remote, " + text(apps, "bindings") + " bindings"},
    {"control", r.value("registered", std::string{}) == "yes"
                  ? std::string{"registered as herm.control"}
                  : "not registered: " + text(r, "registered")},
  });
}

void show_channels(std::ostream& out, const json& r) {
  std::vector<row> rows;
  std::vector<std::string> notes;
  for (auto& ch : r) {
    auto p = ch.value("profile", json::object());
    auto s = ch.value("stats", json{});
    auto stat = [&](const char* k) { return s.is_object() ? text(s, k) : "-"; };
    std::string dropped = "-";
    if (s.is_object())
      dropped = std::to_string(s.value("tx_dropped", uint64_t{0})
                               + s.value("rx_malformed", uint64_t{0})
                               + s.value("rx_reassembly_dropped", uint64_t{0}));
    auto bps = p.value("bandwidth_bps", uint64_t{0});
    rows.push_back({text(ch, "id"), text(ch, "device"), text(ch, "kind"),
                    text(ch, "address"), text(ch, "state"), text(p, "name"),
                    bps > 0 ? bandwidth_text(bps) : "-", text(p, "mtu"),
                    cost_text(p.value("cost", json{})), stat("tx_packets"),
                    stat("tx_bytes"), stat("rx_packets"), stat("rx_bytes"),
                    dropped});
    auto err = ch.value("last_error", std::string{});
    if (!err.empty())
      notes.push_back("channel " + text(ch, "id") + " (" + text(ch, "state")
                      + "): " + err);
  }
  print_table(out,
              {"ID", "DEVICE", "KIND", "ADDRESS", "STATE", "PROFILE",
               "BANDWIDTH", "MTU", "COST", "TX PKTS", "TX BYTES", "RX PKTS",
               "RX BYTES", "DROPPED"},
              rows);
  for (auto& n : notes)
    out << n << '\n';
}

json route_rows(const json& routes, bool all) {
  std::vector<json> rows;
  for (auto& r : routes)
    if (all || (r.value("selected", false) && r.value("size_class", 0) == 0))
      rows.push_back(r);
  std::stable_sort(rows.begin(), rows.end(), [](const json& a, const json& b) {
    auto ka = std::make_tuple(mid_number(a["destination"]),
                              a.value("size_class", 0),
                              !a.value("selected", false));
    auto kb = std::make_tuple(mid_number(b["destination"]),
                              b.value("size_class", 0),
                              !b.value("selected", false));
    return ka < kb;
  });
  return json(rows);
}

void show_routes(std::ostream& out, const json& rows, bool all) {
  auto lines = rows_of(rows, [all](const json& r) {
    row line{text(r, "destination")};
    if (all)
      line.push_back(text(r, "size_class") + " (" + text(r, "size_class_bytes")
                     + " B)");
    line.insert(line.end(),
                {text(r, "channel"), neighbour_text(r),
                 cost_text(r.value("cost", json{})), text(r, "hops"),
                 r.value("forwarding", std::string{}).empty()
                   ? std::string{"-"}
                   : text(r, "forwarding")});
    if (all) {
      line.push_back(text(r, "selected"));
      line.push_back(text(r, "feasible"));
    }
    return line;
  });
  if (all)
    print_table(out,
                {"DESTINATION", "CLASS", "NEXT CHANNEL", "NEIGHBOUR", "COST",
                 "HOPS", "FORWARDING", "SELECTED", "FEASIBLE"},
                lines);
  else
    print_table(out,
                {"DESTINATION", "NEXT CHANNEL", "NEIGHBOUR", "COST", "HOPS",
                 "FORWARDING"},
                lines);
}

void show_neighbors(std::ostream& out, const json& r) {
  auto rows = rows_of(r, [](const json& n) {
    auto cost = n.value("cost", json::array());
    return row{text(n, "module"), text(n, "channel"), text(n, "link_address"),
               text(n, "link_kind"), cost.empty() ? "-" : cost_text(cost[0]),
               text(n, "last_heard_ms") + " ms"};
  });
  std::sort(rows.begin(), rows.end());
  print_table(out,
              {"MODULE", "CHANNEL", "LINK ADDRESS", "LINK", "COST",
               "LAST HEARD"},
              rows);
}

void show_apps(std::ostream& out, const json& r) {
  print_table(out, {"MODULE", "APO", "NAME", "TYPE", "WHERE", "STATE"},
              rows_of(r, [](const json& a) {
                bool local = a.value("local", false);
                return row{text(a, "module"), text(a, "apo"), text(a, "name"),
                           text(a, "type"), local ? "local" : "remote",
                           local ? "watched by " + text(a, "watchers") + " modules"
                                 : "heard " + number(a.value("age_ms", 0) / 1000.0)
                                     + " s ago"};
              }));
}

void show_stats(std::ostream& out, const json& r) {
  print_section(out, "routing", r.value("routing", json::object()));
  print_section(out, "apps", r.value("apps", json::object()));
  // Only the local socket has one: a module reached with --module answers
  // without it.
  if (r.contains("control_socket"))
    print_section(out, "control socket", r["control_socket"]);
  for (auto& ch : r.value("channels", json::array()))
    print_section(out, "channel " + text(ch, "id") + " (" + text(ch, "device")
                         + ", " + text(ch, "state") + ")",
                  ch);
}

void show_ping(std::ostream& out, const json& r, const std::string& target,
               uint32_t count) {
  out << "PING " << target << ": " << count
      << " echoes to its control service\n";
  auto rtts = r.value("rtt_us", json::array());
  for (size_t i = 0; i < rtts.size(); ++i)
    out << "echo " << i + 1 << ": " << text(rtts[i]) << " us\n";
  out << text(r, "count") << " sent, " << text(r, "received") << " received, "
      << text(r, "lost") << " lost";
  if (!rtts.empty())
    out << "; rtt min/avg/max = " << text(r, "min_us") << "/"
        << text(r, "avg_us") << "/" << text(r, "max_us") << " us";
  out << '\n';
}

void show_link(std::ostream& out, const json& r, const std::string& device,
               const std::string& state) {
  auto ids = [](const json& a) {
    std::string s;
    for (auto& x : a)
      s += (s.empty() ? "" : ", ") + text(x);
    return s;
  };
  if (state == "down") {
    auto closed = r.value("closed", json::array());
    out << device << ": down"
        << (closed.empty() ? std::string{" (no channel was open)"}
                           : " (closed channel " + ids(closed) + ")")
        << '\n';
  } else {
    auto chans = r.value("channels", json::array());
    out << device << ": "
        << (r.value("opened", false) ? "up (opened channel "
                                     : "already up (channel ")
        << ids(chans) << ")\n";
  }
}

void show_reload(std::ostream& out, const json& r) {
  out << "reloaded\n";
  if (r.is_object()) {
    std::vector<std::pair<std::string, std::string>> pairs;
    for (auto& [k, v] : r.items())
      pairs.emplace_back(k, v.is_array() || v.is_object() ? v.dump() : text(v));
    print_pairs(out, pairs, "  ");
  } else if (!r.is_null()) {
    out << "  " << text(r) << '\n';
  }
}

} // namespace hermctl
