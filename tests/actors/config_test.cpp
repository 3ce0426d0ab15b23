// The module configuration file (actors/config.hpp): a full file round-trips
// into the structs hermd starts from, defaults fill what is left out, and
// every mistake is refused with the file, the 1-based line and the field
// named and what was expected said.

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "actors/config.hpp"
#include "actors/runtime/error.hpp"
#include "channels/link_driver.hpp"
#include "channels/link_profile.hpp"
#include "tests/support/process.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

// -- helpers ---------------------------------------------------------------------

/// Joins lines with "\n", so that a case's line numbers can be counted:
/// element i is line i + 1.
std::string lines(std::initializer_list<const char*> xs) {
  std::string out;
  for (auto x : xs) {
    out += x;
    out += '\n';
  }
  return out;
}

/// The context string of a config error ("robot.yaml:3: module.id: ...").
std::string context_of(const caf::error& err) {
  auto& ctx = err.context();
  if (ctx.match_elements<std::string>())
    return ctx.get_as<std::string>(0);
  return render(err);
}

/// Parses `text` as robot.yaml, expecting success.
file_config parse_ok(const std::string& text) {
  auto cfg = parse_config(text, "robot.yaml");
  if (!cfg) {
    ADD_FAILURE() << "unexpected error: " << render(cfg.error());
    return {};
  }
  return std::move(*cfg);
}

/// Parses `text` as robot.yaml, expecting an invalid_config error; returns
/// its context.
std::string parse_error(const std::string& text) {
  auto cfg = parse_config(text, "robot.yaml");
  if (cfg) {
    ADD_FAILURE() << "parsed, but expected an error";
    return {};
  }
  EXPECT_TRUE(is(cfg.error(), ec::invalid_config)) << render(cfg.error());
  return context_of(cfg.error());
}

/// A file in a fresh temporary directory, removed with it.
struct temp_dir {
  std::string path;

  temp_dir() {
    char tmpl[] = "/tmp/herm-config-test-XXXXXX";
    auto* p = ::mkdtemp(tmpl);
    EXPECT_NE(p, nullptr);
    path = p != nullptr ? p : "/tmp";
  }

  ~temp_dir() {
    std::string cmd = "rm -rf '" + path + "'";
    if (std::system(cmd.c_str()) != 0)
      std::fprintf(stderr, "cannot remove %s\n", path.c_str());
  }

  std::string write(const std::string& name, const std::string& text) const {
    auto file = path + "/" + name;
    std::ofstream out{file};
    out << text;
    return file;
  }
};

/// Sets (or unsets, for nullptr) an environment variable for one scope.
struct scoped_env {
  std::string name;
  bool had = false;
  std::string old;

  scoped_env(const char* var, const char* value) : name(var) {
    if (auto* x = std::getenv(var)) {
      had = true;
      old = x;
    }
    if (value != nullptr)
      ::setenv(var, value, 1);
    else
      ::unsetenv(var);
  }

  ~scoped_env() {
    if (had)
      ::setenv(name.c_str(), old.c_str(), 1);
    else
      ::unsetenv(name.c_str());
  }
};

const char* full_config = R"(# A main controller with two links and one APO.
module:
  name: main-controller
  id: 0x4E
  hello_interval_ms: 500
  hello_loss: 2.5
  update_every: 3
  hold_factor: 4
  announce_every: 20
log: { level: debug, format: json }
scheduler: { policy: stealing, threads: 4, busy_poll_us: 50 }
control: { socket: /tmp/x/main.sock }
apps:
  tick_ms: 50
  idle_tick_ms: 700
  request_timeout_ms: 2000
  unreachable_grace_ms: 750
  rebind_interval_ms: 300
  watch_refresh_ms: 4000
  subscription_lease_ms: 6000
  remote_entry_ttl_ms: 30000
  max_pending: 100
channels:
  - name: eth0
    kind: udp
    interface: 127.0.0.1:47000
    profile: ethernet
    bandwidth: 100000000
    mtu: 1500
    delay_coef: 1.5
    peers: [127.0.0.1:47001, 127.0.0.1:47002]

  - name: can0
    kind: emu
    interface: /tmp/herm-media/can0
    profile: can2.0
    loss: 0.01
    broadcast: true
apos:
  - name: collector
    kind: collector
    type: herm.testbed.collector
    options: { period_ms: 300, sensors: [front, rear] }
  - name: batcher
    kind: srf04_batcher
)";

/// `text` without its quote markers ("// [name]" lines, which let
/// docs/user-guide.md quote it) and without the empty first line.
std::string unquoted(const std::string& text) {
  std::string out;
  size_t pos = text.empty() || text[0] != '\n' ? 0 : 1;
  while (pos < text.size()) {
    auto end = text.find('\n', pos);
    end = end == std::string::npos ? text.size() : end + 1;
    auto line = text.substr(pos, end - pos);
    if (line.rfind("// [", 0) != 0)
      out += line;
    pos = end;
  }
  return out;
}

// The complete example of the configuration reference (docs/user-guide.md),
// quoted from here.
const std::string documented_example = unquoted(R"(
// [config-example]
# robot.yaml: the main controller of a small robot.
module:
  name: main-controller
  id: main_controller            # the category's first id: 0x4E
  hello_interval_ms: 500
log: { level: info, format: text }
scheduler: { policy: sharing, threads: 2 }
control: { socket: /tmp/herm-example/main-controller.sock }
apps:
  request_timeout_ms: 5000
channels:
  - name: eth0                   # Ethernet: UDP, one peer on loopback
    kind: udp
    interface: 127.0.0.1:47000
    peers: [127.0.0.1:47001]
  - name: can0                   # CAN 2.0 at 1 Mbit/s, emulated bus
    kind: can
    interface: emu:/tmp/herm-example/can0
    node: 1
    bitrate: 1000000
  - name: fw0                    # IEEE 1394a, emulated medium
    kind: emu
    interface: /tmp/herm-example/fw0
    profile: ieee1394a
    loss: 0.001
apos:
  - name: collector              # receives what the other modules send
    kind: collector
  - name: camera                 # 100 bytes to 'collector' every second
    kind: vision_source
    type: herm.testbed.camera
    options: { period_ms: 1000, bytes: 100, target: collector }
// [config-example-end]
)");

// -- the documented example ------------------------------------------------------

TEST(config, reads_the_documented_example) {
  auto cfg = parse_ok(documented_example);
  EXPECT_EQ(cfg.name, "main-controller");
  EXPECT_EQ(cfg.module.routing.id, 0x4E);
  EXPECT_EQ(cfg.module.routing.hello_interval, 500ms);
  EXPECT_EQ(cfg.threads, 2u);
  EXPECT_EQ(cfg.control_socket, "/tmp/herm-example/main-controller.sock");
  EXPECT_EQ(cfg.module.apps.request_timeout, 5000ms);
  ASSERT_EQ(cfg.module.devices.size(), 3u);
  EXPECT_EQ(cfg.device_lines, (std::vector<int>{12, 16, 21}));
  auto& can = cfg.module.devices[1];
  EXPECT_EQ(can.kind, "can");
  EXPECT_EQ(can.interface, "emu:/tmp/herm-example/can0");
  option_map can_opts{{"node", "1"}, {"bitrate", "1000000"}};
  EXPECT_EQ(can.options, can_opts);
  ASSERT_EQ(cfg.apos.size(), 2u);
  EXPECT_EQ(cfg.apos[0].type, "herm.collector");
  EXPECT_EQ(cfg.apos[1].type, "herm.testbed.camera");
  EXPECT_EQ(cfg.apos[1].options.at("period_ms"), "1000");
  EXPECT_EQ(cfg.apos[1].options.size(), 3u);
}

TEST(config, the_documented_examples_channels_open_with_their_drivers) {
  // Every option of the example is one its link kind knows (drivers refuse
  // unknown ones). Interfaces move to a private directory and a free port.
  auto cfg = parse_ok(documented_example);
  temp_dir dir;
  for (auto dev : cfg.module.devices) {
    SCOPED_TRACE(dev.name);
    if (dev.kind == "udp")
      dev.interface = "127.0.0.1:0";
    else if (dev.kind == "can")
      dev.interface = "emu:" + dir.path + "/" + dev.name;
    else
      dev.interface = dir.path + "/" + dev.name;
    auto* kind = find_link_kind(dev.kind);
    ASSERT_NE(kind, nullptr);
    auto driver = kind->open(dev);
    EXPECT_TRUE(driver) << render(driver.error());
  }
}

// -- a full file -----------------------------------------------------------------

TEST(config, parses_every_section_of_a_full_file_into_the_structs) {
  auto cfg = parse_ok(full_config);
  EXPECT_EQ(cfg.path, "robot.yaml");
  EXPECT_EQ(cfg.name, "main-controller");
  auto& r = cfg.module.routing;
  EXPECT_EQ(r.id, 0x4E);
  EXPECT_EQ(r.hello_interval, 500ms);
  EXPECT_DOUBLE_EQ(r.hello_loss, 2.5);
  EXPECT_EQ(r.update_every, 3u);
  EXPECT_DOUBLE_EQ(r.hold_factor, 4.0);
  EXPECT_EQ(r.announce_every, 20u);
  EXPECT_EQ(cfg.log_level, "debug");
  EXPECT_EQ(cfg.log_format, "json");
  EXPECT_EQ(cfg.scheduler, "stealing");
  EXPECT_EQ(cfg.threads, 4u);
  EXPECT_EQ(cfg.busy_poll_us, 50u);
  EXPECT_EQ(cfg.control_socket, "/tmp/x/main.sock");
  auto& a = cfg.module.apps;
  EXPECT_EQ(a.tick, 50ms);
  EXPECT_EQ(a.idle_tick, 700ms);
  EXPECT_EQ(a.request_timeout, 2000ms);
  EXPECT_EQ(a.unreachable_grace, 750ms);
  EXPECT_EQ(a.rebind_interval, 300ms);
  EXPECT_EQ(a.watch_refresh, 4000ms);
  EXPECT_EQ(a.subscription_lease, 6000ms);
  EXPECT_EQ(a.remote_entry_ttl, 30000ms);
  EXPECT_EQ(a.max_pending, 100u);
}

TEST(config, turns_each_channel_into_a_device_with_options_as_text) {
  auto cfg = parse_ok(full_config);
  ASSERT_EQ(cfg.module.devices.size(), 2u);
  auto& eth = cfg.module.devices[0];
  EXPECT_EQ(eth.name, "eth0");
  EXPECT_EQ(eth.kind, "udp");
  EXPECT_EQ(eth.interface, "127.0.0.1:47000");
  option_map eth_opts{{"profile", "ethernet"},
                      {"bandwidth", "100000000"},
                      {"mtu", "1500"},
                      {"delay_coef", "1.5"},
                      {"peers", "127.0.0.1:47001,127.0.0.1:47002"}};
  EXPECT_EQ(eth.options, eth_opts);
  auto& can = cfg.module.devices[1];
  EXPECT_EQ(can.name, "can0");
  EXPECT_EQ(can.kind, "emu");
  EXPECT_EQ(can.interface, "/tmp/herm-media/can0");
  option_map can_opts{
    {"profile", "can2.0"}, {"loss", "0.01"}, {"broadcast", "true"}};
  EXPECT_EQ(can.options, can_opts);
}

TEST(config, records_the_line_of_every_channel_and_apo) {
  auto cfg = parse_ok(full_config);
  EXPECT_EQ(cfg.device_lines, (std::vector<int>{24, 33}));
  ASSERT_EQ(cfg.apos.size(), 2u);
  EXPECT_EQ(cfg.apos[0].line, 40);
  EXPECT_EQ(cfg.apos[1].line, 44);
}

TEST(config, reads_apos_with_their_type_and_options) {
  auto cfg = parse_ok(full_config);
  ASSERT_EQ(cfg.apos.size(), 2u);
  auto& col = cfg.apos[0];
  EXPECT_EQ(col.name, "collector");
  EXPECT_EQ(col.kind, "collector");
  EXPECT_EQ(col.type, "herm.testbed.collector");
  std::map<std::string, std::string> opts{{"period_ms", "300"},
                                          {"sensors", "front,rear"}};
  EXPECT_EQ(col.options, opts);
  auto& bat = cfg.apos[1];
  EXPECT_EQ(bat.name, "batcher");
  EXPECT_EQ(bat.type, "herm.srf04_batcher");
  EXPECT_TRUE(bat.options.empty());
}

// -- module ids ------------------------------------------------------------------

TEST(config, reads_module_ids_in_hex_decimal_by_category_or_dynamic) {
  struct row {
    const char* text;
    module_id want;
  };
  row rows[] = {
    {"0x4E", 0x4E},
    {"0X4e", 0x4E},
    {"78", 0x4E},
    {"0x0001", 0x0001},
    {"0xFFFE", 0xFFFE},
    {"65534", 0xFFFE},
    {"0x0100", 0x0100},
    {"main_controller", 0x4E},
    {"left_arm", 0x10},
    {"vision", 0x30},
    {"other", 0x80},
    {"dynamic", no_module},
    {"\"dynamic\"", no_module},
  };
  for (auto& x : rows) {
    SCOPED_TRACE(x.text);
    auto text = std::string{"module:\n  name: m\n  id: "} + x.text + "\n";
    EXPECT_EQ(parse_ok(text).module.routing.id, x.want);
  }
}

TEST(config, refuses_ids_a_module_cannot_hold) {
  for (auto bad : {"0", "0x0000", "0xFFFF", "65535", "0x10000", "-1", "4E",
                   "0x", "main", "Main_Controller", "[1]"}) {
    SCOPED_TRACE(bad);
    auto text = std::string{"module:\n  name: m\n  id: "} + bad + "\n";
    auto err = parse_error(text);
    EXPECT_EQ(err.rfind("robot.yaml:3: module.id: expected a module id "
                        "(0x0001..0xFFFE), \"dynamic\" or a category "
                        "(main_controller, left_arm, ",
                        0),
              0u)
      << err;
  }
}

// -- defaults --------------------------------------------------------------------

TEST(config, fills_everything_but_the_name_with_defaults) {
  auto cfg = parse_ok("module: { name: m }\n");
  EXPECT_EQ(cfg.name, "m");
  routing_config r0;
  auto& r = cfg.module.routing;
  EXPECT_EQ(r.id, no_module);
  EXPECT_EQ(r.hello_interval, r0.hello_interval);
  EXPECT_DOUBLE_EQ(r.hello_loss, r0.hello_loss);
  EXPECT_EQ(r.update_every, r0.update_every);
  EXPECT_DOUBLE_EQ(r.hold_factor, r0.hold_factor);
  EXPECT_EQ(r.announce_every, r0.announce_every);
  app_support_config a0;
  auto& a = cfg.module.apps;
  EXPECT_EQ(a.tick, a0.tick);
  EXPECT_EQ(a.request_timeout, a0.request_timeout);
  EXPECT_EQ(a.unreachable_grace, a0.unreachable_grace);
  EXPECT_EQ(a.rebind_interval, a0.rebind_interval);
  EXPECT_EQ(a.watch_refresh, a0.watch_refresh);
  EXPECT_EQ(a.subscription_lease, a0.subscription_lease);
  EXPECT_EQ(a.remote_entry_ttl, a0.remote_entry_ttl);
  EXPECT_EQ(a.max_pending, a0.max_pending);
  EXPECT_EQ(cfg.log_level, "info");
  EXPECT_EQ(cfg.log_format, "text");
  EXPECT_EQ(cfg.scheduler, "loop");
  EXPECT_EQ(cfg.threads, 1u);
  EXPECT_EQ(cfg.busy_poll_us, 0u);
  EXPECT_EQ(cfg.control_socket, default_control_socket("m"));
  EXPECT_TRUE(cfg.module.devices.empty());
  EXPECT_TRUE(cfg.device_lines.empty());
  EXPECT_TRUE(cfg.apos.empty());
}

TEST(config, takes_empty_sections_as_all_defaults) {
  auto cfg = parse_ok(lines({"module:", "  name: m", "log:", "scheduler:",
                             "apps:", "channels:", "apos: []"}));
  EXPECT_EQ(cfg.log_level, "info");
  EXPECT_EQ(cfg.scheduler, "loop");
  EXPECT_EQ(cfg.control_socket, default_control_socket("m"));
  EXPECT_TRUE(cfg.module.devices.empty());
  EXPECT_TRUE(cfg.apos.empty());
}

TEST(config, turns_the_control_socket_off_with_off) {
  auto cfg = parse_ok(lines({"module: { name: m }", "control:",
                             "  socket: off"}));
  EXPECT_EQ(cfg.control_socket, "");
}

TEST(config, defaults_the_control_socket_when_the_section_names_none) {
  auto cfg = parse_ok(lines({"module: { name: m }", "control: {}"}));
  EXPECT_EQ(cfg.control_socket, default_control_socket("m"));
}

TEST(config, keeps_channel_options_as_written) {
  auto cfg = parse_ok(lines({
    "module: { name: m }",
    "channels:",
    "  - name: a",
    "    kind: inproc",
    "    interface: seg",
    "    quoted: \"007\"",
    "    empty_list: []",
    "    one: [x]",
    "    numbers: [1, 2.5, -3]",
    "    text: hello world",
  }));
  ASSERT_EQ(cfg.module.devices.size(), 1u);
  option_map want{{"quoted", "007"},
                  {"empty_list", ""},
                  {"one", "x"},
                  {"numbers", "1,2.5,-3"},
                  {"text", "hello world"}};
  EXPECT_EQ(cfg.module.devices[0].options, want);
}

TEST(config, accepts_every_registered_link_kind_and_builtin_profile) {
  for (auto* k : link_kinds()) {
    for (auto& p : builtin_profiles()) {
      SCOPED_TRACE(std::string{k->name} + " " + p.name);
      auto text = "module: { name: m }\nchannels:\n  - { name: a, kind: "
                  + std::string{k->name} + ", interface: x, profile: "
                  + p.name + " }\n";
      auto cfg = parse_ok(text);
      ASSERT_EQ(cfg.module.devices.size(), 1u);
      EXPECT_EQ(cfg.module.devices[0].options.at("profile"), p.name);
    }
  }
}

// -- errors ----------------------------------------------------------------------

/// One malformed file and what the error says. With `tail` empty the context
/// equals `head`; otherwise it starts with `head` and ends with `tail` (for
/// messages that list every link kind or profile, which may grow).
struct error_case {
  const char* name;
  std::string text;
  std::string head;
  std::string tail = "";
};

void PrintTo(const error_case& x, std::ostream* os) {
  *os << x.name;
}

const std::string channel_head = lines({
  "module:",              // 1
  "  name: m",            // 2
  "channels:",            // 3
  "  - name: eth0",       // 4
  "    kind: udp",        // 5
  "    interface: a:1",   // 6
});

const error_case error_cases[] = {
  // -- module -------------------------------------------------------------------
  {"bad_module_id",
   lines({"module:", "  name: m", "  id: foo"}),
   "robot.yaml:3: module.id: expected a module id (0x0001..0xFFFE), "
   "\"dynamic\" or a category (main_controller, left_arm, right_arm, vision, "
   "sensor, mobile, manipulator, power, other), got 'foo'"},
  {"missing_module_section",
   lines({"log: { level: info }"}),
   "robot.yaml:1: module: missing (required: the module's name and id)"},
  {"empty_file", "",
   "robot.yaml:1: module: missing (required: the module's name and id)"},
  {"missing_module_name",
   lines({"log: { level: info }", "module:", "  id: 0x4E"}),
   "robot.yaml:2: module.name: missing (required: a name of 1 to 64 "
   "characters from [A-Za-z0-9_.-])"},
  {"module_name_with_a_space",
   lines({"module:", "  name: main controller"}),
   "robot.yaml:2: module.name: expected a name of 1 to 64 characters from "
   "[A-Za-z0-9_.-], got 'main controller'"},
  {"module_name_too_long",
   lines({"module:",
          "  name: "
          "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa"}),
   "robot.yaml:2: module.name: expected a name of 1 to 64 characters from "
   "[A-Za-z0-9_.-], got "
   "'aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa...'"},
  {"module_name_empty",
   lines({"module:", "  name: \"\""}),
   "robot.yaml:2: module.name: expected a name of 1 to 64 characters from "
   "[A-Za-z0-9_.-], got ''"},
  {"module_name_left_empty",
   lines({"module:", "  name:", "  id: 1"}),
   "robot.yaml:2: module.name: expected a name of 1 to 64 characters from "
   "[A-Za-z0-9_.-], got nothing"},
  {"hello_interval_too_short",
   lines({"module:", "  name: m", "  hello_interval_ms: 2"}),
   "robot.yaml:3: module.hello_interval_ms: expected an integer in [4, "
   "65535], got '2'"},
  {"hello_loss_not_a_number",
   lines({"module:", "  name: m", "  hello_loss: often"}),
   "robot.yaml:3: module.hello_loss: expected a number in [1, 100], got "
   "'often'"},
  {"update_every_negative",
   lines({"module:", "  name: m", "  update_every: -1"}),
   "robot.yaml:3: module.update_every: expected an integer in [1, 1000], got "
   "'-1'"},
  {"unknown_module_key",
   lines({"module:", "  name: m", "  hello_intervall_ms: 100"}),
   "robot.yaml:3: module.hello_intervall_ms: unknown key (expected name, id, "
   "hello_interval_ms, hello_loss, update_every, hold_factor, "
   "announce_every or limits)"},
  {"duplicate_key",
   lines({"module:", "  name: a", "  id: 1", "  name: b"}),
   "robot.yaml:4: module.name: duplicate key (first at line 2)"},
  {"module_is_a_list",
   lines({"module:", "  - name: m"}),
   "robot.yaml:2: module: expected a map, got a list"},
  // -- top level, log, scheduler, control, apps ---------------------------------
  {"unknown_top_level_key",
   lines({"module: { name: m }", "chanels: []"}),
   "robot.yaml:2: chanels: unknown key (expected module, log, scheduler, "
   "control, apps, channels, apos or auth)"},
  {"top_level_is_a_list",
   lines({"- module"}),
   "robot.yaml:1: expected a map of sections, got a list"},
  {"two_documents",
   lines({"module: { name: m }", "---", "module: { name: n }"}),
   "robot.yaml:3: expected one YAML document, got a second one here"},
  {"bad_log_level",
   lines({"module: { name: m }", "log:", "  level: verbose"}),
   "robot.yaml:3: log.level: expected trace, debug, info, warn, error or off, "
   "got 'verbose'"},
  {"bad_log_format",
   lines({"module: { name: m }", "log: { format: xml }"}),
   "robot.yaml:2: log.format: expected text or json, got 'xml'"},
  {"unknown_log_key",
   lines({"module: { name: m }", "log: { levle: info }"}),
   "robot.yaml:2: log.levle: unknown key (expected level or format)"},
  {"bad_scheduler_policy",
   lines({"module: { name: m }", "scheduler: { policy: fifo }"}),
   "robot.yaml:2: scheduler.policy: expected loop, sharing or stealing, got "
   "'fifo'"},
  {"too_many_threads",
   lines({"module: { name: m }", "scheduler:", "  threads: 257"}),
   "robot.yaml:3: scheduler.threads: expected an integer in [0, 256], got "
   "'257'"},
  {"busy_poll_too_long",
   lines({"module: { name: m }", "scheduler: { busy_poll_us: -1 }"}),
   "robot.yaml:2: scheduler.busy_poll_us: expected an integer in [0, "
   "100000], got '-1'"},
  {"control_socket_a_list",
   lines({"module: { name: m }", "control:", "  socket: [a, b]"}),
   "robot.yaml:3: control.socket: expected a socket path of at most 107 bytes "
   "or \"off\", got a list"},
  {"control_socket_too_long",
   lines({"module: { name: m }", "control:",
          "  socket: /tmp/aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa"
          "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa.sock"}),
   "robot.yaml:3: control.socket: expected a socket path of at most 107 bytes "
   "or \"off\", got "
   "'/tmp/aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa...'"},
  {"control_off_without_socket_key",
   lines({"module: { name: m }", "control: off"}),
   "robot.yaml:2: control: expected a map, got 'off'"},
  {"bad_request_timeout",
   lines({"module: { name: m }", "apps:", "  request_timeout_ms: soon"}),
   "robot.yaml:3: apps.request_timeout_ms: expected an integer in [1, "
   "86400000], got 'soon'"},
  {"unknown_apps_key",
   lines({"module: { name: m }", "apps:", "  request_timeout: 5"}),
   "robot.yaml:3: apps.request_timeout: unknown key (expected tick_ms, "
   "idle_tick_ms, request_timeout_ms, unreachable_grace_ms, rebind_interval_ms, "
   "watch_refresh_ms, subscription_lease_ms, remote_entry_ttl_ms or "
   "max_pending)"},
  // -- channels -----------------------------------------------------------------
  {"bad_mtu",
   lines({
     "module:",                  // 1
     "  name: m",                // 2
     "  id: 0x4E",               // 3
     "channels:",                // 4
     "  - name: eth0",           // 5
     "    kind: udp",            // 6
     "    interface: a:1",       // 7
     "    mtu: 1500",            // 8
     "",                         // 9
     "  - name: eth1",           // 10
     "    kind: udp",            // 11
     "    mtu: big",             // 12
     "    interface: a:2",       // 13
   }),
   "robot.yaml:12: channels[1].mtu: expected an integer in [1, 65535], got "
   "'big'"},
  {"mtu_too_large", channel_head + "    mtu: 70000\n",
   "robot.yaml:7: channels[0].mtu: expected an integer in [1, 65535], got "
   "'70000'"},
  {"mtu_zero", channel_head + "    mtu: 0\n",
   "robot.yaml:7: channels[0].mtu: expected an integer in [1, 65535], got "
   "'0'"},
  {"bandwidth_zero", channel_head + "    bandwidth: 0\n",
   "robot.yaml:7: channels[0].bandwidth: expected an integer in [1, "
   "100000000000], got '0'"},
  {"bandwidth_in_exponent_notation", channel_head + "    bandwidth: 1e8\n",
   "robot.yaml:7: channels[0].bandwidth: expected an integer in [1, "
   "100000000000], got '1e8'"},
  {"bandwidth_huge", channel_head + "    bandwidth: 99999999999999999999999\n",
   "robot.yaml:7: channels[0].bandwidth: expected an integer in [1, "
   "100000000000], got '99999999999999999999999'"},
  {"delay_coef_zero", channel_head + "    delay_coef: 0\n",
   "robot.yaml:7: channels[0].delay_coef: expected a number in [0.001, "
   "1000], got '0'"},
  {"delay_coef_text", channel_head + "    delay_coef: fast\n",
   "robot.yaml:7: channels[0].delay_coef: expected a number in [0.001, "
   "1000], got 'fast'"},
  {"delay_coef_nan", channel_head + "    delay_coef: nan\n",
   "robot.yaml:7: channels[0].delay_coef: expected a number in [0.001, "
   "1000], got 'nan'"},
  {"unknown_profile", channel_head + "    profile: firewire\n",
   "robot.yaml:7: channels[0].profile: expected a built-in profile (usb1.1, ",
   " or rs232c), got 'firewire'"},
  {"unknown_kind",
   lines({"module: { name: m }", "channels:", "  - name: eth0",
          "    kind: ud", "    interface: a:1"}),
   "robot.yaml:4: channels[0].kind: expected a link kind (", "got 'ud'"},
  {"missing_channel_name",
   lines({"module: { name: m }", "channels:", "  - kind: udp",
          "    interface: a:1"}),
   "robot.yaml:3: channels[0].name: missing (required: a channel name)"},
  {"missing_channel_kind",
   lines({"module: { name: m }", "channels:", "  - name: eth0",
          "    interface: a:1"}),
   "robot.yaml:3: channels[0].kind: missing (required: a link kind: ", ")"},
  {"missing_channel_interface",
   lines({"module: { name: m }", "channels:", "  - name: eth0",
          "    kind: udp"}),
   "robot.yaml:3: channels[0].interface: missing (required: the interface, "
   "e.g. 127.0.0.1:47000)"},
  {"empty_channel_interface", channel_head + "  - name: eth1\n"
                                             "    kind: udp\n"
                                             "    interface: ''\n",
   "robot.yaml:9: channels[1].interface: expected an interface, got ''"},
  {"duplicate_channel_name",
   channel_head + lines({"  - name: eth0", "    kind: udp",
                         "    interface: a:2"}),
   "robot.yaml:7: channels[1].name: duplicate channel name 'eth0' (first at "
   "line 4)"},
  {"duplicate_channel_key", channel_head + "    kind: emu\n",
   "robot.yaml:7: channels[0].kind: duplicate key (first at line 5)"},
  {"channel_option_a_map", channel_head + "    peers: { a: 1 }\n",
   "robot.yaml:7: channels[0].peers: expected a scalar or a list of scalars, "
   "got a map"},
  {"channel_option_left_empty", channel_head + "    peers:\n",
   "robot.yaml:7: channels[0].peers: expected a scalar or a list of scalars, "
   "got nothing"},
  {"channel_option_list_of_lists",
   channel_head + lines({"    peers:", "      - a", "      - [b, c]"}),
   "robot.yaml:9: channels[0].peers[1]: expected a scalar, got a list"},
  {"channels_a_map",
   lines({"module: { name: m }", "channels:", "  eth0: { kind: udp }"}),
   "robot.yaml:3: channels: expected a list of channels, got a map"},
  {"channel_entry_a_scalar",
   lines({"module: { name: m }", "channels:", "  - eth0"}),
   "robot.yaml:3: channels[0]: expected a map with name, kind and interface, "
   "got 'eth0'"},
  // -- apos ---------------------------------------------------------------------
  {"missing_apo_name",
   lines({"module: { name: m }", "apos:", "  - kind: collector"}),
   "robot.yaml:3: apos[0].name: missing (required: an APO name)"},
  {"missing_apo_kind",
   lines({"module: { name: m }", "apos:", "  - name: c"}),
   "robot.yaml:3: apos[0].kind: missing (required: an APO kind)"},
  {"duplicate_apo_name",
   lines({"module: { name: m }", "apos:", "  - { name: c, kind: collector }",
          "  - name: c", "    kind: other"}),
   "robot.yaml:4: apos[1].name: duplicate APO name 'c' (first at line 3)"},
  {"apo_name_too_long",
   "module: { name: m }\napos:\n  - kind: k\n    name: " + std::string(256, 'n')
     + "\n",
   "robot.yaml:4: apos[0].name: expected a name of 1 to 255 bytes, got '"
     + std::string(60, 'n') + "...'"},
  {"unknown_apo_key",
   lines({"module: { name: m }", "apos:", "  - name: c", "    kind: k",
          "    option: { a: 1 }"}),
   "robot.yaml:5: apos[0].option: unknown key (expected name, kind, type or "
   "options)"},
  {"apo_options_a_list",
   lines({"module: { name: m }", "apos:", "  - name: c", "    kind: k",
          "    options: [a, b]"}),
   "robot.yaml:5: apos[0].options: expected a map of options, got a list"},
  {"apo_option_a_map",
   lines({"module: { name: m }", "apos:", "  - name: c", "    kind: k",
          "    options:", "      period_ms: { x: 1 }"}),
   "robot.yaml:6: apos[0].options.period_ms: expected a scalar or a list of "
   "scalars, got a map"},
  {"apo_type_empty",
   lines({"module: { name: m }", "apos:", "  - name: c", "    kind: k",
          "    type:"}),
   "robot.yaml:5: apos[0].type: expected an interface type name, got "
   "nothing"},
  // -- YAML syntax --------------------------------------------------------------
  {"unclosed_flow_sequence",
   lines({"module: { name: m }", "channels: [", "  a: b"}),
   "robot.yaml:4: end of sequence flow not found"},
  {"tab_indentation",
   lines({"module:", "  name: m", "\tid: 1"}),
   "robot.yaml:3: illegal tab when looking for indentation"},
  {"undefined_alias",
   lines({"module: { name: m }", "log: *nothing"}),
   "robot.yaml:2: the referenced anchor is not defined"},
  {"self_referencing_alias",
   channel_head + "    peers: &p [a, *p]\n",
   "robot.yaml:7: channels[0].peers[1]: alias inside the node it refers to "
   "(a cycle)"},
};

class config_errors : public testing::TestWithParam<error_case> {};

TEST_P(config_errors, names_file_line_and_field) {
  auto& x = GetParam();
  auto err = parse_error(x.text);
  if (x.tail.empty()) {
    EXPECT_EQ(err, x.head);
  } else {
    EXPECT_EQ(err.rfind(x.head, 0), 0u) << err;
    ASSERT_GE(err.size(), x.tail.size()) << err;
    EXPECT_NE(err.find(x.tail), std::string::npos) << err;
  }
}

INSTANTIATE_TEST_SUITE_P(config, config_errors, testing::ValuesIn(error_cases),
                         [](const testing::TestParamInfo<error_case>& row) {
                           return std::string{row.param.name};
                         });

TEST(config, names_file_line_and_field_of_a_bad_mtu) {
  // The example of actors/config.hpp, verbatim.
  auto err = parse_error(lines({
    "module:", "  name: m", "  id: 0x4E", "channels:", "  - name: eth0",
    "    kind: udp", "    interface: a:1", "", "", "  - name: eth1",
    "    kind: udp", "    mtu: big", "    interface: a:2"}));
  EXPECT_EQ(err, "robot.yaml:12: channels[1].mtu: expected an integer in [1, "
                 "65535], got 'big'");
}

TEST(config, names_the_line_of_a_yaml_syntax_error) {
  auto err = parse_error(lines({"module:", "  name: m", "channels: [",
                                "  - a: b", "log: {"}));
  // yaml-cpp reports the unclosed flow sequence where it gives up.
  EXPECT_EQ(err.rfind("robot.yaml:", 0), 0u) << err;
  auto line = std::atoi(err.c_str() + std::string{"robot.yaml:"}.size());
  EXPECT_GE(line, 3) << err;
  EXPECT_LE(line, 6) << err;
}

// -- files -----------------------------------------------------------------------

TEST(config, loads_a_file_and_remembers_its_path) {
  temp_dir dir;
  auto file = dir.write("robot.yaml", full_config);
  auto cfg = load_config(file);
  ASSERT_TRUE(cfg) << render(cfg.error());
  EXPECT_EQ(cfg->path, file);
  EXPECT_EQ(cfg->name, "main-controller");
  EXPECT_EQ(cfg->module.devices.size(), 2u);
}

TEST(config, names_the_file_in_errors_from_a_loaded_file) {
  temp_dir dir;
  auto file = dir.write("arm.yaml", lines({"module:", "  name: m",
                                           "  id: nope"}));
  auto cfg = load_config(file);
  ASSERT_FALSE(cfg);
  EXPECT_EQ(context_of(cfg.error()).rfind(file + ":3: module.id: ", 0), 0u)
    << render(cfg.error());
}

TEST(config, names_the_path_and_reason_of_a_missing_file) {
  temp_dir dir;
  auto file = dir.path + "/nowhere.yaml";
  auto cfg = load_config(file);
  ASSERT_FALSE(cfg);
  EXPECT_TRUE(is(cfg.error(), ec::invalid_config));
  EXPECT_EQ(context_of(cfg.error()),
            file + ": cannot read: No such file or directory");
}

TEST(config, names_the_path_and_reason_of_a_directory) {
  temp_dir dir;
  auto cfg = load_config(dir.path);
  ASSERT_FALSE(cfg);
  EXPECT_EQ(context_of(cfg.error()), dir.path + ": cannot read: Is a directory");
}

// -- the default control socket --------------------------------------------------

TEST(config, puts_the_default_control_socket_in_the_runtime_dir) {
  if (::geteuid() == 0) {
    EXPECT_EQ(default_control_socket("arm"), "/run/herm/arm.sock");
    return;
  }
  {
    scoped_env env{"XDG_RUNTIME_DIR", "/run/user/1000"};
    EXPECT_EQ(default_control_socket("arm"), "/run/user/1000/herm/arm.sock");
  }
  {
    scoped_env env{"XDG_RUNTIME_DIR", nullptr};
    EXPECT_EQ(default_control_socket("arm"),
              "/tmp/herm-" + std::to_string(::geteuid()) + "/arm.sock");
  }
  {
    scoped_env env{"XDG_RUNTIME_DIR", ""};
    EXPECT_EQ(default_control_socket("arm"),
              "/tmp/herm-" + std::to_string(::geteuid()) + "/arm.sock");
  }
}

} // namespace

// Found by fuzz_config (tests/fuzz/crashes/config-loadall-comma.bin): with
// yaml-cpp 0.7's LoadAll, a lone "," never returned (empty documents for
// ever, gigabytes allocated). Now it is one bounded, refused document.
TEST(config, a_lone_comma_is_refused_not_looped_on) {
  auto cfg = parse_config(",", "robot.yaml");
  ASSERT_FALSE(cfg);
  EXPECT_NE(render(cfg.error()).find("robot.yaml:"), std::string::npos)
    << render(cfg.error());
}

// -- alias bombs -------------------------------------------------------------------

namespace {

/// One inproc channel whose option `big` is `size` x's anchored as &s,
/// followed by `count` options a0, a1, ... each an alias of it, one a line.
/// Line of option aK: 9 + K.
std::string string_bomb(size_t size, size_t count) {
  std::string text = lines({
    "module: { name: m }",
    "channels:",
    "  - name: a",
    "    kind: inproc",
    "    interface: seg",
  });
  text += "    big: &s " + std::string(size, 'x') + "\n";
  text += "    list: [1, 2]\n";
  text += "    other: 3\n";
  for (size_t i = 0; i < count; ++i)
    text += "    a" + std::to_string(i) + ": *s\n";
  return text;
}

/// "robot.yaml:L: channels[0].aK: ..." names the line of aK.
void expect_names_an_alias_line(const std::string& context) {
  auto colon = context.find(':', std::string{"robot.yaml:"}.size());
  ASSERT_EQ(context.rfind("robot.yaml:", 0), 0u) << context;
  ASSERT_NE(colon, std::string::npos) << context;
  auto line = std::stoul(context.substr(11, colon - 11));
  ASSERT_GE(line, 9u) << context;
  EXPECT_NE(context.find(": channels[0].a" + std::to_string(line - 9) + ": "),
            std::string::npos)
    << context;
}

} // namespace

// Found by an attacker's config: aliases of one large string in channel
// options made parsing allocate every copy (std::bad_alloc, exit 134).
TEST(config, refuses_aliases_of_a_large_string_naming_the_line_and_field) {
  // 256 KiB repeated 100 times: 25 MiB if expanded.
  auto context = parse_error(string_bomb(256 * 1024, 100));
  EXPECT_NE(context.find("expands to more than 8 MiB"), std::string::npos)
    << context.substr(0, 200);
  expect_names_an_alias_line(context);
}

TEST(config, refuses_nested_aliases_that_multiply_before_building_them) {
  // Ten levels of ten: 10^10 strings, from a file of a few hundred bytes.
  std::string text = lines({
    "module: { name: m }",
    "channels:",
    "  - name: a",
    "    kind: inproc",
    "    interface: seg",
    "    l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]",
  });
  for (int i = 1; i < 10; ++i) {
    auto prev = "*l" + std::to_string(i - 1);
    text += "    l" + std::to_string(i) + ": &l" + std::to_string(i) + " [";
    for (int k = 0; k < 10; ++k)
      text += (k == 0 ? "" : ", ") + prev;
    text += "]\n";
  }
  auto context = parse_error(text);
  EXPECT_NE(context.find("expands to more than 8 MiB"), std::string::npos)
    << context;
  // Crossed inside one of the nested lists, named as a list element.
  EXPECT_NE(context.find(": channels[0].l"), std::string::npos) << context;
  EXPECT_NE(context.find("]: "), std::string::npos) << context;
}

TEST(config, refuses_an_alias_inside_the_node_it_refers_to) {
  auto context = parse_error(lines({
    "module: { name: m }",
    "channels:",
    "  - &c",
    "    name: a",
    "    kind: inproc",
    "    interface: seg",
    "    me: *c",
  }));
  EXPECT_NE(context.find("robot.yaml:7: channels[0].me: "), std::string::npos)
    << context;
  EXPECT_NE(context.find("cycle"), std::string::npos) << context;
}

TEST(config, accepts_aliases_whose_expansion_stays_within_the_bound) {
  // 4 KiB repeated 100 times: 400 KiB expanded.
  auto cfg = parse_ok(string_bomb(4 * 1024, 100));
  ASSERT_EQ(cfg.module.devices.size(), 1u);
  auto& opts = cfg.module.devices[0].options;
  EXPECT_EQ(opts.at("a99"), std::string(4 * 1024, 'x'));
  EXPECT_EQ(opts.size(), 103u);
}

TEST(config, a_file_of_the_largest_size_without_aliases_is_within_the_bound) {
  // A list of one-character scalars: the most nodes 1 MiB can hold.
  std::string text = "module: { name: m }\nx: [";
  while (text.size() < 1024 * 1024 - 8)
    text += "1,";
  text += "1]\n";
  auto context = parse_error(text);
  // Refused for the unknown key, not for its size.
  EXPECT_EQ(context.find("expands"), std::string::npos) << context.substr(0, 200);
  EXPECT_NE(context.find("robot.yaml:2: x:"), std::string::npos)
    << context.substr(0, 200);
}

TEST(config, load_config_refuses_an_alias_bomb_file_naming_it) {
  temp_dir dir;
  // Just under the 1 MiB file bound: 512 KiB and tens of thousands of aliases.
  auto text = string_bomb(512 * 1024, 1);
  while (text.size() < 1000 * 1024)
    text += "    b" + std::to_string(text.size()) + ": *s\n";
  auto file = dir.write("bomb.yaml", text);
  auto cfg = load_config(file);
  ASSERT_FALSE(cfg);
  EXPECT_TRUE(is(cfg.error(), ec::invalid_config));
  auto context = context_of(cfg.error());
  EXPECT_EQ(context.rfind(file + ":", 0), 0u) << context.substr(0, 200);
  EXPECT_NE(context.find("expands to more than 8 MiB"), std::string::npos)
    << context.substr(0, 200);
}

#ifdef HERMD_BIN
// What an operator sees: `hermd --check` exits 2 with file, line and field
// (it aborted with std::bad_alloc, exit 134, before).
TEST(config, hermd_check_refuses_an_alias_bomb_with_exit_code_2) {
  temp_dir dir;
  auto file = dir.write("bomb.yaml", string_bomb(256 * 1024, 100));
  test::child_process hermd{{"/bin/sh", "-c",
                             std::string{"exec '"} + HERMD_BIN + "' --check '"
                               + file + "' 2>&1"}};
  ASSERT_TRUE(hermd.started());
  EXPECT_EQ(hermd.wait(std::chrono::seconds(30)), 2) << hermd.output();
  auto& out = hermd.output();
  EXPECT_NE(out.find(file + ":"), std::string::npos) << out;
  EXPECT_NE(out.find(": channels[0].a"), std::string::npos) << out;
  EXPECT_NE(out.find("expands to more than 8 MiB"), std::string::npos) << out;
}
#endif

#if defined(HERMD_BIN) && defined(HERMCTL_BIN)
namespace {

/// A hermctl run with stderr merged: exit status and output.
std::pair<int, std::string> run_hermctl(const std::string& args) {
  test::child_process p{{"/bin/sh", "-c",
                         std::string{"exec '"} + HERMCTL_BIN + "' " + args
                           + " 2>&1"}};
  auto status = p.wait(std::chrono::seconds(30));
  return {status, p.output()};
}

/// Peak resident memory of process `pid` (VmHWM), KiB; 0 if unknown.
long peak_rss_kib(pid_t pid) {
  std::ifstream in{"/proc/" + std::to_string(pid) + "/status"};
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0)
      return std::atol(line.c_str() + 6);
  return 0;
}

} // namespace

// A running module asked to reload a 1 MiB alias bomb (15 GB expanded)
// refuses it with file, line and field, without growing by the expansion,
// and runs on with its old configuration.
TEST(config, hermctl_reload_refuses_an_alias_bomb_and_the_module_runs_on) {
  temp_dir dir;
  auto sock = dir.path + "/m.sock";
  auto head = "module: { name: m }\ncontrol: { socket: " + sock + " }\n";
  auto file = dir.write("m.yaml", head);
  test::child_process hermd{{HERMD_BIN, file}};
  ASSERT_TRUE(hermd.started());
  auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(15);
  int status = -1;
  while (status != 0 && std::chrono::steady_clock::now() < deadline) {
    status = run_hermctl("-s '" + sock + "' info").first;
    if (status != 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_EQ(status, 0) << "hermd did not come up";
  auto before = peak_rss_kib(hermd.pid());
  // 512 KiB anchored, then aliases of it up to 1000 KiB of file.
  auto text = head + lines({"channels:", "  - name: a", "    kind: inproc",
                            "    interface: seg"});
  text += "    big: &s " + std::string(512 * 1024, 'x') + "\n";
  for (int i = 0; text.size() < 1000 * 1024; ++i)
    text += "    b" + std::to_string(i) + ": *s\n";
  dir.write("m.yaml", text);
  auto [code, out] = run_hermctl("-s '" + sock + "' reload");
  EXPECT_NE(code, 0) << out;
  EXPECT_NE(out.find(file + ":"), std::string::npos) << out;
  EXPECT_NE(out.find(": channels[0].b"), std::string::npos) << out;
  EXPECT_NE(out.find("expands to more than 8 MiB"), std::string::npos) << out;
  auto after = peak_rss_kib(hermd.pid());
  // The text is read (1 MiB) and parsed event by event, never expanded.
  EXPECT_LT(after - before, 32 * 1024) << before << " KiB -> " << after << " KiB";
  EXPECT_TRUE(hermd.running());
  EXPECT_EQ(run_hermctl("-s '" + sock + "' info").first, 0);
  ::kill(hermd.pid(), SIGTERM);
  EXPECT_EQ(hermd.wait(std::chrono::seconds(15)), 0) << hermd.output();
}
#endif

// module.limits: bounds on routing state (docs/user-guide.md), defaults
// from routing_config and route_limits, each key checked for its range.
TEST(config, reads_routing_limits_and_refuses_them_out_of_range) {
  auto defaults = parse_ok(lines({"module:", "  name: m"})).module.routing;
  EXPECT_EQ(defaults.limits.destinations, 4096u);
  EXPECT_EQ(defaults.limits.per_neighbour, 1024u);
  EXPECT_EQ(defaults.limits.routes, 16384u);
  EXPECT_EQ(defaults.max_neighbours, 512u);
  EXPECT_EQ(defaults.max_neighbours_per_channel, 128u);
  EXPECT_EQ(defaults.max_floods, 8192u);
  auto r = parse_ok(lines({"module:", "  name: m", "  limits:",
                           "    destinations: 100",
                           "    destinations_per_neighbour: 50",
                           "    routes: 400", "    neighbours: 20",
                           "    neighbours_per_channel: 10",
                           "    floods: 300"}))
             .module.routing;
  EXPECT_EQ(r.limits.destinations, 100u);
  EXPECT_EQ(r.limits.per_neighbour, 50u);
  EXPECT_EQ(r.limits.routes, 400u);
  EXPECT_EQ(r.max_neighbours, 20u);
  EXPECT_EQ(r.max_neighbours_per_channel, 10u);
  EXPECT_EQ(r.max_floods, 300u);
  EXPECT_EQ(parse_error(lines({"module:", "  name: m", "  limits:",
                               "    destinations: 0"})),
            "robot.yaml:4: module.limits.destinations: expected an integer "
            "in [1, 65534], got '0'");
  EXPECT_EQ(parse_error(lines({"module:", "  name: m", "  limits:",
                               "    destination: 10"})),
            "robot.yaml:4: module.limits.destination: unknown key (expected "
            "destinations, destinations_per_neighbour, routes, neighbours, "
            "neighbours_per_channel or floods)");
}
