// A keyed network of real hermd processes on UDP loopback: two modules with
// the key find each other; an intruder without the key (or with another
// key) on the same medium is ignored: no route to it, and its hellos are
// counted as refused (hermctl stats). Every wait is bounded; nothing
// asserts on timing.

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "channels/testing/loopback.hpp"
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
