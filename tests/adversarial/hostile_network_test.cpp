// The adversarial suite: hostile traffic at running hermd processes.
//
// Two real modules, a (0x21, the victim) and b (0x22, its legitimate
// neighbour), talk over UDP on loopback. An attacker on the same segment,
// without any key, sends what one host can send: garbage, malformed frames,
// floods of routes, neighbours, fragments and application messages. Every
// test asserts the same four things:
//   - no crash: a is still running when the attack ends;
//   - bounded memory: a's peak resident set stays below a documented bound
//     (watched while the attack runs; the watchdog kills a long before the
//     machine would notice, and the test then fails);
//   - legitimate traffic keeps flowing: a still reaches b (`hermctl ping`)
//     and still answers hermctl;
//   - every refusal is counted: the counter named in docs/reliability.md's
//     "attack / bound / counter / test" table grows.
// Every attack is bounded in datagrams and seconds; only loopback carries
// it. Nothing asserts on timing.

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <thread>

#include <nlohmann/json.hpp>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/message.hpp"

#include "actors/marshal.hpp"
#include "actors/runtime/system.hpp"
#include "channels/testing/loopback.hpp"
#include "tests/adversarial/hostile_peer.hpp"
#include "tests/support/process.hpp"

using namespace herm;
using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

const std::string hermd = HERMD_BIN;
const std::string hermctl = HERMCTL_BIN;

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool sanitized = true;
#elif defined(__has_feature)
#  if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
constexpr bool sanitized = true;
#  else
constexpr bool sanitized = false;
#  endif
#else
constexpr bool sanitized = false;
#endif

/// The documented bound on a module's peak resident memory under attack
/// (docs/reliability.md): an idle hermd holds about 11 MiB. Sanitizer
/// builds keep freed memory in quarantine and shadow every byte, so there
/// only the watchdog's limit applies.
constexpr uint64_t memory_bound_kib = 64 * 1024;

/// The watchdog: far above the bound, far below what hurts the machine.
constexpr uint64_t watchdog_kib = 1024 * 1024;

struct memory {
  uint64_t rss_kib = 0;
  uint64_t peak_kib = 0;
};

memory memory_of(pid_t pid) {
  memory m;
  std::ifstream in{"/proc/" + std::to_string(pid) + "/status"};
  std::string key;
  while (in >> key) {
    if (key == "VmRSS:")
      in >> m.rss_kib;
    else if (key == "VmHWM:")
      in >> m.peak_kib;
    in.ignore(1 << 20, '\n');
  }
  return m;
}

/// The first object in `x` (depth first) that has `key`, or null.
json find_holder(const json& x, const std::string& key) {
  if (x.is_object()) {
    if (x.contains(key))
      return x;
    for (auto& [k, v] : x.items())
      if (auto r = find_holder(v, key); !r.is_null())
        return r;
  }
  if (x.is_array())
    for (auto& v : x)
      if (auto r = find_holder(v, key); !r.is_null())
        return r;
  return nullptr;
}

/// Sum of every number named `key` anywhere in `x` (per-channel counters).
uint64_t sum_of(const json& x, const std::string& key) {
  uint64_t n = 0;
  if (x.is_object()) {
    for (auto& [k, v] : x.items()) {
      if (k == key && v.is_number_unsigned())
        n += v.get<uint64_t>();
      else
        n += sum_of(v, key);
    }
  }
  if (x.is_array())
    for (auto& v : x)
      n += sum_of(v, key);
  return n;
}

class hostile_network : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-hostile-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
    pa_ = free_udp_port();
    pb_ = free_udp_port();
  }

  void TearDown() override {
    a_.reset();
    b_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  /// hermd with its log in a file: a pipe nobody reads while an attack
  /// runs would fill and block the daemon in write(), which is not what is
  /// under test. (exec keeps the pid hermd's.)
  std::vector<std::string> daemon(const std::string& name,
                                   const std::string& config_file) const {
    return {"/bin/sh", "-c",
            "exec " + hermd + " " + config_file + " >" + dir_ + "/" + name
              + ".log 2>&1"};
  }

  /// What module `name` logged so far (its last 8 KiB).
  std::string log(const std::string& name) const {
    std::ifstream in{dir_ + "/" + name + ".log"};
    std::string text{std::istreambuf_iterator<char>{in}, {}};
    return text.size() > 8192 ? text.substr(text.size() - 8192) : text;
  }

  std::string sock(const std::string& name) const {
    return dir_ + "/" + name + ".sock";
  }

  std::string config(const std::string& name, const std::string& id,
                     uint16_t port, uint16_t peer, const std::string& extra) {
    auto path = dir_ + "/" + name + ".yaml";
    std::ofstream{path} << "module:\n  name: " << name << "\n  id: " << id
                        << "\n  hello_interval_ms: 200\ncontrol:\n  socket: "
                        << sock(name) << "\n"
                        // b's control service answers a's pings (the
                        // legitimate traffic); a, the victim, keeps the
                        // default: no remote control without a key.
                        << (name == "b" && extra.find("auth:") == std::string::npos
                              ? "  allow_unsigned_remote: true\n"
                              : "")
                        << extra
                        << "channels:\n  - name: eth0\n    kind: udp\n"
                           "    interface: 127.0.0.1:"
                        << port << "\n    peers: [127.0.0.1:" << peer << "]\n";
    return path;
  }

  /// Starts a and b (each with `extra` YAML before its channels) and waits,
  /// bounded, until a reaches b.
  void start(const std::string& extra_a = "", const std::string& extra_b = "") {
    a_.emplace(daemon("a", config("a", "0x21", pa_, pb_, extra_a)));
    b_.emplace(daemon("b", config("b", "0x22", pb_, pa_, extra_b)));
    for (int i = 0; i < 150; ++i) {
      auto st = stats();
      if (!st.is_null() && st.value("reachable", 0u) >= 1u)
        return;
      std::this_thread::sleep_for(100ms);
    }
    FAIL() << "a never reached b:\n" << log("a") << "\nb:\n" << log("b");
  }

  /// `hermctl -s a.sock ARGS --json`, parsed; null when it failed.
  json ctl(const std::string& args, const std::string& who = "a") {
    child_process p{{"/bin/sh", "-c",
                     hermctl + " -s " + sock(who) + " " + args
                       + " --json 2>/dev/null"}};
    if (p.wait(30s) != 0)
      return nullptr;
    auto j = json::parse(p.output(), nullptr, false);
    return j.is_discarded() ? json{nullptr} : j;
  }

  /// a's routing counters.
  json stats() {
    auto st = ctl("stats");
    return st.is_null() ? st : find_holder(st, "rx_refused_routes");
  }

  /// Every counter a shows, whole.
  json all_stats() {
    return ctl("stats");
  }

  /// a still reaches b, end to end (an echo through b's control service).
  bool a_reaches_b() {
    for (int i = 0; i < 3; ++i) {
      auto r = ctl("ping 0x22 -c 1");
      if (!r.is_null() && r.value("received", 0) > 0)
        return true;
      std::this_thread::sleep_for(200ms);
    }
    return false;
  }

  /// Runs `attack` while a watchdog samples a's memory every 20 ms (and
  /// kills a past watchdog_kib); returns a's peak.
  uint64_t under_attack(const std::function<void()>& attack) {
    std::atomic<bool> done{false};
    std::atomic<uint64_t> peak{0};
    auto pid = a_->pid();
    std::thread watchdog{[&] {
      while (!done) {
        auto m = memory_of(pid);
        peak = std::max<uint64_t>(peak, m.peak_kib);
        if (m.rss_kib > watchdog_kib)
          ::kill(pid, SIGKILL);
        std::this_thread::sleep_for(20ms);
      }
    }};
    attack();
    done = true;
    watchdog.join();
    return std::max<uint64_t>(peak, memory_of(pid).peak_kib);
  }

  /// What every test asserts after its attack. The peak is read again
  /// after a answered: what the attack queued is processed by then.
  void expect_survived(uint64_t peak_kib) {
    ASSERT_TRUE(a_->running()) << "a died under attack:\n" << log("a");
    EXPECT_FALSE(stats().is_null()) << "a stopped answering hermctl";
    EXPECT_TRUE(a_reaches_b()) << "legitimate traffic stopped:\n" << log("a");
    ASSERT_TRUE(a_->running()) << "a died under attack:\n" << log("a");
    peak_kib = std::max(peak_kib, memory_of(a_->pid()).peak_kib);
    RecordProperty("peak_kib", std::to_string(peak_kib));
    std::cout << "[ adversarial ] a's peak resident memory: " << peak_kib
              << " KiB" << std::endl;
    if (!sanitized) {
      EXPECT_LT(peak_kib, memory_bound_kib) << "bound in docs/reliability.md";
    }
  }

  std::string dir_;
  uint16_t pa_ = 0;
  uint16_t pb_ = 0;
  std::optional<child_process> a_;
  std::optional<child_process> b_;
};

} // namespace

// Finding 1 of issue 14: one fake neighbour (a hello, then updates of 24
// origins each) advertising 50,000 destinations drove hermd to 24 GB. Now
// the table keeps its bound, refuses the rest with a counter, and keeps
// serving its real routes.
TEST_F(hostile_network, a_fake_neighbour_advertising_50000_destinations_is_bounded) {
  start();
  hostile_socket x;
  ASSERT_TRUE(x.ok());
  constexpr module_id fake = 0x66;
  constexpr uint64_t instance = 0x0BADC0DE;
  constexpr size_t destinations = 50000;
  auto peak = under_attack([&] {
    uint16_t seqno = 1;
    x.send(pa_, hello_frame(fake, instance, seqno++, 200));
    std::this_thread::sleep_for(50ms);
    size_t sent = 0;
    module_id first = 0x0100;
    while (sent < destinations) {
      auto n = std::min(max_update_entries, destinations - sent);
      x.send(pa_, update_frame(fake, instance,
                               static_cast<module_id>(first + sent), n));
      sent += n;
      // Paced so that the kernel's receive buffer keeps most of it (the
      // attack must reach the table to test its bound), with hellos that
      // keep the fake neighbour alive.
      if (sent % (max_update_entries * 64) == 0) {
        x.send(pa_, hello_frame(fake, instance, seqno++, 200));
        x.drain();
        // Sanitized daemons run several times slower.
        std::this_thread::sleep_for(sanitized ? 100ms : 5ms);
      }
    }
    // Hold the fake neighbour for two more hello intervals: the table is
    // full while the module answers hermctl below.
    for (int i = 0; i < 4; ++i) {
      x.send(pa_, hello_frame(fake, instance, seqno++, 200));
      x.drain();
      std::this_thread::sleep_for(100ms);
    }
  });
  expect_survived(peak);
  auto st = stats();
  ASSERT_FALSE(st.is_null());
  EXPECT_GT(st.value("rx_routes_over_limit", uint64_t{0}), 0u) << st.dump();
  // One neighbour fills its share first, leaving room for the others.
  EXPECT_GT(st.value("rx_routes_over_share", uint64_t{0}), 0u) << st.dump();
  EXPECT_LE(st.value("destinations", uint64_t{0}), 4096u) << st.dump();
  EXPECT_LE(st.value("reachable", uint64_t{0}), 4096u) << st.dump();
}

// Garbage of every shape on the channel: empty and random datagrams, frames
// with reserved bits set, length fields that overrun, first frames
// announcing megabytes, truncated and unknown network packets. Each is
// dropped and counted below the routing agent or by it.
TEST_F(hostile_network, malformed_frames_are_dropped_and_counted) {
  start();
  hostile_socket x;
  ASSERT_TRUE(x.ok());
  std::mt19937 rng{14};
  auto peak = under_attack([&] {
    for (int i = 0; i < 4000; ++i) {
      byte_buffer frame;
      switch (i % 8) {
        case 0: // random bytes of random length
          frame.resize(rng() % 1400);
          for (auto& b : frame)
            b = static_cast<uint8_t>(rng());
          break;
        case 1: // a single frame with reserved bits set
          frame = {0x0F, 0x10, 0x01, 0x21, 0x00};
          break;
        case 2: // a first frame announcing 2 MiB, LEB128 FF FF 7F
          frame = {0x40, 0xFF, 0xFF, 0x7F, 0x01, 0x02};
          break;
        case 3: // a length field that runs past the frame
          frame = {0x40, 0xFF, 0xFF};
          break;
        case 4: // a single frame holding an unknown packet version
          frame = {0x00, 0xF1, 0x00, 0x00};
          break;
        case 5: // a truncated update claiming 24 entries
          frame = {0x00, 0x12, 0x66, 0x00, 1, 2, 3, 4, 5, 6, 7, 8, 24};
          break;
        case 6: // a consecutive frame with no packet, random sequence
          frame = {static_cast<uint8_t>(0x80 | (rng() % 64)), 1, 2, 3};
          break;
        case 7: // a malformed bundle
          frame = {0x01, 0xFF, 0xFF, 0xFF, 0x0F};
          break;
      }
      x.send(pa_, frame);
      if (i % 256 == 255) {
        x.drain();
        std::this_thread::sleep_for(2ms);
      }
    }
  });
  expect_survived(peak);
  auto all = all_stats();
  ASSERT_FALSE(all.is_null());
  // Dropped below the routing agent (the fragment layer) or by it.
  EXPECT_GT(sum_of(all, "rx_malformed"), 0u) << all.dump();
}

// Fragments: first frames of large packets from many source ports, never
// completed, must not pin memory: the reassembly bounds refuse or evict
// them and count it.
TEST_F(hostile_network, unfinished_fragments_from_many_senders_are_bounded) {
  start();
  std::vector<hostile_socket> xs;
  for (int i = 0; i < 64; ++i) {
    xs.emplace_back();
    ASSERT_TRUE(xs.back().ok());
  }
  auto peak = under_attack([&] {
    byte_buffer first(1400, 0xA5);
    first[0] = 0x40 | 0x08; // first frame, wide sequence numbers
    // LEB128 60,000: 0xE0 0xD4 0x03.
    first[1] = 0xE0;
    first[2] = 0xD4;
    first[3] = 0x03;
    for (int round = 0; round < 8; ++round) {
      for (auto& x : xs) {
        for (uint8_t tag = 0; tag < 4; ++tag) {
          first[0] = static_cast<uint8_t>(0x48 | (tag << 4));
          x.send(pa_, first);
        }
        x.drain();
      }
      std::this_thread::sleep_for(5ms);
    }
  });
  expect_survived(peak);
  auto all = all_stats();
  ASSERT_FALSE(all.is_null());
  EXPECT_GT(sum_of(all, "rx_reassembly_dropped"), 0u) << all.dump();
}

// Neighbours: hellos from many source ports, each a different sender id,
// and one port that restarts (a new instance) with every hello, which would
// make a send its whole table each time. The neighbour table keeps its
// bound; a's real neighbour stays.
TEST_F(hostile_network, hello_storms_from_many_ports_and_instances_are_bounded) {
  start();
  std::vector<hostile_socket> xs;
  for (int i = 0; i < 300; ++i) {
    xs.emplace_back();
    ASSERT_TRUE(xs.back().ok());
  }
  auto peak = under_attack([&] {
    for (int round = 0; round < 3; ++round) {
      for (size_t i = 0; i < xs.size(); ++i) {
        xs[i].send(pa_, hello_frame(static_cast<module_id>(0x1000 + i),
                                    0xFEED0000 + i, round, 200));
        xs[i].drain();
      }
      std::this_thread::sleep_for(20ms);
    }
    hostile_socket restarter;
    for (uint64_t i = 0; i < 2000; ++i) {
      restarter.send(pa_, hello_frame(0x0777, 0xAB000000 + i, 1, 200));
      if (i % 100 == 99) {
        restarter.drain();
        std::this_thread::sleep_for(5ms);
      }
    }
  });
  expect_survived(peak);
  auto st = stats();
  ASSERT_FALSE(st.is_null());
  // 300 new neighbours on one channel: past the per-channel share.
  EXPECT_GT(st.value("rx_neighbours_over_limit", uint64_t{0}), 0u) << st.dump();
}

// Flooded control packets: claims, conflicts and seqno requests with fresh
// ids (each new one is relayed to every neighbour once, so a relays them to
// b: the flood caches must stay bounded and never drop a's own traffic).
TEST_F(hostile_network, floods_of_claims_conflicts_and_seqno_requests_are_bounded) {
  start();
  hostile_socket x;
  ASSERT_TRUE(x.ok());
  x.send(pa_, hello_frame(0x66, 0x5EED, 1, 200));
  auto peak = under_attack([&] {
    for (uint32_t i = 0; i < 6000; ++i) {
      byte_buffer packet;
      switch (i % 3) {
        case 0:
          encode(claim{static_cast<module_id>(0x0100 + i), 0x1000000ull + i,
                       0x2000000ull + i, 4},
                 packet);
          break;
        case 1:
          encode(conflict{static_cast<module_id>(0x0100 + i), 0x3000000ull + i,
                          0x4000000ull + i, 0x5000000ull + i, 4},
                 packet);
          break;
        case 2:
          encode(seqno_request{0x66, static_cast<module_id>(0x0100 + i),
                               static_cast<seqno_t>(i), 4},
                 packet);
          break;
      }
      x.send(pa_, single_frame(packet));
      // In bursts of 1,500: more distinct floods within the suppression
      // window (half a hello interval) than the flood memory holds.
      if (i % 1500 == 1499) {
        x.send(pa_, hello_frame(0x66, 0x5EED, 1, 200));
        x.drain();
        std::this_thread::sleep_for(5ms);
      }
    }
  });
  expect_survived(peak);
  // The flood memory's own bound (4,096 within half a hello interval) is
  // driven past deterministically in routing_bounds_test; here, where the
  // kernel's receive buffer limits what arrives, every datagram is
  // accounted for: received by the channel, or counted as a kernel drop
  // (reported with the next datagram: the hellos after each burst) or as a
  // drop at the channel's inbound queue.
  std::this_thread::sleep_for(50ms);
  x.send(pa_, hello_frame(0x66, 0x5EED, 1, 200));
  std::this_thread::sleep_for(100ms);
  auto all = all_stats();
  ASSERT_FALSE(all.is_null());
  EXPECT_GE(sum_of(all, "rx_frames") + sum_of(all, "rx_kernel_dropped")
              + sum_of(all, "rx_queue_dropped"),
            6000u + 5u)
    << all.dump();
}

// Application messages from forged module ids: flooded discovery queries
// and broadcast garbage with fresh flood ids, requests and reliable
// requests for random APO numbers with random request ids, subscriptions
// and watches from thousands of "modules". Each table they would fill in
// a's application support layer is bounded and counts what it refused.
TEST_F(hostile_network, application_message_floods_from_forged_modules_are_bounded) {
  start();
  hostile_socket x;
  ASSERT_TRUE(x.ok());
  constexpr module_id fake = 0x66;
  // A route back to the attacker, so that a answers it (and keeps state).
  x.send(pa_, hello_frame(fake, 0x5EED, 1, 200));
  std::this_thread::sleep_for(50ms);
  x.send(pa_, self_update_frame(fake, 0x5EED));
  std::mt19937_64 rng{1414};
  auto peak = under_attack([&] {
    for (uint32_t i = 0; i < 12000; ++i) {
      auto src = static_cast<module_id>(0x0100 + (i % 0xF000));
      switch (i % 8) {
        case 0:
          x.send(pa_, asl_frame(src, broadcast_module,
                                asl_query{i, query_by::any, ""}, 0x10000 + i));
          break;
        case 1: {
          byte_buffer garbage(200);
          for (auto& b : garbage)
            b = static_cast<uint8_t>(rng());
          x.send(pa_, data_frame(src, broadcast_module, asl_protocol, garbage,
                                 0x20000 + i));
          break;
        }
        case 2:
          x.send(pa_, asl_frame(fake, 0x21,
                                asl_request{rng() | 1,
                                            static_cast<uint32_t>(rng()),
                                            byte_buffer(64, 0x5A)}));
          break;
        case 3:
          x.send(pa_, asl_frame(src, 0x21,
                                asl_reliable_request{rng() | 1,
                                                     static_cast<uint32_t>(rng()),
                                                     false,
                                                     byte_buffer(64, 0x5A)}));
          break;
        case 4:
          x.send(pa_, asl_frame(src, 0x21,
                                asl_subscribe{"topic/" + std::to_string(i % 500),
                                              3600000}));
          break;
        case 5:
          x.send(pa_, asl_frame(src, 0x21,
                                asl_watch{static_cast<uint32_t>(rng())}));
          break;
        case 6:
          x.send(pa_, asl_frame(src, 0x21,
                                asl_response{rng() | 1, true, byte_buffer(8, 1),
                                             {}}));
          break;
        case 7:
          x.send(pa_, asl_frame(src, broadcast_module,
                                asl_advertise{"topic/" + std::to_string(i)},
                                0x30000 + i));
          break;
      }
      if (i % 200 == 199) {
        x.send(pa_, hello_frame(fake, 0x5EED, 1, 200));
        x.drain();
        std::this_thread::sleep_for(5ms);
      }
    }
  });
  expect_survived(peak);
  auto all = all_stats();
  ASSERT_FALSE(all.is_null());
  EXPECT_GT(sum_of(all, "rx_malformed"), 0u) << all.dump();
  EXPECT_GT(sum_of(all, "rx_unexpected_response"), 0u) << all.dump();
}

// Finding 3 of issue 14: in a keyed network (default `auth.data:
// discovery`), one unsigned datagram delivered `link down` to the victim's
// control service. The attacker here knows everything a sniffer could (the
// control APO's number) and forges the request as if from b: it is refused
// and counted, and the link stays up.
TEST_F(hostile_network, a_forged_unsigned_control_request_in_a_keyed_network_is_refused) {
  auto key = dir_ + "/net.key";
  std::ofstream{key}
    << "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff\n";
  ::chmod(key.c_str(), 0600);
  auto keyed = "auth:\n  key_file: " + key + "\n";
  start(keyed, keyed);
  // The control APO's number, as a sniffer of discovery answers learns it.
  auto apps = ctl("apps");
  uint32_t control_apo = 0;
  std::function<void(const json&)> scan = [&](const json& x) {
    if (x.is_object() && x.value("name", "") == "herm.control"
        && x.contains("apo"))
      control_apo = x["apo"].get<uint32_t>();
    if (x.is_structured())
      for (auto& v : x)
        scan(v);
  };
  scan(apps);
  ASSERT_NE(control_apo, 0u) << apps.dump();
  caf::actor_system_config cfg;
  configure(cfg);
  caf::actor_system sys{cfg};
  auto payload = marshal(
    sys, caf::make_message(std::string{
           R"({"cmd":"link","device":"eth0","state":"down"})"}));
  ASSERT_TRUE(payload) << caf::to_string(payload.error());
  hostile_socket x;
  ASSERT_TRUE(x.ok());
  auto peak = under_attack([&] {
    for (uint64_t i = 0; i < 200; ++i) {
      // Forged as b's and as an unknown module's, one-way and answered.
      auto src = static_cast<module_id>(i % 2 == 0 ? 0x22 : 0x66);
      x.send(pa_, asl_frame(src, 0x21,
                            asl_request{i % 3 == 0 ? 0 : 0x1000 + i,
                                        control_apo, *payload}));
      x.send(pa_, asl_frame(src, 0x21,
                            asl_reliable_request{0x5000 + i, control_apo,
                                                 i % 2 == 0, *payload}));
    }
    std::this_thread::sleep_for(300ms);
  });
  expect_survived(peak);
  auto channels = ctl("channels");
  ASSERT_FALSE(channels.is_null());
  auto text = channels.dump();
  EXPECT_NE(text.find("\"state\":\"up\""), std::string::npos) << text;
  auto all = all_stats();
  EXPECT_GT(sum_of(all, "rx_unauthorized"), 0u) << all.dump();
}
