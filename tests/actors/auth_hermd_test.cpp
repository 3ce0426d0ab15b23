// A keyed network of real hermd processes on UDP loopback: two modules with
// the key find each other; an intruder without the key (or with another
// key) on the same medium is ignored: no route to it, and its hellos are
// counted as refused (hermctl stats); one unsigned datagram from a host
// without the key cannot control a module (remote control must be signed).
// Every wait is bounded; nothing asserts on timing.

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/make_message.hpp"

#include "actors/marshal.hpp"
#include "actors/runtime/system.hpp"
#include "channels/testing/loopback.hpp"
#include "tests/adversarial/hostile_peer.hpp"
#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string hermd = HERMD_BIN;
const std::string hermctl = HERMCTL_BIN;

std::string lo(uint16_t port) {
  return "127.0.0.1:" + std::to_string(port);
}

class auth_hermd : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-auth-hermd-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
  }

  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::string write(const std::string& name, const std::string& text,
                    mode_t mode = 0644) {
    auto path = dir_ + "/" + name;
    std::ofstream{path} << text;
    ::chmod(path.c_str(), mode);
    return path;
  }

  std::string sock(const std::string& name) const {
    return dir_ + "/" + name + ".sock";
  }

  /// A module with one UDP channel to `peers`, keyed with `key_file` unless
  /// it is empty.
  std::string module(const std::string& name, const std::string& id,
                     uint16_t port, const std::vector<uint16_t>& peers,
                     const std::string& key_file) {
    std::string list;
    for (auto p : peers)
      list += (list.empty() ? "" : ", ") + lo(p);
    std::string text = "module:\n  name: " + name + "\n  id: " + id
                       + "\n  hello_interval_ms: 100\ncontrol:\n  socket: "
                       + sock(name)
                       + "\nchannels:\n  - name: eth0\n    kind: udp\n"
                         "    interface: "
                       + lo(port) + "\n    peers: [" + list + "]\n";
    if (!key_file.empty())
      text += "auth:\n  key_file: " + key_file + "\n";
    return write(name + ".yaml", text);
  }

  /// hermctl with `args` against module `name`'s socket: exit status and
  /// output (stderr merged).
  std::pair<int, std::string> ctl(const std::string& name,
                                  const std::string& args) {
    child_process p{{"/bin/sh", "-c",
                     hermctl + " -s " + sock(name) + " " + args + " 2>&1"}};
    auto status = p.wait(30s);
    return {status, p.output()};
  }

  /// The routing stats of module `name` (hermctl stats --json), or null.
  nlohmann::json routing_stats(const std::string& name) {
    child_process p{{"/bin/sh", "-c",
                     hermctl + " -s " + sock(name) + " stats --json 2>&1"}};
    if (p.wait(30s) != 0)
      return nullptr;
    auto j = nlohmann::json::parse(p.output(), nullptr, false);
    if (j.is_discarded())
      return nullptr;
    // Find the object holding rx_auth_failed wherever hermctl nests it.
    std::function<nlohmann::json(const nlohmann::json&)> find
      = [&](const nlohmann::json& x) -> nlohmann::json {
      if (x.is_object()) {
        if (x.contains("rx_auth_failed"))
          return x;
        for (auto& [k, v] : x.items())
          if (auto r = find(v); !r.is_null())
            return r;
      }
      if (x.is_array())
        for (auto& v : x)
          if (auto r = find(v); !r.is_null())
            return r;
      return nullptr;
    };
    return find(j);
  }

  std::string dir_;
};

} // namespace

TEST_F(auth_hermd, an_intruder_without_the_key_is_ignored) {
  auto key = write("net.key",
                   "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff\n",
                   0600);
  auto other = write("other.key",
                     "ffeeddccbbaa99887766554433221100ffeeddccbbaa998877665544\n",
                     0600);
  for (std::string intruder_key : {std::string{}, other}) {
    SCOPED_TRACE(intruder_key.empty() ? "intruder without a key"
                                      : "intruder with another key");
    auto pa = free_udp_port(), pb = free_udp_port(), px = free_udp_port();
    child_process a{{hermd, module("a", "0x21", pa, {pb, px}, key)}};
    child_process b{{hermd, module("b", "0x22", pb, {pa, px}, key)}};
    child_process x{{hermd, module("x", "0x66", px, {pa, pb}, intruder_key)}};
    auto learned = a.wait_for_line_containing("route to 0x22:", 10s);
    ASSERT_TRUE(learned) << a.output();
    // Bounded wait until a has refused some of the intruder's hellos.
    nlohmann::json st;
    for (int i = 0; i < 100; ++i) {
      st = routing_stats("a");
      if (!st.is_null() && st["rx_auth_failed"].get<uint64_t>() > 0)
        break;
      std::this_thread::sleep_for(100ms);
    }
    ASSERT_FALSE(st.is_null()) << a.output();
    EXPECT_GT(st["rx_auth_failed"].get<uint64_t>(), 0u) << st.dump();
    EXPECT_GT(st["tx_signed"].get<uint64_t>(), 0u) << st.dump();
    // a reaches b only; the intruder never became a route.
    EXPECT_EQ(st["reachable"].get<uint64_t>(), 1u) << st.dump();
    EXPECT_EQ(a.output().find("route to 0x66"), std::string::npos) << a.output();
    auto xs = routing_stats("x");
    ASSERT_FALSE(xs.is_null()) << x.output();
    EXPECT_EQ(xs["reachable"].get<uint64_t>(), 0u) << xs.dump();
    // The key never shows in a log.
    EXPECT_EQ(a.output().find("00112233445566778899"), std::string::npos);
  }
}

// Finding 3 of issue 14: with the key and the default `auth.data:
// discovery`, one unsigned datagram from a host without the key delivered
// `link eth0 down` to a module's control service. Now the request is
// refused (counted, answered with `unauthorized`) and the link stays up,
// while the keyed neighbour still controls the module remotely (signed).
TEST_F(auth_hermd, an_unsigned_datagram_cannot_control_a_keyed_module) {
  auto key = write("net.key",
                   "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff\n",
                   0600);
  hostile_socket x;
  ASSERT_TRUE(x.ok());
  auto pa = free_udp_port(), pb = free_udp_port();
  child_process a{{hermd, module("a", "0x21", pa, {pb, x.port()}, key)}};
  child_process b{{hermd, module("b", "0x22", pb, {pa}, key)}};
  ASSERT_TRUE(a.wait_for_line_containing("route to 0x22:", 10s)) << a.output();
  // The keyed neighbour's remote control works (bounded retries while the
  // control services discover each other).
  std::pair<int, std::string> remote;
  for (int i = 0; i < 50; ++i) {
    remote = ctl("b", "--module 0x21 info");
    if (remote.first == 0)
      break;
    std::this_thread::sleep_for(100ms);
  }
  ASSERT_EQ(remote.first, 0) << remote.second;
  // What a sniffer learns: the control APO's number.
  auto [st, apps] = ctl("a", "apps --json");
  ASSERT_EQ(st, 0) << apps;
  uint32_t apo = 0;
  for (auto& row : nlohmann::json::parse(apps))
    if (row["name"] == "herm.control" && row["local"] == true)
      apo = row["apo"].get<uint32_t>();
  ASSERT_NE(apo, 0u) << apps;
  // The forged command, claiming to come from b, unsigned.
  caf::actor_system_config cfg;
  herm::configure_for_testing(cfg);
  caf::actor_system sys{cfg};
  auto payload = herm::marshal(
    sys, caf::make_message(std::string{R"({"cmd":"link","device":"eth0","state":"down"})"}));
  ASSERT_TRUE(payload);
  for (int i = 0; i < 3; ++i)
    ASSERT_TRUE(x.send(pa, asl_frame(0x22, 0x21,
                                     herm::asl_request{7 + uint64_t(i), apo,
                                                       *payload})));
  // Counted as refused; the channel stays up and b stays reachable.
  nlohmann::json stats;
  for (int i = 0; i < 100; ++i) {
    auto [s2, out] = ctl("a", "stats --json");
    stats = nlohmann::json::parse(out, nullptr, false);
    if (s2 == 0 && !stats.is_discarded()
        && stats["apps"]["rx_unauthorized"].get<uint64_t>() >= 3)
      break;
    std::this_thread::sleep_for(100ms);
  }
  ASSERT_FALSE(stats.is_discarded());
  EXPECT_GE(stats["apps"]["rx_unauthorized"].get<uint64_t>(), 3u) << stats.dump();
  auto [s3, channels] = ctl("a", "channels --json");
  ASSERT_EQ(s3, 0) << channels;
  auto rows = nlohmann::json::parse(channels);
  ASSERT_EQ(rows.size(), 1u) << channels;
  EXPECT_EQ(rows[0]["state"], "up") << channels;
  EXPECT_EQ(a.output().find("eth0 down"), std::string::npos);
  EXPECT_EQ(ctl("b", "ping 0x21").first, 0);
}
