// hermctl's discovery of the modules on this machine
// (apps/hermctl/local_modules.hpp): which socket it picks from what the
// runtime directory holds, what it says, and what a scan of a real
// directory finds (live, stale and non-socket files).

#include <gtest/gtest.h>

#include <stdlib.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "apps/hermctl/local_modules.hpp"

using namespace hermctl;
namespace fs = std::filesystem;

namespace {

local_socket live(const std::string& name) {
  return {name, "/run/herm/" + name + ".sock", true};
}

local_socket dead(const std::string& name) {
  return {name, "/run/herm/" + name + ".sock", false};
}

struct choice_case {
  const char* what;
  std::vector<local_socket> sockets;
  module_choice::kind_t kind;
  std::string chosen;
};

/// A Unix socket bound at `path`: listening (live) or closed without
/// removing its file (stale, as a module that died leaves it).
int bind_socket(const std::string& path, bool listening) {
  int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.data(), path.size());
  EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0) << path;
  if (listening) {
    EXPECT_EQ(::listen(fd, 4), 0);
    return fd;
  }
  ::close(fd);
  return -1;
}

} // namespace

TEST(hermctl_local_modules, choice_follows_the_live_sockets) {
  std::vector<choice_case> cases{
    {"nothing", {}, module_choice::none, ""},
    {"only stale sockets", {dead("a"), dead("hermd")}, module_choice::none, ""},
    {"one live", {live("sensor")}, module_choice::use, "sensor"},
    {"one live among stale ones", {dead("a"), live("b"), dead("hermd")},
     module_choice::use, "b"},
    {"several, one of them hermd", {live("a"), live("hermd"), live("z")},
     module_choice::use, "hermd"},
    {"several, hermd stale", {live("a"), dead("hermd"), live("z")},
     module_choice::ambiguous, ""},
    {"several, no hermd", {live("a"), live("b")}, module_choice::ambiguous, ""},
  };
  for (auto& c : cases) {
    auto got = choose_module(c.sockets);
    EXPECT_EQ(got.kind, c.kind) << c.what;
    if (c.kind == module_choice::use) {
      EXPECT_EQ(got.chosen.name, c.chosen) << c.what;
    }
  }
}

TEST(hermctl_local_modules, the_preferred_name_can_be_another_than_hermd) {
  auto got = choose_module({live("a"), live("hermd"), live("b")}, "b");
  EXPECT_EQ(got.kind, module_choice::use);
  EXPECT_EQ(got.chosen.path, "/run/herm/b.sock");
}

TEST(hermctl_local_modules, says_which_module_it_uses) {
  EXPECT_EQ(using_line({"sensor", "/run/user/0/herm/sensor.sock", true}),
            "hermctl: using module 'sensor' (/run/user/0/herm/sensor.sock)");
}

TEST(hermctl_local_modules, ambiguity_names_the_live_modules_and_the_way_out) {
  EXPECT_EQ(ambiguous_message({live("a"), dead("b"), live("c")}, "/run/herm"),
            "2 modules run here (a, c; in /run/herm): choose one with --name "
            "NAME or -s PATH (hermctl modules lists them)");
}

TEST(hermctl_local_modules, ambiguity_counts_names_past_eight) {
  std::vector<local_socket> many;
  for (char c = 'a'; c <= 'k'; ++c)
    many.push_back(live(std::string(1, c)));
  EXPECT_EQ(ambiguous_message(many, "/d"),
            "11 modules run here (a, b, c, d, e, f, g, h and 3 more; in /d): "
            "choose one with --name NAME or -s PATH (hermctl modules lists "
            "them)");
}

TEST(hermctl_local_modules, runtime_dir_is_herm_runtime_dir_when_set) {
  auto* old = std::getenv("HERM_RUNTIME_DIR");
  std::string saved = old != nullptr ? old : "";
  ::setenv("HERM_RUNTIME_DIR", "/tmp/herm-rt", 1);
  EXPECT_EQ(runtime_dir(), "/tmp/herm-rt");
  EXPECT_EQ(socket_of("alpha"), "/tmp/herm-rt/alpha.sock");
  ::setenv("HERM_RUNTIME_DIR", "", 1);
  EXPECT_NE(runtime_dir(), "");
  EXPECT_EQ(socket_of("alpha"), runtime_dir() + "/alpha.sock");
  if (old != nullptr)
    ::setenv("HERM_RUNTIME_DIR", saved.c_str(), 1);
  else
    ::unsetenv("HERM_RUNTIME_DIR");
}

TEST(hermctl_local_modules, a_scan_finds_sockets_sorted_and_tells_live_from_stale) {
  char tmpl[] = "/tmp/herm-lm-XXXXXX";
  std::string dir = ::mkdtemp(tmpl);
  int b = bind_socket(dir + "/beta.sock", true);
  int a = bind_socket(dir + "/alpha.sock", true);
  bind_socket(dir + "/gone.sock", false);
  int other = bind_socket(dir + "/not-a-module", true);
  std::ofstream{dir + "/file.sock"} << "not a socket";
  fs::create_directory(dir + "/dir.sock");
  auto found = scan_runtime_dir(dir);
  std::vector<local_socket> expected{{"alpha", dir + "/alpha.sock", true},
                                     {"beta", dir + "/beta.sock", true},
                                     {"gone", dir + "/gone.sock", false}};
  EXPECT_EQ(found, expected);
  EXPECT_TRUE(is_live(dir + "/alpha.sock"));
  EXPECT_FALSE(is_live(dir + "/gone.sock"));
  EXPECT_FALSE(is_live(dir + "/no-such.sock"));
  EXPECT_EQ(choose_module(found).kind, module_choice::ambiguous);
  ::close(a);
  ::close(b);
  ::close(other);
  fs::remove_all(dir);
}

TEST(hermctl_local_modules, a_missing_directory_has_no_sockets) {
  EXPECT_TRUE(scan_runtime_dir("/tmp/herm-no-such-runtime-dir/x").empty());
}

TEST(hermctl_local_modules, the_listing_shows_each_module_and_who_did_not_answer) {
  std::ostringstream out;
  show_modules(out,
               {{"alpha", "0x30", "/r/alpha.sock", ""},
                {"mute", "-", "/r/mute.sock", "no reply from /r/mute.sock within 300 ms"}},
               "/r", false);
  EXPECT_EQ(out.str(), "NAME   MODULE  SOCKET\n"
                       "alpha  0x30    /r/alpha.sock\n"
                       "mute   -       /r/mute.sock\n"
                       "/r/mute.sock: no reply from /r/mute.sock within 300 ms\n");
}

TEST(hermctl_local_modules, an_empty_listing_says_where_it_looked) {
  std::ostringstream out;
  show_modules(out, {}, "/run/herm", false);
  EXPECT_EQ(out.str(), "no modules running (no live control socket in /run/herm)\n");
  std::ostringstream j;
  show_modules(j, {}, "/run/herm", true);
  EXPECT_EQ(j.str(), "[]\n");
}

TEST(hermctl_local_modules, the_json_listing_has_null_for_an_unknown_id) {
  std::ostringstream out;
  show_modules(out, {{"mute", "-", "/r/mute.sock", "timeout"}}, "/r", true);
  auto j = nlohmann::json::parse(out.str());
  ASSERT_EQ(j.size(), 1u);
  EXPECT_TRUE(j[0]["module"].is_null());
  EXPECT_EQ(j[0]["socket"], "/r/mute.sock");
  EXPECT_EQ(j[0]["error"], "timeout");
}
