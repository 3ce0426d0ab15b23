// The `auth` section of a module's configuration file: the key comes from a
// file with strict permissions (never from the file's text or the command
// line), errors name the file, line and field, and never show the key; and
// control.allow_unsigned_remote, which only a module without a key may set.

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <string>

#include "actors/config.hpp"
#include "actors/runtime/error.hpp"

using namespace herm;

namespace {

const std::string secret = "00112233445566778899aabbccddeeff"
                           "0123456789abcdef0123456789abcdef";

class auth_config_file : public ::testing::Test {
protected:
  std::string dir;
  std::string key;

  void SetUp() override {
    char tmpl[] = "/tmp/herm-auth-config-XXXXXX";
    ASSERT_NE(::mkdtemp(tmpl), nullptr);
    dir = tmpl;
    key = write("net.key", secret + "\n", 0600);
  }

  void TearDown() override {
    std::string cmd = "rm -rf '" + dir + "'";
    EXPECT_EQ(std::system(cmd.c_str()), 0);
  }

  std::string write(const std::string& name, const std::string& text,
                    mode_t mode) {
    auto path = dir + "/" + name;
    std::ofstream{path} << text;
    EXPECT_EQ(::chmod(path.c_str(), mode), 0);
    return path;
  }

  static std::string doc(const std::string& auth_lines) {
    return "module:\n  name: arm\n  id: 0x0010\n" + auth_lines;
  }

  static std::string error_of(const std::string& text) {
    auto cfg = parse_config(text, "robot.yaml");
    if (cfg)
      return "(parsed)";
    auto& ctx = cfg.error().context();
    if (ctx.match_elements<std::string>())
      return ctx.get_as<std::string>(0);
    return render(cfg.error());
  }
};

} // namespace

TEST_F(auth_config_file, no_auth_section_means_no_key) {
  auto cfg = parse_config(doc(""), "robot.yaml");
  ASSERT_TRUE(cfg) << render(cfg.error());
  EXPECT_FALSE(cfg->module.routing.auth.enabled());
}

TEST_F(auth_config_file, the_key_is_read_from_the_key_file_with_defaults) {
  auto cfg = parse_config(doc("auth:\n  key_file: " + key + "\n"), "robot.yaml");
  ASSERT_TRUE(cfg) << render(cfg.error());
  auto& a = cfg->module.routing.auth;
  ASSERT_TRUE(a.enabled());
  ASSERT_EQ(a.key.size(), 32u);
  EXPECT_EQ(a.key[0], 0x00);
  EXPECT_EQ(a.key[1], 0x11);
  EXPECT_EQ(a.key[31], 0xEF);
  EXPECT_EQ(a.tag_bytes, 8);
  EXPECT_EQ(a.key_id, 1);
  EXPECT_EQ(a.data, auth_data::discovery);
  EXPECT_TRUE(a.challenge);
}

TEST_F(auth_config_file, every_field_is_read) {
  auto cfg = parse_config(doc("auth:\n  key_file: " + key
                              + "\n  key_id: 7\n  tag_bytes: 16\n  data: all\n"
                              + "  challenge: false\n"),
                          "robot.yaml");
  ASSERT_TRUE(cfg) << render(cfg.error());
  auto& a = cfg->module.routing.auth;
  EXPECT_EQ(a.tag_bytes, 16);
  EXPECT_EQ(a.key_id, 7);
  EXPECT_EQ(a.data, auth_data::all);
  EXPECT_FALSE(a.challenge);
}

TEST_F(auth_config_file, mistakes_name_the_file_line_and_field) {
  auto loose = write("loose.key", secret, 0644);
  auto short_key = write("short.key", "0011", 0600);
  struct row {
    std::string auth;
    std::string expected;
  };
  std::vector<row> rows{
    {"auth:\n  tag_bytes: 8\n",
     "robot.yaml:4: auth.key_file: missing (required: the path of a key file)"},
    {"auth:\n  key_file: " + key + "\n  tag_bytes: 12\n",
     "robot.yaml:6: auth.tag_bytes: expected 8 or 16, got '12'"},
    {"auth:\n  key_file: " + key + "\n  data: some\n",
     "robot.yaml:6: auth.data: expected discovery or all, got 'some'"},
    {"auth:\n  key_file: " + key + "\n  challenge: maybe\n",
     "robot.yaml:6: auth.challenge: expected true or false, got 'maybe'"},
    {"auth:\n  key_file: " + key + "\n  key: " + secret + "\n",
     "robot.yaml:6: auth.key: unknown key"},
    {"auth:\n  key_file: " + loose + "\n",
     "robot.yaml:5: auth.key_file: " + loose
       + ": key file has mode 0644: group or others may access it"},
    {"auth:\n  key_file: " + short_key + "\n",
     "robot.yaml:5: auth.key_file: " + short_key
       + ": key file holds a key of 2 bytes"},
    {"auth:\n  key_file: " + dir + "/missing\n",
     "robot.yaml:5: auth.key_file: " + dir
       + "/missing: key file cannot be opened: No such file or directory"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.auth);
    auto err = error_of(doc(r.auth));
    EXPECT_EQ(err.substr(0, r.expected.size()), r.expected) << err;
    EXPECT_EQ(err.find(secret), std::string::npos) << "the key leaked: " << err;
  }
}

// -- remote control without a key ----------------------------------------------------

TEST_F(auth_config_file, unsigned_remote_control_is_off_unless_a_keyless_config_allows_it) {
  auto plain = parse_config(doc(""), "robot.yaml");
  ASSERT_TRUE(plain) << render(plain.error());
  EXPECT_FALSE(plain->module.apps.allow_unsigned_remote);
  auto allowed = parse_config(
    doc("control:\n  allow_unsigned_remote: true\n"), "robot.yaml");
  ASSERT_TRUE(allowed) << render(allowed.error());
  EXPECT_TRUE(allowed->module.apps.allow_unsigned_remote);
  EXPECT_EQ(error_of(doc("control:\n  allow_unsigned_remote: maybe\n")),
            "robot.yaml:5: control.allow_unsigned_remote: expected true or "
            "false, got 'maybe'");
  // A keyed module takes remote control only signed, in either order of
  // the sections.
  auto msg = "robot.yaml:5: control.allow_unsigned_remote: expected false "
             "with auth (a keyed module takes remote control only signed), "
             "got 'true'";
  EXPECT_EQ(error_of(doc("control:\n  allow_unsigned_remote: true\nauth:\n"
                         "  key_file: " + key + "\n")),
            msg);
  EXPECT_EQ(error_of(doc("auth:\n  key_file: " + key
                         + "\ncontrol:\n  allow_unsigned_remote: true\n")),
            std::string{msg}.replace(std::string{msg}.find(":5:"), 3, ":7:"));
  auto off = parse_config(doc("control:\n  allow_unsigned_remote: false\nauth:\n"
                              "  key_file: " + key + "\n"),
                          "robot.yaml");
  EXPECT_TRUE(off) << render(off.error());
}
