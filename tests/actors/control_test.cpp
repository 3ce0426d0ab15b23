// The control service, its socket and hermctl, on three real modules in one
// process (CAF's real scheduler, in-process links with Table 1 profiles):
//
//   alpha 0x30 ==eth0 (Ethernet, 10)== bravo 0x31 --eth1 (Ethernet)-- charlie 0x32
//              --can0 (CAN2.0, 30)---
//
// bravo is a router module. Every reply's shape, forwarding through bravo,
// typed errors, taking links down and up, the socket's rules, and hermctl's
// tables, JSON and exit statuses (run as a child process). Every wait is
// bounded; nothing asserts on timing.

#include <gtest/gtest.h>

#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <thread>

#include <nlohmann/json.hpp>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/control.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm;
using herm::test::temp_dir;
using namespace std::chrono_literals;
using json = nlohmann::json;

namespace {

const std::string hermctl_bin = HERM_HERMCTL_BIN;


/// Polls `pred` every 50 ms for at most `timeout`.
template <class Pred>
bool eventually(Pred pred, std::chrono::milliseconds timeout = 15s) {
  auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (pred())
      return true;
    if (std::chrono::steady_clock::now() >= deadline)
      return false;
    std::this_thread::sleep_for(50ms);
  }
}

/// The selected class-0 route to `dst` among `routes`, or null.
json selected_route(const json& routes, const std::string& dst) {
  if (!routes.is_array())
    return nullptr;
  for (auto& r : routes)
    if (r["destination"] == dst && r["selected"] == true && r["size_class"] == 0)
      return r;
  return nullptr;
}

/// Sends raw bytes to a socket and reads until EOF, `lines` reply lines or
/// `timeout`.
std::string raw_exchange(const std::string& path, const std::string& bytes,
                         bool shut_write, std::chrono::milliseconds timeout,
                         size_t lines = 1000) {
  int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return "connect failed";
  }
  size_t done = 0;
  while (done < bytes.size()) {
    auto n = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n <= 0)
      break; // the server may close early (overlong line)
    done += static_cast<size_t>(n);
  }
  if (shut_write)
    ::shutdown(fd, SHUT_WR);
  timeval tv{static_cast<time_t>(timeout.count() / 1000),
             static_cast<suseconds_t>(timeout.count() % 1000 * 1000)};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  std::string out;
  char buf[4096];
  for (;;) {
    auto n = ::recv(fd, buf, sizeof(buf), 0);
    if (n <= 0)
      break;
    out.append(buf, static_cast<size_t>(n));
    if (static_cast<size_t>(std::count(out.begin(), out.end(), '\n')) >= lines)
      break;
  }
  ::close(fd);
  return out;
}

/// A hermctl run: exit status and everything it printed (stdout and
/// stderr).
struct run_result {
  int status;
  std::string output;
};

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s)
    out += c == '\'' ? std::string{"'\\''"} : std::string(1, c);
  return out + "'";
}

/// Runs hermctl with `args` (and `env` assignments first), stderr merged
/// into stdout, at most 60 s.
run_result hermctl(const std::vector<std::string>& args,
                   const std::string& env = "") {
  // Forwarded requests wait for discoveries and bindings: under sanitizers
  // on a loaded machine the default 5 s can pass. A test that wants a
  // timeout says so with its own --timeout.
  auto full = args;
  if (args.size() >= 2 && args[0] == "-s"
      && std::find(args.begin(), args.end(), "--timeout") == args.end())
    full.insert(full.begin() + 2, {"--timeout", "30000"});
  std::string cmd = env + " " + shell_quote(hermctl_bin);
  for (auto& a : full)
    cmd += " " + shell_quote(a);
  cmd += " 2>&1";
  herm::test::child_process p{{"/bin/sh", "-c", cmd}};
  auto status = p.wait(60s);
  return {status, p.output()};
}

// -- the three modules -----------------------------------------------------------------

class control_test : public ::testing::Test {
protected:
  void SetUp() override {
    ASSERT_FALSE(dir.path().empty());
    configure(cfg);
    sys.emplace(cfg);
    auto prefix = "ctl" + std::to_string(::getpid()) + "-";
    auto dev = [&](std::string name, std::string seg, std::string profile) {
      return device_config{std::move(name), "inproc", prefix + seg,
                           {{"profile", std::move(profile)}}};
    };
    alpha = start(0x30, {dev("eth0", "ab-eth", "ethernet"),
                         dev("can0", "ab-can", "can2.0")});
    bravo = start(0x31, {dev("eth0", "ab-eth", "ethernet"),
                         dev("can0", "ab-can", "can2.0"),
                         dev("eth1", "bc-eth", "ethernet")});
    charlie = start(0x32, {dev("eth0", "bc-eth", "ethernet")});
    ASSERT_TRUE(alpha && bravo && charlie);
    ctl_alpha = spawn_control(*sys, *alpha, "alpha");
    ctl_bravo = spawn_control(*sys, *bravo, "bravo");
    ctl_charlie = spawn_control(*sys, *charlie, "charlie");
    socket = dir.path() + "/alpha.sock";
    local_commands locals;
    locals["reload"] = [this](const std::string& req) {
      ++reloads;
      return json{{"ok", true}, {"result", {{"request", req}}}}.dump();
    };
    auto srv = control_server::start(*sys, ctl_alpha, socket, std::move(locals));
    ASSERT_TRUE(srv) << render(srv.error());
    server = std::move(*srv);
  }

  void TearDown() override {
    server.reset();
    for (auto* c : {&ctl_alpha, &ctl_bravo, &ctl_charlie})
      if (*c)
        caf::anon_send_exit(*c, caf::exit_reason::user_shutdown);
    for (auto* m : {&alpha, &bravo, &charlie})
      if (*m)
        stop_module(**m);
  }

  std::optional<module_handles> start(module_id id,
                                      std::vector<device_config> devices) {
    module_config mc;
    mc.routing.id = id;
    mc.routing.hello_interval = 100ms;
    mc.devices = std::move(devices);
    // Remote control needs a keyed network (or, without a key, a module
    // that allows unsigned remote control).
    if (keyed)
      mc.routing.auth.key = std::vector<uint8_t>(32, 0x5A);
    mc.apps.allow_unsigned_remote = allow_unsigned.count(id) != 0;
    auto m = start_module(*sys, mc);
    if (!m) {
      ADD_FAILURE() << render(m.error());
      return std::nullopt;
    }
    return *m;
  }

  /// One request through alpha's socket; the parsed reply.
  json call(const json& req) {
    auto text = req.dump();
    auto reply = control_call(socket, text, control_deadline(text) + 2s);
    if (!reply) {
      ADD_FAILURE() << render(reply.error());
      return nullptr;
    }
    auto j = json::parse(*reply, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << *reply;
    return j;
  }

  /// The result of a request that must succeed.
  json result(const json& req) {
    auto j = call(req);
    EXPECT_EQ(j.value("ok", false), true) << req.dump() << " -> " << j.dump();
    return j.value("result", json{});
  }

  /// The error code of a request that must fail.
  std::string error_code(const json& req) {
    auto j = call(req);
    EXPECT_EQ(j.value("ok", true), false) << req.dump() << " -> " << j.dump();
    return j["error"].value("code", std::string{});
  }

  /// True once alpha has a selected route to `dst` (whose cost is `cost`,
  /// if given).
  bool alpha_routes_to(const std::string& dst, std::optional<int> cost = {}) {
    auto r = selected_route(call({{"cmd", "routes"}})["result"], dst);
    return !r.is_null() && (!cost || r["cost"] == *cost);
  }

  /// Waits until every module reaches every other and every control
  /// service answers through alpha.
  void converge() {
    ASSERT_TRUE(eventually([&] {
      return alpha_routes_to("0x31", 10) && alpha_routes_to("0x32", 20);
    })) << call({{"cmd", "routes"}}).dump();
    ASSERT_TRUE(eventually([&] {
      auto j = call({{"cmd", "echo"}, {"module", "0x32"}});
      return j.value("ok", false);
    })) << call({{"cmd", "echo"}, {"module", "0x32"}}).dump();
  }

  /// Set in a derived fixture's constructor: whether the three modules
  /// share a key, and which of them allow unsigned remote control (by
  /// default no key, and all three allow it: control.allow_unsigned_remote).
  bool keyed = false;
  std::set<module_id> allow_unsigned{0x30, 0x31, 0x32};
  temp_dir dir;
  caf::actor_system_config cfg;
  std::optional<caf::actor_system> sys;
  std::optional<module_handles> alpha, bravo, charlie;
  control_actor ctl_alpha, ctl_bravo, ctl_charlie;
  std::string socket;
  std::unique_ptr<control_server> server;
  std::atomic<int> reloads{0};
};

// -- every command's reply --------------------------------------------------------------

TEST_F(control_test, info_names_the_module_and_summarises_its_state) {
  converge();
  auto r = result({{"cmd", "info"}});
  EXPECT_EQ(r["name"], "alpha");
  EXPECT_EQ(r["module"], "0x30");
  EXPECT_EQ(r["id"], 0x30);
  EXPECT_TRUE(r["instance"].is_number());
  EXPECT_TRUE(r["uptime_ms"].is_number());
  EXPECT_EQ(r["reachable"], 2);
  EXPECT_EQ(r["neighbours"], 2);
  EXPECT_EQ(r["channels"]["up"], 2);
  EXPECT_EQ(r["channels"]["total"], 2);
  EXPECT_EQ(r["registered"], "yes");
  EXPECT_GE(r["apps"]["local"].get<int>(), 1);
  EXPECT_TRUE(r["apps"]["known_remote"].is_number());
  EXPECT_TRUE(r["apps"]["bindings"].is_number());
}

TEST_F(control_test, channels_lists_the_channel_table_with_profiles_and_counters) {
  converge();
  auto rows = result({{"cmd", "channels"}});
  ASSERT_TRUE(rows.is_array());
  ASSERT_EQ(rows.size(), 2u) << rows.dump();
  std::map<std::string, json> by_device;
  for (auto& row : rows)
    by_device[row["device"]] = row;
  ASSERT_EQ(by_device.count("eth0"), 1u);
  ASSERT_EQ(by_device.count("can0"), 1u);
  auto& eth = by_device["eth0"];
  EXPECT_EQ(eth["state"], "up");
  EXPECT_EQ(eth["kind"], "inproc");
  EXPECT_EQ(eth["address"], "*");
  EXPECT_EQ(eth["persistent"], true);
  EXPECT_EQ(eth["profile"]["name"], "ethernet");
  EXPECT_EQ(eth["profile"]["bandwidth_bps"], 100000000);
  EXPECT_EQ(eth["profile"]["mtu"], 1500);
  EXPECT_EQ(eth["profile"]["cost"], 10);
  auto& can = by_device["can0"];
  EXPECT_EQ(can["profile"]["name"], "can2.0");
  EXPECT_EQ(can["profile"]["mtu"], 8);
  EXPECT_EQ(can["profile"]["cost"], 30);
  for (auto& row : rows) {
    ASSERT_TRUE(row["stats"].is_object()) << row.dump();
    for (auto key : {"tx_packets", "tx_bytes", "tx_frames", "tx_dropped",
                     "rx_packets", "rx_bytes", "rx_frames", "rx_malformed",
                     "rx_reassembly_dropped", "rx_duplicates"})
      EXPECT_TRUE(row["stats"][key].is_number()) << key;
    // Hellos went out and came in on both links.
    EXPECT_GT(row["stats"]["tx_packets"].get<uint64_t>(), 0u);
    EXPECT_GT(row["stats"]["rx_packets"].get<uint64_t>(), 0u);
  }
}

TEST_F(control_test, routes_have_the_papers_columns) {
  converge();
  auto routes = result({{"cmd", "routes"}});
  auto r = selected_route(routes, "0x32");
  ASSERT_FALSE(r.is_null()) << routes.dump();
  auto eth = result({{"cmd", "channels"}});
  json eth_id;
  for (auto& ch : eth)
    if (ch["device"] == "eth0")
      eth_id = ch["id"];
  EXPECT_EQ(r["size_class"], 0);
  EXPECT_EQ(r["size_class_bytes"], 8);
  EXPECT_EQ(r["channel"], eth_id);
  EXPECT_TRUE(r["neighbour"].is_string());
  EXPECT_EQ(r["neighbour_module"], "0x31");
  EXPECT_EQ(r["link_kind"], "Ethernet");
  EXPECT_EQ(r["link_cost"], 10);
  EXPECT_EQ(r["cost"], 20);
  EXPECT_EQ(r["hops"], 2);
  EXPECT_EQ(r["forwarding"], "Ethernet-Ethernet");
  EXPECT_EQ(r["feasible"], true);
  // Every class has rows, and the CAN link appears as an unselected route.
  std::set<int> classes;
  bool can_alternative = false;
  for (auto& row : routes) {
    classes.insert(row["size_class"].get<int>());
    if (row["destination"] == "0x31" && row["link_kind"] == "CAN2.0"
        && row["size_class"] == 0) {
      can_alternative = true;
      EXPECT_EQ(row["selected"], false);
      EXPECT_EQ(row["cost"], 30);
    }
  }
  EXPECT_EQ(classes, (std::set<int>{0, 1, 2, 3}));
  EXPECT_TRUE(can_alternative) << routes.dump();
  // "all": false keeps the selected routes of class 0 only.
  auto selected = result({{"cmd", "routes"}, {"all", false}});
  ASSERT_EQ(selected.size(), 2u) << selected.dump();
  for (auto& row : selected) {
    EXPECT_EQ(row["selected"], true);
    EXPECT_EQ(row["size_class"], 0);
  }
}

TEST_F(control_test, neighbors_apps_stats_and_echo_have_their_shapes) {
  converge();
  auto ns = result({{"cmd", "neighbors"}});
  ASSERT_EQ(ns.size(), 2u) << ns.dump();
  std::set<std::string> kinds;
  for (auto& n : ns) {
    EXPECT_EQ(n["module"], "0x31");
    kinds.insert(n["link_kind"]);
    EXPECT_TRUE(n["channel"].is_number());
    EXPECT_TRUE(n["link_address"].is_string());
    EXPECT_TRUE(n["instance"].is_number());
    EXPECT_EQ(n["cost"].size(), 4u);
    EXPECT_TRUE(n["last_heard_ms"].is_number());
  }
  EXPECT_EQ(kinds, (std::set<std::string>{"Ethernet", "CAN2.0"}));
  EXPECT_EQ(result({{"cmd", "neighbours"}}).size(), 2u);

  auto apps = result({{"cmd", "apps"}});
  bool own = false;
  for (auto& a : apps)
    if (a["module"] == "0x30" && a["name"] == control_apo_name
        && a["type"] == control_apo_type && a["local"] == true)
      own = true;
  EXPECT_TRUE(own) << apps.dump();

  auto stats = result({{"cmd", "stats"}});
  EXPECT_EQ(stats["routing"]["self"], "0x30");
  EXPECT_GT(stats["routing"]["tx_hellos"].get<uint64_t>(), 0u);
  EXPECT_TRUE(stats["apps"]["registered"].is_number());
  ASSERT_EQ(stats["channels"].size(), 2u);
  for (auto& ch : stats["channels"]) {
    EXPECT_TRUE(ch["device"].is_string());
    EXPECT_TRUE(ch["tx_packets"].is_number()) << ch.dump();
  }
  for (auto& [k, v] : stats["routing"].items()) {
    if (k != "self" && k != "assigned" && k != "id_conflict") {
      EXPECT_TRUE(v.is_number()) << k;
    }
  }

  auto echo = result({{"cmd", "echo"}});
  EXPECT_EQ(echo["module"], "0x30");
  EXPECT_EQ(echo["id"], 0x30);
  EXPECT_EQ(echo["name"], "alpha");
}

// apps lists what this module knows; apps with "all" asks the network
// first, so a remote APO never looked up before is listed with its module.
TEST_F(control_test, apps_all_asks_the_network_for_every_apo) {
  converge();
  // An APO on charlie (two hops away) that nobody has looked up.
  auto apo = sys->spawn([]() -> caf::behavior {
    return {[](int32_t x) { return x; }};
  });
  caf::scoped_actor self{*sys};
  self->request(charlie->apps, 5s, atom::add_v, std::string{"lidar"},
                std::string{"scan"}, caf::actor_cast<caf::actor>(apo))
    .receive([](apo_ref&) {},
             [](caf::error& err) { FAIL() << render(err); });
  auto lidar = [](const json& rows) {
    for (auto& a : rows)
      if (a["module"] == "0x32" && a["name"] == "lidar" && a["type"] == "scan"
          && a["local"] == false)
        return true;
    return false;
  };
  auto before = result({{"cmd", "apps"}});
  EXPECT_FALSE(lidar(before)) << before.dump();
  auto all = result({{"cmd", "apps"}, {"all", true}});
  EXPECT_TRUE(lidar(all)) << all.dump();
  // A non-boolean "all" is the plain table.
  EXPECT_TRUE(result({{"cmd", "apps"}, {"all", "yes"}}).is_array());
  caf::anon_send_exit(apo, caf::exit_reason::user_shutdown);
}

// Answers over slow or busy links may need more than the default 500 ms:
// "wait_ms" sets how long they are collected, and the caller's deadline
// grows with it.
TEST_F(control_test, apps_all_waits_as_long_as_asked) {
  converge();
  auto t0 = std::chrono::steady_clock::now();
  auto all = result({{"cmd", "apps"}, {"all", true}, {"wait_ms", 1500}});
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 1500ms);
  EXPECT_TRUE(all.is_array()) << all.dump();
  auto with = control_deadline(R"({"cmd":"apps","all":true,"wait_ms":20000})");
  auto without = control_deadline(R"({"cmd":"apps","all":true})");
  EXPECT_EQ(with - without, 20000ms);
  EXPECT_EQ(error_code({{"cmd", "apps"}, {"all", true}, {"wait_ms", 0}}),
            "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "apps"}, {"all", true}, {"wait_ms", 60001}}),
            "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "apps"}, {"all", true}, {"wait_ms", "long"}}),
            "invalid_parameter");
}

TEST_F(control_test, the_service_answers_actors_directly_too) {
  caf::scoped_actor self{*sys};
  std::string reply;
  self->request(ctl_bravo, 10s, std::string{R"({"cmd":"echo"})"})
    .receive([&](std::string& r) { reply = r; },
             [&](caf::error& e) { FAIL() << render(e); });
  auto j = json::parse(reply);
  EXPECT_EQ(j["result"]["module"], "0x31");
  EXPECT_EQ(j["result"]["name"], "bravo");
}

// -- forwarding --------------------------------------------------------------------------

TEST_F(control_test, forwards_requests_through_a_router_module) {
  converge();
  auto info = result({{"cmd", "info"}, {"module", "0x32"}});
  EXPECT_EQ(info["name"], "charlie");
  EXPECT_EQ(info["module"], "0x32");
  // Decimal text and numbers name modules too.
  EXPECT_EQ(result({{"cmd", "echo"}, {"module", "50"}})["name"], "charlie");
  EXPECT_EQ(result({{"cmd", "echo"}, {"module", 49}})["name"], "bravo");
  // Our own id is answered here.
  EXPECT_EQ(result({{"cmd", "echo"}, {"module", "0x30"}})["name"], "alpha");
  // The router's view: charlie one hop away over its own Ethernet.
  auto r = selected_route(result({{"cmd", "routes"}, {"module", "0x31"}}),
                          "0x32");
  ASSERT_FALSE(r.is_null());
  EXPECT_EQ(r["hops"], 1);
  EXPECT_EQ(r["cost"], 10);
  auto ns = result({{"cmd", "neighbors"}, {"module", "0x32"}});
  ASSERT_EQ(ns.size(), 1u);
  EXPECT_EQ(ns[0]["module"], "0x31");
  // A second request reuses the cached proxy.
  EXPECT_EQ(result({{"cmd", "info"}, {"module", "0x32"}})["name"], "charlie");
  // Forwarded errors come back as they are.
  EXPECT_EQ(error_code({{"cmd", "nope"}, {"module", "0x32"}}), "unknown_command");
}

/// The same modules without a key: charlie allows unsigned remote control
/// (control.allow_unsigned_remote), bravo does not.
class control_keyless_test : public control_test {
protected:
  control_keyless_test() {
    keyed = false;
    allow_unsigned = {0x32};
  }
};

TEST_F(control_keyless_test, a_module_without_a_key_refuses_remote_control_unless_allowed) {
  converge(); // echo through alpha to charlie works: charlie allows it
  EXPECT_EQ(result({{"cmd", "info"}, {"module", "0x32"}})["name"], "charlie");
  // bravo refuses every remote command with a typed error, at once (no
  // timeout), and counts it; its links stay as they were.
  auto j = call({{"cmd", "link"}, {"module", "0x31"}, {"device", "eth0"},
                 {"state", "down"}});
  ASSERT_FALSE(j.value("ok", true)) << j.dump();
  EXPECT_EQ(j["error"]["code"], "unauthorized") << j.dump();
  EXPECT_NE(j["error"]["message"].get<std::string>().find("0x31"),
            std::string::npos);
  EXPECT_EQ(error_code({{"cmd", "echo"}, {"module", "0x31"}}), "unauthorized");
  caf::scoped_actor self{*sys};
  app_support_stats st;
  self->request(bravo->apps, 5s, atom::get_v, atom::stats_v)
    .receive([&](app_support_stats& x) { st = x; },
             [](caf::error& err) { FAIL() << render(err); });
  EXPECT_GE(st.rx_unauthorized, 2u);
  EXPECT_EQ(result({{"cmd", "channels"}, {"module", "0x32"}}).size(), 1u);
  // Local control of bravo (its own service) still works.
  self->request(ctl_bravo, 5s, std::string{R"({"cmd":"echo"})"})
    .receive([](std::string& reply) {
               EXPECT_NE(reply.find("\"ok\":true"), std::string::npos) << reply;
             },
             [](caf::error& err) { FAIL() << render(err); });
  // hermctl shows the refusal as one line with its code.
  auto r = hermctl({"-s", socket, "--module", "0x31", "info"});
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("unauthorized"), std::string::npos) << r.output;
}

/// The same modules with a network key (auth.data: discovery, the
/// default): remote control travels signed and is served.
class control_keyed_test : public control_test {
protected:
  control_keyed_test() {
    keyed = true;
    allow_unsigned.clear();
  }
};

TEST_F(control_keyed_test, remote_control_travels_signed_through_a_router) {
  converge();
  EXPECT_EQ(result({{"cmd", "info"}, {"module", "0x32"}})["name"], "charlie");
  EXPECT_EQ(result({{"cmd", "echo"}, {"module", "0x31"}})["name"], "bravo");
  auto st = result({{"cmd", "stats"}, {"module", "0x32"}});
  EXPECT_EQ(st["apps"]["rx_unauthorized"], 0) << st.dump();
  EXPECT_GT(st["routing"]["tx_signed"].get<uint64_t>(), 0u) << st.dump();
}

TEST_F(control_test, ping_measures_round_trips_to_a_remote_module) {
  converge();
  auto r = result({{"cmd", "ping"}, {"module", "0x32"}, {"count", 3}});
  EXPECT_EQ(r["module"], "0x32");
  EXPECT_EQ(r["count"], 3);
  EXPECT_EQ(r["received"], 3);
  EXPECT_EQ(r["lost"], 0);
  ASSERT_EQ(r["rtt_us"].size(), 3u);
  EXPECT_LE(r["min_us"].get<uint64_t>(), r["avg_us"].get<uint64_t>());
  EXPECT_LE(r["avg_us"].get<uint64_t>(), r["max_us"].get<uint64_t>());
  // Pinging ourselves works as well.
  EXPECT_EQ(result({{"cmd", "ping"}, {"module", "0x30"}})["received"], 1);
}

// -- errors -------------------------------------------------------------------------------

TEST_F(control_test, errors_are_typed) {
  converge();
  EXPECT_EQ(error_code({{"cmd", "fly"}}), "unknown_command");
  EXPECT_EQ(error_code({{"nocmd", 1}}), "invalid_request");
  EXPECT_EQ(error_code({{"cmd", 42}}), "invalid_request");
  EXPECT_EQ(error_code(json::array({1, 2})), "invalid_request");
  EXPECT_EQ(error_code({{"cmd", "info"}, {"module", "zz"}}), "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "info"}, {"module", "0xFFFF"}}),
            "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "info"}, {"timeout_ms", -1}}),
            "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "ping"}}), "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "ping"}, {"module", "0x31"}, {"count", 0}}),
            "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "link"}, {"device", "eth0"}}),
            "invalid_parameter");
  EXPECT_EQ(error_code({{"cmd", "link"}, {"device", "fw9"}, {"state", "down"}}),
            "unknown_device");
  // A module nobody knows: a typed error naming it.
  auto j = call({{"cmd", "info"}, {"module", "0x99"}, {"timeout_ms", 1000}});
  EXPECT_EQ(j["ok"], false);
  EXPECT_EQ(j["error"]["code"], "not_found");
  EXPECT_NE(j["error"]["message"].get<std::string>().find("unknown module 0x99"),
            std::string::npos)
    << j.dump();
  // Pinging it too.
  EXPECT_EQ(error_code({{"cmd", "ping"}, {"module", "0x99"}, {"timeout_ms", 500}}),
            "not_found");
}

TEST_F(control_test, bad_input_on_the_socket_gets_an_error_reply_never_a_crash) {
  // Not JSON.
  auto out = raw_exchange(socket, "{\"cmd\": \"info\"\n", false, 5s, 1);
  auto j = json::parse(out.substr(0, out.find('\n')), nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << out;
  EXPECT_EQ(j["error"]["code"], "invalid_request");
  // Binary garbage, then a good request on the same connection.
  out = raw_exchange(socket,
                     std::string("\x00\xff\xfe garbage\n", 12)
                       + "{\"cmd\":\"echo\"}\n",
                     true, 5s);
  auto nl = out.find('\n');
  ASSERT_NE(nl, std::string::npos) << out;
  EXPECT_EQ(json::parse(out.substr(0, nl))["error"]["code"], "invalid_request");
  auto second = json::parse(out.substr(nl + 1, out.find('\n', nl + 1) - nl - 1),
                            nullptr, false);
  EXPECT_EQ(second["result"]["name"], "alpha") << out;
  // A last request without its newline is still answered.
  out = raw_exchange(socket, "{\"cmd\":\"echo\"}", true, 5s);
  EXPECT_NE(out.find("\"alpha\""), std::string::npos) << out;
  // An overlong line: an error reply, then the connection closes.
  out = raw_exchange(socket, std::string(100 * 1024, 'x'), false, 5s);
  j = json::parse(out.substr(0, out.find('\n')), nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << out.substr(0, 200);
  EXPECT_EQ(j["error"]["code"], "invalid_request");
  EXPECT_NE(j["error"]["message"].get<std::string>().find("longer than"),
            std::string::npos);
  // Still serving.
  EXPECT_EQ(result({{"cmd", "echo"}})["name"], "alpha");
}

TEST_F(control_test, no_module_listening_is_a_clear_error) {
  auto path = dir.path() + "/nobody.sock";
  auto reply = control_call(path, R"({"cmd":"info"})", 2s);
  ASSERT_FALSE(reply);
  EXPECT_TRUE(is(reply.error(), app_ec::not_found)) << render(reply.error());
  auto text = render(reply.error());
  EXPECT_NE(text.find(path), std::string::npos) << text;
  EXPECT_NE(text.find("hermd"), std::string::npos) << text;
  // The server removes its socket when it stops; then nobody listens.
  server.reset();
  EXPECT_FALSE(std::filesystem::exists(socket));
  reply = control_call(socket, R"({"cmd":"info"})", 2s);
  ASSERT_FALSE(reply);
  EXPECT_TRUE(is(reply.error(), app_ec::not_found));
}

// -- the socket -------------------------------------------------------------------------

TEST_F(control_test, the_socket_is_private_exclusive_and_replaces_stale_files) {
  struct stat sb;
  ASSERT_EQ(::stat(socket.c_str(), &sb), 0);
  EXPECT_TRUE(S_ISSOCK(sb.st_mode));
  EXPECT_EQ(sb.st_mode & 0777, 0600u);
  // A live socket is not taken over.
  auto second = control_server::start(*sys, ctl_bravo, socket);
  ASSERT_FALSE(second);
  EXPECT_TRUE(is(second.error(), ec::already_exists)) << render(second.error());
  // The parent directory is created private when missing.
  auto nested = dir.path() + "/run/herm/bravo.sock";
  auto srv = control_server::start(*sys, ctl_bravo, nested);
  ASSERT_TRUE(srv) << render(srv.error());
  ASSERT_EQ(::stat((dir.path() + "/run/herm").c_str(), &sb), 0);
  EXPECT_EQ(sb.st_mode & 0777, 0700u);
  EXPECT_EQ((*srv)->path(), nested);
  auto reply = control_call(nested, R"({"cmd":"echo"})", 10s);
  ASSERT_TRUE(reply) << render(reply.error());
  EXPECT_EQ(json::parse(*reply)["result"]["name"], "bravo");
  srv->reset();
  // A stale socket file (nobody listening) is replaced.
  auto stale = dir.path() + "/stale.sock";
  {
    int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, stale.c_str(), sizeof(addr.sun_path) - 1);
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ::close(fd);
  }
  auto replaced = control_server::start(*sys, ctl_charlie, stale);
  ASSERT_TRUE(replaced) << render(replaced.error());
  reply = control_call(stale, R"({"cmd":"echo"})", 10s);
  ASSERT_TRUE(reply);
  EXPECT_EQ(json::parse(*reply)["result"]["name"], "charlie");
  // A file that is not a socket is never removed.
  auto plain = dir.path() + "/plain.sock";
  std::ofstream{plain} << "keep me";
  auto refused = control_server::start(*sys, ctl_charlie, plain);
  ASSERT_FALSE(refused);
  EXPECT_TRUE(std::filesystem::exists(plain));
  // A path too long for a Unix socket.
  EXPECT_FALSE(control_server::start(*sys, ctl_charlie,
                                     dir.path() + "/" + std::string(200, 'x')));
}

TEST_F(control_test, local_commands_run_on_the_server_and_clients_take_turns) {
  auto j = call({{"cmd", "reload"}});
  EXPECT_EQ(j["ok"], true);
  EXPECT_EQ(reloads.load(), 1);
  EXPECT_NE(j["result"]["request"].get<std::string>().find("reload"),
            std::string::npos);
  // Several clients one after another, several requests per connection.
  for (int i = 0; i < 5; ++i)
    EXPECT_EQ(result({{"cmd", "echo"}})["module"], "0x30");
  auto out = raw_exchange(socket,
                          "{\"cmd\":\"echo\"}\n\n{\"cmd\":\"reload\"}\n",
                          true, 5s);
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 2) << out;
  EXPECT_EQ(reloads.load(), 2);
}

/// A control service that takes requests and never answers them.
control_actor spawn_silent_service(caf::actor_system& sys,
                                   std::shared_ptr<std::atomic<int>> received) {
  return sys.spawn(
    [received](control_actor::pointer self) -> control_actor::behavior_type {
      using promise = caf::typed_response_promise<std::string>;
      auto kept = std::make_shared<std::vector<promise>>();
      return {
        [self, received, kept](std::string&) -> caf::result<std::string> {
          ++*received;
          kept->push_back(self->make_response_promise<std::string>());
          return kept->back();
        },
        [self, received, kept](herm::atom::subscribe, std::string&,
                               caf::actor&) -> caf::result<std::string> {
          ++*received;
          kept->push_back(self->make_response_promise<std::string>());
          return kept->back();
        },
      };
    });
}

// Charlie's control service replaced by one that never answers: a
// forwarded request ends with a typed timeout.
TEST_F(control_test, a_module_that_does_not_answer_in_time_is_a_typed_timeout) {
  converge();
  caf::anon_send_exit(ctl_charlie, caf::exit_reason::user_shutdown);
  ctl_charlie = nullptr;
  auto silent
    = spawn_silent_service(*sys, std::make_shared<std::atomic<int>>(0));
  caf::scoped_actor self{*sys};
  self->request(charlie->apps, 10s, atom::add_v, std::string{control_apo_name},
                std::string{control_apo_type}, caf::actor_cast<caf::actor>(silent))
    .receive([](apo_ref&) {}, [](caf::error& e) { FAIL() << render(e); });
  // Until alpha drops its binding to the old service, other errors come.
  json last;
  EXPECT_TRUE(eventually([&] {
    last = call({{"cmd", "echo"}, {"module", "0x32"}, {"timeout_ms", 300}});
    return last["error"].value("code", std::string{}) == "timeout";
  })) << last.dump();
  EXPECT_NE(last["error"]["message"].get<std::string>(), "");
  caf::anon_send_exit(silent, caf::exit_reason::user_shutdown);
}

// A service that never answers: stopping the server does not wait for it,
// and the waiting client gets an error reply.
TEST_F(control_test, stopping_the_server_abandons_a_request_in_progress) {
  auto received = std::make_shared<std::atomic<int>>(0);
  auto silent = spawn_silent_service(*sys, received);
  auto path = dir.path() + "/silent.sock";
  auto srv = control_server::start(*sys, silent, path);
  ASSERT_TRUE(srv) << render(srv.error());
  caf::expected<std::string> reply{std::string{}};
  std::thread client{[&] {
    reply = control_call(path, R"({"cmd":"info","timeout_ms":600000})", 60s);
  }};
  EXPECT_TRUE(eventually([&] { return received->load() > 0; }));
  srv->reset();
  client.join();
  ASSERT_TRUE(reply) << render(reply.error());
  auto j = json::parse(*reply, nullptr, false);
  EXPECT_EQ(j["error"]["code"], "unavailable") << *reply;
  caf::anon_send_exit(silent, caf::exit_reason::user_shutdown);
}

// -- taking links down --------------------------------------------------------------------

TEST_F(control_test, link_down_moves_routes_and_withdraws_them_link_up_restores) {
  converge();
  // On another module, through the socket: bravo's CAN side goes down and
  // comes back.
  auto r = result({{"cmd", "link"}, {"module", "0x31"}, {"device", "can0"},
                   {"state", "down"}});
  EXPECT_EQ(r["state"], "down");
  EXPECT_EQ(r["closed"].size(), 1u);
  EXPECT_TRUE(result({{"cmd", "channels"}, {"module", "0x31"}}).size() == 2u);
  r = result({{"cmd", "link"}, {"module", "0x31"}, {"device", "can0"},
              {"state", "up"}});
  EXPECT_EQ(r["opened"], true);
  EXPECT_EQ(result({{"cmd", "channels"}, {"module", "0x31"}}).size(), 3u);
  converge();
  ASSERT_TRUE(eventually([&] {
    auto ns = result({{"cmd", "neighbors"}});
    return ns.size() == 2u;
  }));

  // Alpha's Ethernet down: traffic moves to CAN (30, then 30 + 10).
  r = result({{"cmd", "link"}, {"device", "eth0"}, {"state", "down"}});
  EXPECT_EQ(r["device"], "eth0");
  EXPECT_EQ(r["state"], "down");
  ASSERT_EQ(r["closed"].size(), 1u);
  EXPECT_TRUE(eventually([&] { return alpha_routes_to("0x31", 30); }))
    << call({{"cmd", "routes"}}).dump();
  EXPECT_TRUE(eventually([&] { return alpha_routes_to("0x32", 40); }))
    << call({{"cmd", "routes"}}).dump();
  auto via_can = selected_route(result({{"cmd", "routes"}}), "0x32");
  EXPECT_EQ(via_can["forwarding"], "CAN2.0-Ethernet");
  EXPECT_EQ(via_can["link_kind"], "CAN2.0");
  // Again: already down, nothing to close.
  EXPECT_EQ(result({{"cmd", "link"}, {"device", "eth0"}, {"state", "down"}})
              ["closed"].size(),
            0u);

  // CAN down too: no route is left.
  result({{"cmd", "link"}, {"device", "can0"}, {"state", "down"}});
  EXPECT_TRUE(eventually([&] {
    return !alpha_routes_to("0x31") && !alpha_routes_to("0x32");
  })) << call({{"cmd", "routes"}}).dump();
  EXPECT_EQ(result({{"cmd", "channels"}}).size(), 0u);
  // A module we know of but cannot reach: a typed no_route.
  auto j = call({{"cmd", "echo"}, {"module", "0x32"}, {"timeout_ms", 1000}});
  EXPECT_EQ(j["ok"], false) << j.dump();
  EXPECT_EQ(j["error"]["code"], "no_route") << j.dump();
  j = call({{"cmd", "ping"}, {"module", "0x31"}, {"count", 2},
            {"timeout_ms", 1000}});
  EXPECT_EQ(j["error"]["code"], "no_route") << j.dump();

  // Ethernet up again: the routes come back.
  r = result({{"cmd", "link"}, {"device", "eth0"}, {"state", "up"}});
  EXPECT_EQ(r["opened"], true);
  ASSERT_EQ(r["channels"].size(), 1u);
  EXPECT_TRUE(eventually([&] { return alpha_routes_to("0x32", 20); }))
    << call({{"cmd", "routes"}}).dump();
  r = result({{"cmd", "link"}, {"device", "eth0"}, {"state", "up"}});
  EXPECT_EQ(r["opened"], false);
}

// -- hermctl -------------------------------------------------------------------------------

TEST_F(control_test, hermctl_prints_tables_for_people) {
  converge();
  auto info = hermctl({"-s", socket, "info"});
  EXPECT_EQ(info.status, 0) << info.output;
  EXPECT_NE(info.output.find("alpha (0x30)"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("2 modules reachable"), std::string::npos)
    << info.output;

  auto routes = hermctl({"-s", socket, "routes"});
  EXPECT_EQ(routes.status, 0) << routes.output;
  for (auto s : {"DESTINATION", "NEXT CHANNEL", "NEIGHBOUR", "COST", "HOPS",
                 "FORWARDING", "0x31", "0x32", "Ethernet-Ethernet"})
    EXPECT_NE(routes.output.find(s), std::string::npos) << s << "\n"
                                                        << routes.output;
  EXPECT_EQ(routes.output.find("CAN2.0"), std::string::npos) << routes.output;
  auto all = hermctl({"-s", socket, "routes", "--all"});
  EXPECT_EQ(all.status, 0) << all.output;
  for (auto s : {"CLASS", "SELECTED", "FEASIBLE", "CAN2.0", "65536 B"})
    EXPECT_NE(all.output.find(s), std::string::npos) << s << "\n" << all.output;

  auto channels = hermctl({"-s", socket, "channels"});
  EXPECT_EQ(channels.status, 0) << channels.output;
  for (auto s : {"DEVICE", "TX PKTS", "RX BYTES", "eth0", "can0", "can2.0",
                 "1 Mbit/s", "100 Mbit/s"})
    EXPECT_NE(channels.output.find(s), std::string::npos) << s << "\n"
                                                          << channels.output;

  auto ns = hermctl({"-s", socket, "neighbors"});
  EXPECT_EQ(ns.status, 0) << ns.output;
  EXPECT_NE(ns.output.find("CAN2.0"), std::string::npos) << ns.output;
  auto apps = hermctl({"-s", socket, "apps"});
  EXPECT_EQ(apps.status, 0) << apps.output;
  EXPECT_NE(apps.output.find("herm.control"), std::string::npos) << apps.output;
  auto stats = hermctl({"-s", socket, "stats"});
  EXPECT_EQ(stats.status, 0) << stats.output;
  EXPECT_NE(stats.output.find("tx_hellos"), std::string::npos) << stats.output;
  EXPECT_NE(stats.output.find("channel "), std::string::npos) << stats.output;

  auto remote = hermctl({"-s", socket, "--module", "0x32", "info"});
  EXPECT_EQ(remote.status, 0) << remote.output;
  EXPECT_NE(remote.output.find("charlie (0x32)"), std::string::npos)
    << remote.output;

  auto ping = hermctl({"-s", socket, "ping", "0x32", "-c", "2"});
  EXPECT_EQ(ping.status, 0) << ping.output;
  EXPECT_NE(ping.output.find("2 sent, 2 received, 0 lost"), std::string::npos)
    << ping.output;

  auto trace = hermctl({"-s", socket, "trace", "0x32"});
  EXPECT_EQ(trace.status, 0) << trace.output;
  EXPECT_NE(trace.output.find("2 hops"), std::string::npos) << trace.output;
  for (auto s : {"0x30", "0x31", "0x32", "bravo", "charlie", "Ethernet", "20"})
    EXPECT_NE(trace.output.find(s), std::string::npos) << s << "\n"
                                                       << trace.output;

  auto topo = hermctl({"-s", socket, "topology"});
  EXPECT_EQ(topo.status, 0) << topo.output;
  EXPECT_NE(topo.output.find("graph herm {"), std::string::npos) << topo.output;
  EXPECT_NE(topo.output.find("\"0x30\" -- \"0x31\" [label=\"Ethernet 10\"]"),
            std::string::npos)
    << topo.output;
  EXPECT_NE(topo.output.find("\"0x30\" -- \"0x31\" [label=\"CAN2.0 30\"]"),
            std::string::npos)
    << topo.output;
  EXPECT_NE(topo.output.find("\"0x31\" -- \"0x32\" [label=\"Ethernet 10\"]"),
            std::string::npos)
    << topo.output;
  EXPECT_NE(topo.output.find("0x32\\ncharlie"), std::string::npos)
    << topo.output;
  // The built-in APOs (herm.control, herm.info) every module has are not
  // drawn.
  EXPECT_EQ(topo.output.find("herm."), std::string::npos) << topo.output;
  auto dot_file = dir.path() + "/topo.dot";
  auto svg_file = dir.path() + "/topo.svg";
  auto files = hermctl({"-s", socket, "topology", "--dot", dot_file, "--svg",
                        svg_file},
                       "PATH=/usr/bin:/bin");
  if (::access("/usr/bin/dot", X_OK) == 0) {
    EXPECT_EQ(files.status, 0) << files.output;
    std::ifstream svg{svg_file};
    std::string content{std::istreambuf_iterator<char>{svg}, {}};
    EXPECT_NE(content.find("<svg"), std::string::npos);
  } else {
    EXPECT_EQ(files.status, 1) << files.output;
    EXPECT_NE(files.output.find("graphviz"), std::string::npos) << files.output;
  }
  EXPECT_TRUE(std::filesystem::exists(dot_file));
  // Without graphviz on PATH: a clear message.
  auto no_dot = hermctl({"-s", socket, "topology", "--png",
                         dir.path() + "/t.png"},
                        "PATH=/nonexistent");
  EXPECT_EQ(no_dot.status, 1) << no_dot.output;
  EXPECT_NE(no_dot.output.find("not on PATH"), std::string::npos)
    << no_dot.output;

  auto link = hermctl({"-s", socket, "link", "can0", "down"});
  EXPECT_EQ(link.status, 0) << link.output;
  EXPECT_NE(link.output.find("can0: down (closed channel"), std::string::npos)
    << link.output;
  link = hermctl({"-s", socket, "link", "can0", "up"});
  EXPECT_EQ(link.status, 0) << link.output;
  EXPECT_NE(link.output.find("can0: up (opened channel"), std::string::npos)
    << link.output;

  auto reload = hermctl({"-s", socket, "reload"});
  EXPECT_EQ(reload.status, 0) << reload.output;
  EXPECT_NE(reload.output.find("reloaded"), std::string::npos) << reload.output;
  EXPECT_EQ(reloads.load(), 1);
}

TEST_F(control_test, hermctl_prints_json_for_scripts) {
  converge();
  auto routes = hermctl({"-s", socket, "--json", "routes"});
  ASSERT_EQ(routes.status, 0) << routes.output;
  auto j = json::parse(routes.output, nullptr, false);
  ASSERT_TRUE(j.is_array()) << routes.output;
  EXPECT_EQ(j.size(), 2u) << routes.output; // selected, class 0: 0x31, 0x32
  EXPECT_FALSE(selected_route(j, "0x32").is_null());
  // Options after the subcommand, and the socket from HERM_CONTROL.
  auto info = hermctl({"info", "--json"}, "HERM_CONTROL=" + shell_quote(socket));
  ASSERT_EQ(info.status, 0) << info.output;
  EXPECT_EQ(json::parse(info.output)["name"], "alpha");
  for (auto cmd : {"channels", "neighbors", "apps", "stats"}) {
    auto out = hermctl({"-s", socket, "--json", cmd});
    ASSERT_EQ(out.status, 0) << cmd << "\n" << out.output;
    EXPECT_FALSE(json::parse(out.output, nullptr, false).is_discarded())
      << cmd << "\n" << out.output;
  }
  auto ping = hermctl({"-s", socket, "--json", "ping", "0x31", "-c", "2"});
  ASSERT_EQ(ping.status, 0) << ping.output;
  EXPECT_EQ(json::parse(ping.output)["received"], 2);
  auto trace = hermctl({"-s", socket, "--json", "trace", "0x32"});
  ASSERT_EQ(trace.status, 0) << trace.output;
  auto hops = json::parse(trace.output);
  ASSERT_EQ(hops.size(), 3u) << trace.output;
  EXPECT_EQ(hops[2]["module"], "0x32");
  EXPECT_EQ(hops[2]["cost"], 20);
  EXPECT_EQ(hops[1]["link_kind"], "Ethernet");
  auto topo = hermctl({"-s", socket, "--json", "topology"});
  ASSERT_EQ(topo.status, 0) << topo.output;
  auto g = json::parse(topo.output);
  EXPECT_EQ(g["nodes"].size(), 3u) << topo.output;
  EXPECT_EQ(g["edges"].size(), 3u) << topo.output;
  for (auto& e : g["edges"]) {
    EXPECT_TRUE(e["cost"].is_number()) << e.dump();
  }
  // The default socket of --name, when not running as root.
  if (::geteuid() != 0) {
    auto xdg = dir.path() + "/xdg";
    auto srv = control_server::start(*sys, ctl_bravo, xdg + "/herm/bravo.sock");
    ASSERT_TRUE(srv) << render(srv.error());
    auto named = hermctl({"--name", "bravo", "--json", "info"},
                         "XDG_RUNTIME_DIR=" + shell_quote(xdg));
    ASSERT_EQ(named.status, 0) << named.output;
    EXPECT_EQ(json::parse(named.output)["name"], "bravo");
  }
}

TEST_F(control_test, hermctl_errors_are_one_line_and_exit_non_zero) {
  converge();
  auto nobody = dir.path() + "/nobody.sock";
  auto r = hermctl({"-s", nobody, "info"});
  EXPECT_EQ(r.status, 3) << r.output;
  EXPECT_NE(r.output.find("no module listening at " + nobody), std::string::npos)
    << r.output;
  EXPECT_NE(r.output.find("hermd"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;

  r = hermctl({"-s", socket, "--module", "0x99", "--timeout", "1000", "info"});
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("hermctl: unknown module 0x99"), std::string::npos)
    << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;

  r = hermctl({"-s", socket, "--timeout", "1000", "ping", "0x99"});
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("unknown module 0x99"), std::string::npos) << r.output;

  r = hermctl({"-s", socket, "ping", "zz"});
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("'zz' is not a module id"), std::string::npos)
    << r.output;
  r = hermctl({"-s", socket, "link", "eth0", "sideways"});
  EXPECT_EQ(r.status, 2) << r.output;
  r = hermctl({"-s", socket, "link", "fw9", "down"});
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("no device named 'fw9'"), std::string::npos)
    << r.output;
  r = hermctl({"-s", socket, "frobnicate"});
  EXPECT_EQ(r.status, 2) << r.output;
  r = hermctl({"-s", socket, "--module", "0x31", "trace", "0x32"});
  EXPECT_EQ(r.status, 2) << r.output;

  // No route: alpha's links down, then a trace has nowhere to go.
  result({{"cmd", "link"}, {"device", "eth0"}, {"state", "down"}});
  result({{"cmd", "link"}, {"device", "can0"}, {"state", "down"}});
  ASSERT_TRUE(eventually([&] { return !alpha_routes_to("0x32"); }));
  r = hermctl({"-s", socket, "trace", "0x32"});
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("no route from 0x30 to 0x32"), std::string::npos)
    << r.output;
}

TEST(hermctl, profiles_and_cost_match_table_1) {
  const std::map<std::string, int> table1{
    {"usb1.1", 19}, {"usb2.0", 3},  {"ieee1394a", 4}, {"ieee1394b", 1},
    {"can2.0", 30}, {"ethernet", 10}, {"rs232c", 47}};
  auto r = hermctl({"profiles", "--json"});
  ASSERT_EQ(r.status, 0) << r.output;
  auto profiles = json::parse(r.output);
  ASSERT_EQ(profiles.size(), table1.size());
  for (auto& p : profiles) {
    auto name = p["name"].get<std::string>();
    ASSERT_EQ(table1.count(name), 1u) << name;
    EXPECT_EQ(p["cost"], table1.at(name)) << name;
    // cost --bandwidth gives the same figure.
    auto c = hermctl({"cost", "--json", "--bandwidth",
                      std::to_string(p["bandwidth_bps"].get<uint64_t>())});
    ASSERT_EQ(c.status, 0) << c.output;
    EXPECT_EQ(json::parse(c.output)["link_cost"], table1.at(name)) << name;
  }
  auto table = hermctl({"profiles"});
  ASSERT_EQ(table.status, 0) << table.output;
  for (auto s : {"NAME", "BANDWIDTH", "MTU", "COST", "can2.0", "1 Mbit/s",
                 "rs232c", "19.2 kbit/s", "47"})
    EXPECT_NE(table.output.find(s), std::string::npos) << s << "\n"
                                                       << table.output;
  // Formula (1): a 1,000-byte message over CAN is 125 frames of cost 30,
  // over RS232C 32 frames of 47 (1,504).
  auto can = hermctl({"cost", "--json", "--bandwidth", "1M", "--mtu", "8",
                      "--size", "1000"});
  ASSERT_EQ(can.status, 0) << can.output;
  auto cj = json::parse(can.output);
  EXPECT_EQ(cj["link_cost"], 30);
  EXPECT_EQ(cj["frames"], 125);
  EXPECT_EQ(cj["message_cost"], 3750);
  EXPECT_EQ(cj["class_costs"], json::array({30, 240, 3840, 245760}));
  auto serial = hermctl({"cost", "--bandwidth", "19.2k", "--mtu", "32",
                         "--size", "1000"});
  ASSERT_EQ(serial.status, 0) << serial.output;
  EXPECT_NE(serial.output.find("link cost     47"), std::string::npos)
    << serial.output;
  EXPECT_NE(serial.output.find("32 frames"), std::string::npos) << serial.output;
  EXPECT_NE(serial.output.find("message cost  1504"), std::string::npos)
    << serial.output;
  // The delay coefficient scales the cost.
  auto coef = hermctl({"cost", "--json", "--bandwidth", "100M", "--coef", "2"});
  ASSERT_EQ(coef.status, 0) << coef.output;
  EXPECT_EQ(json::parse(coef.output)["link_cost"], 20);
  // Bad input is a usage error.
  EXPECT_EQ(hermctl({"cost", "--bandwidth", "fast"}).status, 2);
  EXPECT_EQ(hermctl({"cost", "--bandwidth", "1M", "--size", "10"}).status, 2);
  EXPECT_EQ(hermctl({"cost"}).status, 2);
}

} // namespace

// -- the socket under load: slow, many and over-long clients ----------------------------

namespace {

/// A raw client connection to `path`; -1 if it cannot connect.
int connect_raw(const std::string& path) {
  int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return -1;
  }
  timeval tv{10, 0}; // bounds every read below
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  return fd;
}

bool send_text(int fd, const std::string& text) {
  return ::send(fd, text.data(), text.size(), MSG_NOSIGNAL)
         == static_cast<ssize_t>(text.size());
}

/// Reads one reply line (at most 10 s); empty at EOF or timeout.
std::string read_line(int fd) {
  std::string out;
  char c;
  while (::recv(fd, &c, 1, 0) == 1) {
    if (c == '\n')
      return out;
    out += c;
  }
  return out;
}

} // namespace

// One client sending its request a byte every 300 ms used to hold the only
// server thread: every other hermctl waited. Now they are answered
// meanwhile, and the slow request too once complete.
TEST_F(control_test, a_slow_client_does_not_hold_up_other_clients) {
  int slow = connect_raw(socket);
  ASSERT_GE(slow, 0);
  const std::string request = "{\"cmd\":\"echo\"}\n";
  for (size_t i = 0; i + 1 < request.size(); ++i) {
    ASSERT_TRUE(send_text(slow, request.substr(i, 1)));
    if (i % 4 == 0) {
      auto reply = control_call(socket, R"({"cmd":"echo"})", 5s);
      ASSERT_TRUE(reply) << "while a client trickles: " << render(reply.error());
      EXPECT_NE(reply->find("\"alpha\""), std::string::npos) << *reply;
    }
    if (i == 6) {
      auto run = hermctl({"-s", socket, "--timeout", "5000", "info"});
      EXPECT_EQ(run.status, 0) << run.output;
    }
    std::this_thread::sleep_for(300ms);
  }
  ASSERT_TRUE(send_text(slow, "\n"));
  auto reply = json::parse(read_line(slow), nullptr, false);
  ::close(slow);
  ASSERT_FALSE(reply.is_discarded());
  EXPECT_EQ(reply["result"]["name"], "alpha") << reply.dump();
}

// A client still trickling its line 10 s after its first byte is cut off
// with a timeout reply, and counted.
TEST_F(control_test, a_request_line_not_complete_within_the_line_deadline_is_cut_off) {
  int slow = connect_raw(socket);
  ASSERT_GE(slow, 0);
  const std::string request = "{\"cmd\":\"echo\",\"pad\":\"" + std::string(100, 'x');
  std::string got;
  auto deadline = std::chrono::steady_clock::now() + 20s;
  size_t i = 0;
  while (got.empty() && std::chrono::steady_clock::now() < deadline) {
    send_text(slow, request.substr(i++ % request.size(), 1));
    pollfd p{slow, POLLIN, 0};
    if (::poll(&p, 1, 500) > 0)
      got = read_line(slow);
  }
  ::close(slow);
  auto j = json::parse(got, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << got;
  EXPECT_EQ(j["error"]["code"], "timeout") << got;
  auto counters = result({{"cmd", "stats"}})["control_socket"];
  EXPECT_EQ(counters["clients_timed_out"], 1) << counters.dump();
}

// 16 clients at once are served; one more gets a "busy" reply at once; a
// freed slot serves again.
TEST_F(control_test, clients_beyond_the_bound_get_a_busy_reply_and_a_freed_slot_serves_again) {
  std::vector<int> held;
  for (int i = 0; i < 16; ++i) {
    int fd = connect_raw(socket);
    ASSERT_GE(fd, 0);
    held.push_back(fd);
    // Served (not just queued): each gets its answer.
    ASSERT_TRUE(send_text(fd, "{\"cmd\":\"echo\"}\n"));
    EXPECT_NE(read_line(fd).find("\"alpha\""), std::string::npos) << i;
  }
  auto out = raw_exchange(socket, "{\"cmd\":\"echo\"}\n", false, 5s, 1);
  auto j = json::parse(out.substr(0, out.find('\n')), nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << out;
  EXPECT_EQ(j["error"]["code"], "busy") << out;
  EXPECT_NE(j["error"]["message"].get<std::string>().find("16"),
            std::string::npos)
    << out;
  // The held clients are still served.
  ASSERT_TRUE(send_text(held[3], "{\"cmd\":\"echo\"}\n"));
  EXPECT_NE(read_line(held[3]).find("\"alpha\""), std::string::npos);
  ::close(held.back());
  held.pop_back();
  ASSERT_TRUE(eventually([&] {
    auto reply = control_call(socket, R"({"cmd":"echo"})", 5s);
    return reply && reply->find("\"alpha\"") != std::string::npos;
  }));
  for (auto fd : held)
    ::close(fd);
  ASSERT_TRUE(eventually([&] {
    auto c = result({{"cmd", "stats"}})["control_socket"];
    return c["clients"] == 1; // the stats request's own
  }));
  auto c = result({{"cmd", "stats"}})["control_socket"];
  EXPECT_GE(c["clients_refused"].get<int>(), 1) << c.dump();
  EXPECT_EQ(c["max_clients"], 16) << c.dump();
}

// hermctl writes its whole request before it reads: an over-long line used
// to be closed on while it was still writing (a reset, "cannot send the
// request"). Now it reads the documented invalid_request reply.
TEST_F(control_test, an_over_long_request_gets_the_invalid_request_reply_not_a_reset) {
  auto big = R"({"cmd":"echo","pad":")" + std::string(300 * 1024, 'x') + R"("})";
  auto reply = control_call(socket, big, 10s);
  ASSERT_TRUE(reply) << render(reply.error());
  auto j = json::parse(*reply, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << reply->substr(0, 200);
  EXPECT_EQ(j["error"]["code"], "invalid_request");
  EXPECT_NE(j["error"]["message"].get<std::string>().find("65536"),
            std::string::npos)
    << *reply;
  // Through hermctl as a user would meet it: one line, exit non-zero.
  auto run = hermctl({"-s", socket, "--timeout", "5000", "link",
                      std::string(100 * 1024, 'd'), "down"});
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find("longer than 65536 bytes"), std::string::npos)
    << run.output.substr(0, 300);
  auto counters = result({{"cmd", "stats"}})["control_socket"];
  EXPECT_GE(counters["lines_too_long"].get<int>(), 1) << counters.dump();
  EXPECT_EQ(result({{"cmd", "echo"}})["name"], "alpha");
}
