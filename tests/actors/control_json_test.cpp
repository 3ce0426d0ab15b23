// The control service's JSON (actors/control_json.hpp): reply lines, the
// request fields it reads, and HERM's tables and counters under the field
// names of the control protocol (docs/protocol.md, "Control requests").

#include "actors/control_json.hpp"
#include "actors/control_topics.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

#include "caf/sec.hpp"

#include "actors/runtime/error.hpp"
#include "routing/error.hpp"
#include "routing/metric.hpp"

using namespace herm;
using namespace herm::control_json;

namespace {

/// The keys of object `j`, sorted.
std::set<std::string> keys(const json& j) {
  std::set<std::string> out;
  for (auto& [k, v] : j.items())
    out.insert(k);
  return out;
}

} // namespace

// -- replies ---------------------------------------------------------------------------

TEST(control_json_reply, ok_reply_is_one_compact_line_with_the_result) {
  EXPECT_EQ(ok_reply(json{{"name", "alpha"}, {"id", 48}}),
            R"({"ok":true,"result":{"id":48,"name":"alpha"}})");
  EXPECT_EQ(ok_reply(nullptr), R"({"ok":true,"result":null})");
  EXPECT_EQ(ok_reply(json::array({1, 2})), R"({"ok":true,"result":[1,2]})");
}

TEST(control_json_reply, error_reply_carries_code_and_message) {
  EXPECT_EQ(error_reply("invalid_parameter", "bad \"count\""),
            R"({"error":{"code":"invalid_parameter","message":"bad \"count\""},"ok":false})");
}

TEST(control_json_reply, dump_replaces_invalid_utf8_instead_of_throwing) {
  std::string bad = "a\xff" "b";
  EXPECT_EQ(dump(json{{"name", bad}}), "{\"name\":\"a\xEF\xBF\xBD" "b\"}");
  EXPECT_EQ(error_reply("x", bad),
            "{\"error\":{\"code\":\"x\",\"message\":\"a\xEF\xBF\xBD"
            "b\"},\"ok\":false}");
}

TEST(control_json_reply, errors_map_to_protocol_codes_and_sentences) {
  struct row {
    caf::error err;
    std::string code;
    std::string message;
  };
  std::vector<row> cases{
    {make_error(routing_ec::no_route, "no route to 0x32"), "no_route",
     "no route to 0x32"},
    {make_error(app_ec::not_found, "unknown module 0x99"), "not_found",
     "unknown module 0x99"},
    {make_error(ec::timeout, "no reply in 5000 ms"), "timeout",
     "no reply in 5000 ms"},
    {caf::make_error(caf::sec::request_timeout), "timeout",
     "no response in time"},
    {caf::make_error(caf::sec::request_receiver_down), "unavailable",
     "a core actor of this module (IO manager, routing agent or application "
     "support) has stopped"},
  };
  for (auto& c : cases) {
    auto reply = json::parse(error_reply(c.err));
    EXPECT_EQ(reply["ok"], false);
    EXPECT_EQ(reply["error"]["code"], c.code) << c.message;
    EXPECT_EQ(reply["error"]["message"], c.message) << c.code;
  }
}

// A user never sees CAF's system.* codes: each is one of HERM's
// (typed_error), the message saying what CAF said where nothing better is
// known.
TEST(control_json_reply, other_caf_errors_are_hermes_typed_errors) {
  EXPECT_EQ(error_reply(caf::make_error(caf::sec::unexpected_message)),
            R"({"error":{"code":"invalid_parameter",)"
            R"("message":"the receiver does not handle a message of this type"},"ok":false})");
  auto other = json::parse(error_reply(caf::make_error(caf::sec::invalid_argument)));
  EXPECT_EQ(other["error"]["code"], "unavailable");
  EXPECT_NE(other["error"]["message"].get<std::string>().find("invalid_argument"),
            std::string::npos)
    << other.dump();
}

TEST(control_json_reply, an_error_without_a_sentence_is_rendered) {
  EXPECT_EQ(error_reply(make_error(app_ec::apo_gone)),
            R"({"error":{"code":"apo_gone","message":"herm.apo_gone"},"ok":false})");
}

// -- request fields ----------------------------------------------------------------------

// Requests arrive as text, so their fields are parsed JSON: a non-negative
// integer is unsigned there, a negative one signed.

TEST(control_json_fields, module_field_takes_hex_decimal_text_and_numbers) {
  struct row {
    const char* v;
    std::optional<module_id> want;
  };
  std::vector<row> cases{
    {R"("0x4E")", module_id{0x4E}},
    {R"("0x4e")", module_id{0x4E}},
    {R"("78")", module_id{78}},
    {"78", module_id{78}},
    {"0", module_id{0}},
    {"65535", module_id{0xFFFF}},
    {"65536", std::nullopt},
    {"-1", std::nullopt},
    {"78.5", std::nullopt},
    {R"("zz")", std::nullopt},
    {R"("")", std::nullopt},
    {"true", std::nullopt},
    {"null", std::nullopt},
    {"[78]", std::nullopt},
  };
  for (auto& c : cases)
    EXPECT_EQ(module_field(json::parse(c.v)), c.want) << c.v;
}

TEST(control_json_fields, uint_field_is_fallback_when_absent_and_refuses_bad_values) {
  struct row {
    const char* req;
    std::optional<uint32_t> want;
  };
  // count in [1, 1000], default 1, as ping reads it.
  std::vector<row> cases{
    {"{}", 1u},
    {R"({"other": 7})", 1u},
    {R"({"count": 1})", 1u},
    {R"({"count": 3})", 3u},
    {R"({"count": 1000})", 1000u},
    {R"({"count": 0})", std::nullopt},
    {R"({"count": 1001})", std::nullopt},
    {R"({"count": -3})", std::nullopt},
    {R"({"count": 2.0})", std::nullopt},
    {R"({"count": "3"})", std::nullopt},
    {R"({"count": null})", std::nullopt},
    {R"({"count": true})", std::nullopt},
    {R"({"count": 1099511627776})", std::nullopt},
  };
  for (auto& c : cases)
    EXPECT_EQ(uint_field(json::parse(c.req), "count", 1, 1, 1000), c.want)
      << c.req;
}

TEST(control_json_fields, uint_field_range_reaches_uint32_max) {
  auto req = json::parse(R"({"timeout_ms": 4294967295})");
  EXPECT_EQ(uint_field(req, "timeout_ms", 5, 0, 0xFFFFFFFFu), 0xFFFFFFFFu);
  auto over = json::parse(R"({"timeout_ms": 4294967296})");
  EXPECT_EQ(uint_field(over, "timeout_ms", 5, 0, 0xFFFFFFFFu), std::nullopt);
}

TEST(control_json_fields, string_field_is_empty_when_absent_or_not_a_string) {
  struct row {
    json req;
    std::string want;
  };
  std::vector<row> cases{
    {{{"device", "eth0"}}, "eth0"},
    {{{"device", ""}}, ""},
    {json::object(), ""},
    {{{"device", 3}}, ""},
    {{{"device", nullptr}}, ""},
    {{{"device", json::array({"eth0"})}}, ""},
  };
  for (auto& c : cases)
    EXPECT_EQ(string_field(c.req, "device"), c.want) << c.req.dump();
}

// -- HERM's types ------------------------------------------------------------------------

TEST(control_json_types, an_infinite_cost_is_null) {
  EXPECT_EQ(cost_json(0), json(0));
  EXPECT_EQ(cost_json(20), json(20));
  EXPECT_EQ(cost_json(infinite_metric - 1), json(infinite_metric - 1));
  EXPECT_EQ(cost_json(infinite_metric), json(nullptr));
  EXPECT_EQ(cost_json(uint64_t{1} << 40), json(nullptr));
}

TEST(control_json_types, link_profile_carries_its_cost_or_null_without_bandwidth) {
  link_profile p{"ethernet", 100'000'000, 1500, true, 1.0, 0};
  EXPECT_EQ(dump(to_json(p)),
            R"({"bandwidth_bps":100000000,"cost":10,"delay_coef":1.0,)"
            R"("mtu":1500,"multi_access":true,"name":"ethernet"})");
  p.bandwidth_bps = 0;
  EXPECT_EQ(to_json(p)["cost"], json(nullptr));
}

TEST(control_json_types, a_route_row_is_completed_from_its_neighbour) {
  route_info r{0x32, 0, 1, "2", 20, 2, "Ethernet-Ethernet", true, true};
  std::vector<neighbour_info> ns{
    {2, "2", 0x40, 7, "CAN2.0", {30, 240, 3840, 245760}, 5, false},
    {1, "2", 0x31, 1234, "Ethernet", {10, 10, 10, infinite_metric}, 83, false},
  };
  EXPECT_EQ(dump(to_json(r, ns)),
            R"({"channel":1,"cost":20,"destination":"0x32","feasible":true,)"
            R"("forwarding":"Ethernet-Ethernet","hops":2,"link_cost":10,)"
            R"("link_kind":"Ethernet","neighbour":"2","neighbour_module":"0x31",)"
            R"("selected":true,"size_class":0,"size_class_bytes":8})");
  r.size_class = 3;
  r.cost = infinite_metric;
  auto j = to_json(r, ns);
  EXPECT_EQ(j["size_class_bytes"], 65536);
  EXPECT_EQ(j["link_cost"], json(nullptr));
  EXPECT_EQ(j["cost"], json(nullptr));
}

TEST(control_json_types, a_route_row_without_its_neighbour_has_nulls) {
  route_info r{0x32, 7, 9, "5", 20, 2, "", false, true};
  auto j = to_json(r, {});
  EXPECT_EQ(j["neighbour_module"], json(nullptr));
  EXPECT_EQ(j["link_kind"], json(nullptr));
  EXPECT_EQ(j["link_cost"], json(nullptr));
  // No such class: its size is unknown.
  EXPECT_EQ(j["size_class_bytes"], json(nullptr));
}

TEST(control_json_types, neighbours_and_apos_use_the_protocol_names) {
  neighbour_info n{2, "2", 0x31, 1234, "CAN2.0", {30, infinite_metric}, 83, true};
  EXPECT_EQ(dump(to_json(n)),
            R"({"channel":2,"cost":[30,null],"duplicate_id":true,"instance":1234,)"
            R"("last_heard_ms":83,"link_address":"2","link_kind":"CAN2.0","module":"0x31"})");
  apo_info a{{0x30, 3582914457u, "herm.control", "herm.control/1"}, true, 2, 0};
  EXPECT_EQ(dump(to_json(a)),
            R"({"age_ms":0,"apo":3582914457,"local":true,"module":"0x30",)"
            R"("name":"herm.control","type":"herm.control/1","watchers":2})");
  EXPECT_EQ(dump(rows_json(std::vector<apo_info>{})), "[]");
  EXPECT_EQ(rows_json(std::vector<apo_info>{a, a}).size(), 2u);
}

TEST(control_json_types, channel_counters_have_the_protocol_names) {
  channel_stats s;
  s.tx_packets = 1;
  s.rx_bytes = 2;
  s.rx_orphans = 3;
  s.tx_overload_control = 4;
  s.tx_overload_bulk = 5;
  s.backlog_limit_bytes = 1048576;
  auto j = to_json(s);
  EXPECT_EQ(keys(j), (std::set<std::string>{
                       "tx_packets", "tx_bytes", "tx_frames", "tx_dropped",
                       "rx_packets", "rx_bytes", "rx_frames", "rx_malformed",
                       "rx_reassembly_dropped", "rx_duplicates", "rx_orphans",
                       "rx_kernel_dropped", "rx_queue_dropped",
                       "rx_peers_unrecorded", "tx_overload", "backlog_bytes",
                       "backlog_peak_bytes", "backlog_limit_bytes",
                       "tx_bundles", "rx_bundles"}));
  EXPECT_EQ(j["tx_packets"], 1);
  EXPECT_EQ(j["rx_bytes"], 2);
  EXPECT_EQ(j["rx_orphans"], 3);
  EXPECT_EQ(j["backlog_limit_bytes"], 1048576);
  EXPECT_EQ(dump(j["tx_overload"]),
            R"({"bulk":5,"control":4,"high":0,"normal":0})");
}

TEST(control_json_types, routing_counters_have_the_protocol_names) {
  routing_stats s;
  s.self = 0x30;
  s.instance = 42;
  s.delivered = 16;
  auto j = to_json(s);
  EXPECT_EQ(keys(j).size(), 49u);
  for (auto k : {"self", "instance", "assigned", "reachable", "delivered",
                 "forwarded", "dropped_no_route", "rx_auth_failed",
                 "id_conflicts", "id_conflict", "destinations", "routes",
                 "neighbours", "floods_evicted", "sources_evicted", "fast_sent",
                 "fast_routes_refused", "fast_delivered", "fast_forwarded"})
    EXPECT_TRUE(j.contains(k)) << k;
  EXPECT_EQ(j["self"], "0x30");
  EXPECT_EQ(j["instance"], 42);
  EXPECT_EQ(j["delivered"], 16);
  EXPECT_EQ(j["id_conflict"], json(nullptr));
  s.id_conflict_instance = 9;
  s.id_conflict_heard = "channel 1 (eth0) from 2, hello";
  EXPECT_EQ(dump(to_json(s)["id_conflict"]),
            R"({"heard":"channel 1 (eth0) from 2, hello","instance":9})");
}

TEST(control_json_types, app_counters_have_the_protocol_names) {
  app_support_stats s;
  s.local_apos = 1;
  s.requests_sent = 14;
  s.reliable_waited = 2;
  auto j = to_json(s);
  EXPECT_EQ(keys(j).size(), 37u);
  for (auto k : {"local_apos", "known_remote_apos", "live_bindings",
                 "requests_sent", "request_timeouts", "rx_unauthorized",
                 "unexpected_messages", "reliable"})
    EXPECT_TRUE(j.contains(k)) << k;
  EXPECT_EQ(j["local_apos"], 1);
  EXPECT_EQ(j["requests_sent"], 14);
  EXPECT_EQ(keys(j["reliable"]),
            (std::set<std::string>{"sent", "retransmissions",
                                   "duplicates_suppressed", "acks_sent",
                                   "acks_received", "late_duplicates",
                                   "waited_for_route", "cached_responses"}));
  EXPECT_EQ(j["reliable"]["waited_for_route"], 2);
}

// -- topic lists ---------------------------------------------------------------------------

// topic list: one row per topic from every module's own rows, including
// the modules they heard of that did not answer (a board without herm.info).
TEST(control_topics_merge, modules_heard_of_are_listed_with_those_that_answered) {
  std::vector<json> per_module{
    {{"module", "0x40"},
     {"topics", json::array({{{"topic", "sonar"}, {"publishing", true},
                              {"seq", 4294967295u}, {"local_subscribers", 0},
                              {"remote_subscribers", json::array({"0x4E"})},
                              {"publishers", json::array()},
                              {"type", "herm.srf04_reading"}},
                             {{"topic", "cmd"}, {"publishing", false},
                              {"local_subscribers", 1},
                              {"remote_subscribers", json::array()},
                              {"publishers", json::array({"0xA04"})},
                              {"type", "@i32"}}})}},
    {{"module", "0x4E"},
     {"topics", json::array({{{"topic", "sonar"}, {"publishing", false},
                              {"local_subscribers", 2},
                              {"remote_subscribers", json::array()},
                              {"publishers", json::array({"0x40"})},
                              {"type", ""}}})}},
  };
  auto rows = herm::control_topics::merge_topics(per_module);
  ASSERT_EQ(rows.size(), 2u) << rows.dump();
  // In topic order.
  EXPECT_EQ(rows[0]["topic"], "cmd");
  EXPECT_EQ(rows[0]["publishers"], json::array({"0xA04"})); // the board: heard of
  EXPECT_EQ(rows[0]["subscribers"], json::array({"0x40"}));
  EXPECT_EQ(rows[0]["type"], "@i32");
  EXPECT_EQ(rows[1]["topic"], "sonar");
  EXPECT_EQ(rows[1]["publishers"], json::array({"0x40"}));
  EXPECT_EQ(rows[1]["subscribers"], json::array({"0x4E"}));
  EXPECT_EQ(rows[1]["type"], "herm.srf04_reading");
  // Sequence numbers of the publishers that answered, for publish rates.
  EXPECT_EQ(rows[1]["seqs"], json({{"0x40", 4294967295u}}));
  EXPECT_EQ(rows[0]["seqs"], json::object());
}

// Rows come from other modules' open herm.info: rows of the wrong shape are
// passed over, never thrown on (an exception would end the control
// service, and hermd with it).
TEST(control_topics_merge, rows_of_the_wrong_shape_are_passed_over) {
  std::vector<json> per_module{
    {{"module", "0x40"},
     {"topics", json::array({5, "x", json::object(),
                             {{"topic", 7}},
                             {{"topic", "b"}, {"publishing", true}, {"seq", -3}},
                             {{"topic", "a"}, {"publishing", "yes"}, {"seq", 5},
                              {"local_subscribers", -1},
                              {"publishers", "0x41"},
                              {"remote_subscribers", json::array({1, "0x42"})},
                              {"type", 3}},
                             {{"topic", "b"}}})}},
    {{"module", 17}, {"topics", "none"}},
    json::array(),
    {{"module", "0x43"}},
  };
  json rows;
  ASSERT_NO_THROW(rows = herm::control_topics::merge_topics(per_module));
  ASSERT_EQ(rows.size(), 2u) << rows.dump();
  EXPECT_EQ(rows[0]["topic"], "a");
  EXPECT_TRUE(rows[0]["publishers"].empty());
  EXPECT_EQ(rows[0]["subscribers"], json::array({"0x42"}));
  EXPECT_EQ(rows[0]["type"], "");
  EXPECT_EQ(rows[1]["topic"], "b");
  EXPECT_EQ(rows[1]["publishers"], json::array({"0x40"}));
  EXPECT_EQ(rows[1]["seqs"], json::object());  // a negative seq is no seq
}

TEST(control_json_reply, only_an_object_with_ok_true_is_an_ok_reply) {
  EXPECT_TRUE(is_ok_reply(json::parse(R"({"ok":true,"result":1})")));
  for (auto text : {R"({"ok":false})", R"({"ok":"yes"})", R"({"ok":1})", "5",
                    R"(["ok"])", R"({})", "null"})
    EXPECT_FALSE(is_ok_reply(json::parse(text))) << text;
  EXPECT_FALSE(is_ok_reply(json::parse("{", nullptr, false))); // discarded
}
