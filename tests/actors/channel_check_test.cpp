// Channel options are checked when the file is read (link_kind::check, the
// parser each driver's open runs first): a misspelled option, a host name
// where an IPv4 address is needed, a port or a value out of range and a bad
// peers list are configuration errors naming the file, the line and the
// field, for `hermd --check` as for a start, and never open a device.

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "actors/config.hpp"
#include "actors/runtime/error.hpp"
#include "channels/link_driver.hpp"
#include "tests/support/process.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

/// The kind's check on a device with `interface` and `options`.
caf::error check(const std::string& kind, const std::string& interface,
                 std::map<std::string, std::string> options = {}) {
  device_config dev;
  dev.name = "dev0";
  dev.kind = kind;
  dev.interface = interface;
  dev.options = std::move(options);
  auto* k = find_link_kind(kind);
  EXPECT_NE(k, nullptr) << kind;
  if (k == nullptr || k->check == nullptr) {
    ADD_FAILURE() << "link kind '" << kind << "' has no check";
    return make_error(ec::invalid_parameter, "no check");
  }
  return k->check(dev);
}

/// A file of one module whose only channel is `channel` (YAML lines,
/// indented as list items: "    kind: udp"); the channel starts at line 5.
std::string file_with(const std::string& channel) {
  return "module:\n  name: a\n  id: 0x21\nchannels:\n  - name: eth0\n"
         + channel;
}

/// The error text parse_config, then check_channels give for `text`, ""
/// when it loads and checks.
std::string config_error(const std::string& text) {
  auto cfg = parse_config(text, "robot.yaml");
  if (!cfg)
    return render(cfg.error());
  auto err = check_channels(*cfg);
  return err ? render(err) : std::string{};
}

} // namespace

// -- each kind's check -----------------------------------------------------------

TEST(link_kind_check, every_built_in_kind_has_a_check) {
  for (auto* k : link_kinds())
    EXPECT_NE(k->check, nullptr) << k->name;
}

TEST(link_kind_check, accepts_what_the_kinds_document) {
  EXPECT_FALSE(check("udp", "127.0.0.1:0",
                     {{"peers", "127.0.0.1:47001,127.0.0.1:47002"},
                      {"broadcast", "10.77.0.255:47000"},
                      {"rcvbuf", "65536"}}));
  EXPECT_FALSE(check("inproc", "seg", {{"station", "3"}}));
  EXPECT_FALSE(check("emu", "/tmp/herm-check-medium", {{"loss", "0.1"}}));
  EXPECT_FALSE(check("serial", "/dev/herm-no-such-tty", {{"baud", "115200"}}));
  EXPECT_FALSE(check("can", "vcan0", {{"node", "5"}, {"filter", "false"}}));
  EXPECT_FALSE(check("can", "emu:/tmp/herm-check-bus", {{"node", "5"},
                                                        {"loss", "0.01"}}));
}

TEST(link_kind_check, touches_no_device) {
  // A tty that does not exist and a medium directory that is not created:
  // opening would fail or create it, checking does neither.
  auto dir = "/tmp/herm-check-never-created-" + std::to_string(::getpid());
  EXPECT_FALSE(check("emu", dir));
  EXPECT_FALSE(check("can", "emu:" + dir, {{"node", "1"}}));
  EXPECT_FALSE(std::filesystem::exists(dir));
}

TEST(link_kind_check, refuses_a_misspelled_option_and_lists_the_known_ones) {
  auto err = check("udp", "127.0.0.1:0", {{"peer", "127.0.0.1:1"}});
  ASSERT_TRUE(err);
  EXPECT_TRUE(is(err, ec::invalid_parameter)) << render(err);
  auto text = render(err);
  EXPECT_NE(text.find("unknown option(s) 'peer' for link kind 'udp'"),
            std::string::npos)
    << text;
  EXPECT_NE(text.find("peers"), std::string::npos) << text;
  for (auto kind : {"inproc", "emu", "serial"}) {
    auto e = check(kind, kind == std::string{"serial"} ? "/dev/ttyS0" : "x",
                   {{"lossy", "1"}});
    EXPECT_NE(render(e).find("unknown option(s) 'lossy'"), std::string::npos)
      << kind << ": " << render(e);
  }
}

TEST(link_kind_check, names_at_most_eight_unknown_options) {
  std::map<std::string, std::string> many;
  for (int i = 10; i < 30; ++i)
    many["x" + std::to_string(i)] = "1";
  auto text = render(check("inproc", "seg", many));
  EXPECT_NE(text.find("unknown option(s) 'x10', 'x11', 'x12', 'x13', 'x14', "
                      "'x15', 'x16', 'x17' and 12 more for link kind 'inproc'"),
            std::string::npos)
    << text;
}

TEST(link_kind_check, a_misspelled_can_node_is_named_before_the_missing_one) {
  auto err = check("can", "vcan0", {{"nod", "3"}});
  EXPECT_NE(render(err).find("unknown option(s) 'nod'"), std::string::npos)
    << render(err);
  err = check("can", "vcan0");
  EXPECT_NE(render(err).find("option 'node' is required"), std::string::npos)
    << render(err);
}

TEST(link_kind_check, refuses_host_names_and_ports_out_of_range) {
  for (auto bad : {"robot-a:47000", "127.0.0.1:70000", "127.0.0.1", "::1:47000"}) {
    auto err = check("udp", bad);
    EXPECT_TRUE(is(err, ec::invalid_address)) << bad << ": " << render(err);
  }
  auto err = check("udp", "127.0.0.1:0", {{"peers", "127.0.0.1:1,robot-b:47000"}});
  EXPECT_TRUE(is(err, ec::invalid_address)) << render(err);
  EXPECT_NE(render(err).find("'robot-b:47000' is not an IPv4 address"),
            std::string::npos)
    << render(err);
  err = check("udp", "127.0.0.1:0", {{"broadcast", "everyone:47000"}});
  EXPECT_TRUE(is(err, ec::invalid_address)) << render(err);
  err = check("can", "no such interface", {{"node", "1"}});
  EXPECT_TRUE(is(err, ec::invalid_address)) << render(err);
}

TEST(link_kind_check, refuses_values_out_of_range) {
  EXPECT_TRUE(is(check("inproc", "seg", {{"station", "70000"}}),
                 ec::invalid_parameter));
  EXPECT_TRUE(is(check("emu", "/tmp/m", {{"loss", "2"}}), ec::invalid_parameter));
  EXPECT_TRUE(is(check("can", "vcan0", {{"node", "300"}}), ec::invalid_parameter));
  EXPECT_TRUE(is(check("serial", "/dev/ttyS0", {{"baud", "12345"}}),
                 ec::invalid_parameter));
  EXPECT_TRUE(is(check("inproc", ""), ec::invalid_address));
}

// -- in the configuration file ---------------------------------------------------

TEST(channel_check_config, names_the_line_and_field_of_a_misspelled_option) {
  auto err = config_error(file_with("    kind: udp\n"
                                    "    interface: 127.0.0.1:0\n"
                                    "    peer: 127.0.0.1:47001\n"));
  EXPECT_NE(err.find("herm.invalid_config: robot.yaml:8: channels[0].peer: "
                     "unknown option(s) 'peer' for link kind 'udp' (known: "),
            std::string::npos)
    << err;
}

TEST(channel_check_config, names_the_interface_line_for_a_host_name) {
  auto err = config_error(file_with("    kind: udp\n"
                                    "    interface: robot-a:47000\n"));
  EXPECT_NE(err.find("robot.yaml:7: channels[0].interface: interface "
                     "'robot-a:47000' is not an IPv4 address and port"),
            std::string::npos)
    << err;
}

TEST(channel_check_config, names_the_peers_line_for_a_bad_peers_list) {
  auto err = config_error(file_with("    kind: udp\n"
                                    "    interface: 127.0.0.1:0\n"
                                    "    peers:\n"
                                    "      - 127.0.0.1:47001\n"
                                    "      - robot-b:47000\n"));
  EXPECT_NE(err.find(": channels[0].peers: option 'peers': 'robot-b:47000'"),
            std::string::npos)
    << err;
}

TEST(channel_check_config, a_required_option_missing_blames_the_channel) {
  auto err = config_error(file_with("    kind: can\n"
                                    "    interface: vcan0\n"));
  EXPECT_NE(err.find("robot.yaml:5: channels[0] 'eth0': option 'node' is "
                     "required"),
            std::string::npos)
    << err;
}

TEST(channel_check_config, a_good_channel_loads) {
  EXPECT_EQ(config_error(file_with("    kind: can\n"
                                   "    interface: emu:/tmp/herm-bus\n"
                                   "    node: 3\n")),
            "");
}

// -- hermd --check -----------------------------------------------------------------

TEST(channel_check_hermd, check_refuses_a_bad_option_with_file_line_and_field) {
  char tmpl[] = "/tmp/herm-check-XXXXXX";
  std::string dir = ::mkdtemp(tmpl);
  auto path = dir + "/bad.yaml";
  std::ofstream{path} << file_with("    kind: udp\n"
                                   "    interface: 127.0.0.1:0\n"
                                   "    rcvbuf: 12\n");
  herm::test::child_process p{
    {"/bin/sh", "-c", std::string{HERMD_BIN} + " --check " + path + " 2>&1"}};
  auto status = p.wait(30s);
  auto out = p.output();
  std::filesystem::remove_all(dir);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find(path + ":8: channels[0].rcvbuf: option 'rcvbuf' expects "
                            "an integer in [1024, "),
            std::string::npos)
    << out;
  EXPECT_EQ(out.find(": valid: module"), std::string::npos) << out;
}
