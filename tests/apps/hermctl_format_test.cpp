// hermctl's text for people (apps/hermctl/format.hpp, views.hpp): fields,
// bit rates, durations, --bandwidth's syntax, tables, and the views of fixed
// control replies exactly as hermctl prints them.

#include "apps/hermctl/format.hpp"
#include "apps/hermctl/views.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

using namespace hermctl;

// -- fields ------------------------------------------------------------------------------

TEST(hermctl_format, fields_print_as_text_for_people) {
  struct row {
    const char* v;
    std::string want;
  };
  std::vector<row> cases{
    {"null", "-"},          {R"("eth0")", "eth0"}, {R"("")", ""},
    {"true", "yes"},        {"false", "no"},       {"42", "42"},
    {"-7", "-7"},           {"1.5", "1.5"},        {"[1,2]", "[1,2]"},
    {R"({"a":1})", R"({"a":1})"},
  };
  for (auto& c : cases)
    EXPECT_EQ(text(json::parse(c.v)), c.want) << c.v;
}

TEST(hermctl_format, a_missing_field_is_a_dash_and_a_null_cost_is_inf) {
  auto obj = json::parse(R"({"mtu": 1500, "cost": null})");
  EXPECT_EQ(text(obj, "mtu"), "1500");
  EXPECT_EQ(text(obj, "cost"), "-");
  EXPECT_EQ(text(obj, "name"), "-");
  EXPECT_EQ(cost_text(obj["cost"]), "inf");
  EXPECT_EQ(cost_text(json(10)), "10");
}

TEST(hermctl_format, numbers_have_six_significant_digits) {
  EXPECT_EQ(number(0.5), "0.5");
  EXPECT_EQ(number(19.2), "19.2");
  EXPECT_EQ(number(3.957), "3.957");
  EXPECT_EQ(number(1234567.0), "1.23457e+06");
}

TEST(hermctl_format, module_ids_sort_by_number_and_others_last) {
  EXPECT_EQ(mid_number(json("0x4E")), 0x4Eu);
  EXPECT_EQ(mid_number(json("78")), 78u);
  EXPECT_EQ(mid_number(json("zz")), 0x10000u);
  EXPECT_EQ(mid_number(json(78)), 0x10000u);
  EXPECT_EQ(mid_number(json(nullptr)), 0x10000u);
}

TEST(hermctl_format, dot_strings_escape_quotes_and_backslashes_and_drop_newlines) {
  EXPECT_EQ(dot_escape("plain"), "plain");
  EXPECT_EQ(dot_escape("a\"b\\c\nd"), "a\\\"b\\\\cd");
}

// -- bit rates and durations ---------------------------------------------------------------

TEST(hermctl_format, bit_rates_take_the_largest_unit_that_reads_well) {
  struct row {
    uint64_t bps;
    std::string want;
  };
  std::vector<row> cases{
    {0, "0 bit/s"},
    {300, "300 bit/s"},
    {999, "999 bit/s"},
    {1'000, "1 kbit/s"},
    {19'200, "19.2 kbit/s"},
    {125'000, "125 kbit/s"},
    {1'000'000, "1 Mbit/s"},
    {12'000'000, "12 Mbit/s"},
    {100'000'000, "100 Mbit/s"},
    {1'000'000'000, "1 Gbit/s"},
    {1'500'000'000, "1.5 Gbit/s"},
    // Not a whole tenth of a Gbit/s: stays in Mbit/s.
    {1'050'000'000, "1050 Mbit/s"},
  };
  for (auto& c : cases)
    EXPECT_EQ(bandwidth_text(c.bps), c.want) << c.bps;
}

TEST(hermctl_format, durations_leave_out_leading_zero_units) {
  struct row {
    uint64_t ms;
    std::string want;
  };
  std::vector<row> cases{
    {0, "0s"},
    {999, "0s"},
    {5'000, "5s"},
    {65'000, "1m 5s"},
    {3'600'000, "1h 0m 0s"},
    {86'400'000, "1d 0h 0m 0s"},
    {((2 * 86400 + 3 * 3600 + 4 * 60 + 5) * 1000ull) + 999, "2d 3h 4m 5s"},
  };
  for (auto& c : cases)
    EXPECT_EQ(duration_text(c.ms), c.want) << c.ms;
}

TEST(hermctl_format, bandwidth_accepts_numbers_with_units_and_suffixes) {
  struct row {
    const char* s;
    uint64_t want;
  };
  std::vector<row> cases{
    {"1000000", 1'000'000},   {"1M", 1'000'000},
    {"12Mbit", 12'000'000},   {"19.2k", 19'200},
    {"19.2K", 19'200},        {"400M", 400'000'000},
    {"1.5G", 1'500'000'000},  {"100bps", 100},
    {"1Mbit/s", 1'000'000},   {"2kb/s", 2'000},
    {"125kbps", 125'000},     {"1e15", 1'000'000'000'000'000},
    {"0.5", 1},
  };
  for (auto& c : cases)
    EXPECT_EQ(parse_bandwidth(c.s), std::optional<uint64_t>{c.want}) << c.s;
}

TEST(hermctl_format, bandwidth_refuses_other_text_zero_and_too_much) {
  for (auto s : {"", "M", "bps", "abc", "0", "0M", "-5", "-1M", "1m", "1T",
                 "1 M", "1Mx", "1e16", "2000000G", "nan", "inf"})
    EXPECT_EQ(parse_bandwidth(s), std::nullopt) << s;
}

// -- tables and lists ----------------------------------------------------------------------

TEST(hermctl_format, table_columns_are_as_wide_as_their_widest_cell) {
  std::ostringstream out;
  print_table(out, {"A", "LONG", "END"},
              {{"xyz", "1", "tail"}, {"x", "22222", "t"}});
  EXPECT_EQ(out.str(),
            "A    LONG   END\n"
            "xyz  1      tail\n"
            "x    22222  t\n");
}

TEST(hermctl_format, a_short_row_is_not_padded_and_an_empty_table_is_its_header) {
  std::ostringstream out;
  print_table(out, {"ID", "DEVICE"}, {{"1"}});
  EXPECT_EQ(out.str(), "ID  DEVICE\n1\n");
  std::ostringstream empty;
  print_table(empty, {"ID", "DEVICE"}, {});
  EXPECT_EQ(empty.str(), "ID  DEVICE\n");
}

TEST(hermctl_format, pairs_align_their_values_after_the_longest_key) {
  std::ostringstream out;
  print_pairs(out, {{"a", "1"}, {"long", "2"}}, "  ");
  EXPECT_EQ(out.str(), "  a     1\n  long  2\n");
}

TEST(hermctl_format, json_is_indented_by_two) {
  std::ostringstream out;
  print_json(out, json::parse(R"({"a": [1]})"));
  EXPECT_EQ(out.str(), "{\n  \"a\": [\n    1\n  ]\n}\n");
}

// -- views -------------------------------------------------------------------------------

namespace {

template <class F>
std::string shown(F f) {
  std::ostringstream out;
  f(out);
  return out.str();
}

} // namespace

TEST(hermctl_views, info_summarises_the_module) {
  auto r = json::parse(R"({"name": "alpha", "module": "0x30", "id": 48,
    "instance": 255, "assigned": true, "uptime_ms": 65034, "reachable": 2,
    "registered": "yes", "neighbours": 3,
    "apps": {"local": 1, "known_remote": 4, "bindings": 0},
    "channels": {"up": 2, "total": 3}})");
  EXPECT_EQ(shown([&](auto& out) { show_info(out, r); }),
            "module    alpha (0x30)\n"
            "instance  0xff\n"
            "uptime    1m 5s\n"
            "routing   2 modules reachable, 3 neighbours\n"
            "channels  2 up of 3\n"
            "apps      1 local, 4 known remote, 0 bindings\n"
            "control   registered as herm.control\n");
  r["registered"] = "herm.already_exists: taken";
  EXPECT_NE(shown([&](auto& out) { show_info(out, r); })
              .find("control   not registered: herm.already_exists: taken\n"),
            std::string::npos);
}

namespace {

const char* routes_reply = R"([
  {"destination": "0x32", "size_class": 1, "size_class_bytes": 64,
   "channel": 1, "neighbour": "2", "neighbour_module": "0x31",
   "cost": 40, "hops": 2, "forwarding": "Ethernet-Ethernet",
   "selected": true, "feasible": true},
  {"destination": "0x32", "size_class": 0, "size_class_bytes": 8,
   "channel": 2, "neighbour": "9", "neighbour_module": null,
   "cost": 50, "hops": 3, "forwarding": "CAN2.0",
   "selected": false, "feasible": false},
  {"destination": "0x32", "size_class": 0, "size_class_bytes": 8,
   "channel": 1, "neighbour": "2", "neighbour_module": "0x31",
   "cost": 20, "hops": 2, "forwarding": "Ethernet-Ethernet",
   "selected": true, "feasible": true},
  {"destination": "0x05", "size_class": 0, "size_class_bytes": 8,
   "channel": 2, "neighbour": "7", "neighbour_module": null,
   "cost": null, "hops": 1, "forwarding": "",
   "selected": true, "feasible": true}])";

} // namespace

TEST(hermctl_views, routes_show_selected_class_0_rows_by_destination) {
  auto rows = route_rows(json::parse(routes_reply), false);
  EXPECT_EQ(shown([&](auto& out) { show_routes(out, rows, false); }),
            "DESTINATION  NEXT CHANNEL  NEIGHBOUR      COST  HOPS  FORWARDING\n"
            "0x05         2             link 7         inf   1     -\n"
            "0x32         1             0x31 (link 2)  20    2     Ethernet-Ethernet\n");
}

TEST(hermctl_views, all_routes_order_by_destination_class_then_selected_first) {
  auto rows = route_rows(json::parse(routes_reply), true);
  EXPECT_EQ(shown([&](auto& out) { show_routes(out, rows, true); }),
            "DESTINATION  CLASS     NEXT CHANNEL  NEIGHBOUR      COST  HOPS  "
            "FORWARDING         SELECTED  FEASIBLE\n"
            "0x05         0 (8 B)   2             link 7         inf   1     "
            "-                  yes       yes\n"
            "0x32         0 (8 B)   1             0x31 (link 2)  20    2     "
            "Ethernet-Ethernet  yes       yes\n"
            "0x32         0 (8 B)   2             link 9         50    3     "
            "CAN2.0             no        no\n"
            "0x32         1 (64 B)  1             0x31 (link 2)  40    2     "
            "Ethernet-Ethernet  yes       yes\n");
}

TEST(hermctl_views, neighbours_are_sorted_with_their_class_0_cost) {
  auto r = json::parse(R"([
    {"module": "0x31", "channel": 2, "link_address": "2",
     "link_kind": "CAN2.0", "cost": [30, 240], "last_heard_ms": 83},
    {"module": "0x30", "channel": 1, "link_address": "10",
     "link_kind": "Ethernet", "cost": [], "last_heard_ms": 5}])");
  EXPECT_EQ(shown([&](auto& out) { show_neighbors(out, r); }),
            "MODULE  CHANNEL  LINK ADDRESS  LINK      COST  LAST HEARD\n"
            "0x30    1        10            Ethernet  -     5 ms\n"
            "0x31    2        2             CAN2.0    30    83 ms\n");
}

TEST(hermctl_views, ping_prints_each_echo_and_a_summary) {
  auto r = json::parse(R"({"module": "0x32", "count": 3, "received": 2,
    "lost": 1, "rtt_us": [302, 97], "min_us": 97, "avg_us": 199,
    "max_us": 302})");
  EXPECT_EQ(shown([&](auto& out) { show_ping(out, r, "0x32", 3); }),
            "PING 0x32: 3 echoes to its control service\n"
            "echo 1: 302 us\n"
            "echo 2: 97 us\n"
            "3 sent, 2 received, 1 lost; rtt min/avg/max = 97/199/302 us\n");
  auto none = json::parse(R"({"count": 2, "received": 0, "lost": 2})");
  EXPECT_EQ(shown([&](auto& out) { show_ping(out, none, "0x40", 2); }),
            "PING 0x40: 2 echoes to its control service\n"
            "2 sent, 0 received, 2 lost\n");
}

TEST(hermctl_views, link_says_what_changed) {
  struct row {
    const char* reply;
    const char* state;
    std::string want;
  };
  std::vector<row> cases{
    {R"({"closed": [1, 2]})", "down", "eth0: down (closed channel 1, 2)\n"},
    {R"({"closed": []})", "down", "eth0: down (no channel was open)\n"},
    {R"({"opened": true, "channels": [3]})", "up", "eth0: up (opened channel 3)\n"},
    {R"({"opened": false, "channels": [3, 4]})", "up",
     "eth0: already up (channel 3, 4)\n"},
  };
  for (auto& c : cases)
    EXPECT_EQ(shown([&](auto& out) {
                show_link(out, json::parse(c.reply), "eth0", c.state);
              }),
              c.want)
      << c.reply;
}

TEST(hermctl_views, reload_lists_what_the_reply_says) {
  auto r = json::parse(R"({"changed": ["log"], "count": 2})");
  EXPECT_EQ(shown([&](auto& out) { show_reload(out, r); }),
            "reloaded\n  changed  [\"log\"]\n  count    2\n");
  EXPECT_EQ(shown([&](auto& out) { show_reload(out, json(nullptr)); }),
            "reloaded\n");
  EXPECT_EQ(shown([&](auto& out) { show_reload(out, json("done")); }),
            "reloaded\n  done\n");
}
