// The C client in a keyed network, as real processes: herm-mcu-board-keyed
// (the client's host build with HERMC_AUTH=1, apps/mcu/host) on one end of a
// paced pseudo-terminal cable at 19,200 baud, a keyed hermd (its `auth`
// section, docs/user-guide.md) on the other. With the network's key the
// board passes hermd's challenge, hermd routes to it, and its readings go to
// hermd's sonar APO (a signed flooded query, a signed answer, requests and
// responses). With another key, or none, hermd neither takes it as a
// neighbour nor routes to it, and counts what it refused (hermctl stats).
// Every wait is bounded; nothing asserts on timing.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string>
#include <thread>

#include "tests/mcu/board_fixture.hpp"

using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string board_bin = HERM_MCU_BOARD_BIN;
const std::string keyed_board_bin = HERM_MCU_BOARD_KEYED_BIN;

const std::string network_key =
  "8f1e2d3c4b5a69788796a5b4c3d2e1f00f1e2d3c4b5a69788796a5b4c3d2e1f0";
const std::string other_key =
  "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";

class board_keyed : public board_network {
protected:
  void SetUp() override {
    board_network::SetUp();
    plug({}, 23);
  }

  /// A key file as hermd wants it (hex, one line, mode 0600).
  std::string key_file(const std::string& name, const std::string& hex) {
    auto path = dir_ + "/" + name;
    std::ofstream{path} << hex << "\n";
    ::chmod(path.c_str(), 0600);
    return path;
  }

  /// Keyed hermd as the sensor module (0x40): the board's line, the sonar
  /// APO fed by the board's readings, and a collector.
  void start_sensor() {
    board_network::start_sensor("auth:\n  key_file: "
                                + key_file("net.key", network_key) + "\n");
  }

  void start_board(const std::string& bin, std::vector<std::string> args) {
    std::vector<std::string> argv{"--send", "sonar", "--period-ms", "200",
                                  "--count", "12"};
    argv.insert(argv.end(), args.begin(), args.end());
    board_network::start_board(bin, std::move(argv));
  }

  /// hermd's routing stats (`hermctl stats --json`, section routing), or
  /// null.
  nlohmann::json routing_stats() {
    auto j = nlohmann::json::parse(ctl("stats --json"), nullptr, false);
    return j.is_object() ? j.value("routing", nlohmann::json{}) : nlohmann::json{};
  }

  /// Polls hermd's routing stats until `counter` is above 0 (bounded).
  uint64_t wait_for_count(const std::string& counter) {
    uint64_t v = 0;
    for (int i = 0; i < 40 && v == 0; ++i) {
      auto s = routing_stats();
      if (s.is_object())
        v = s.value(counter, uint64_t{0});
      if (v == 0)
        std::this_thread::sleep_for(250ms);
    }
    return v;
  }

  /// The board is hermd's neighbour or in its routes.
  bool board_known() {
    return ctl("neighbors").find(board_id) != std::string::npos
           || ctl("routes").find(board_id) != std::string::npos;
  }
};

} // namespace

// The board with the network's key: both sides challenge each other, hermd
// routes to the board, and the board's readings (discovery of "sonar",
// signed both ways, then requests) reach the collector.
TEST_F(board_keyed, a_keyed_board_joins_a_keyed_hermd_and_its_readings_arrive) {
  start_sensor();
  start_board(keyed_board_bin, {"--key-file", key_file("board.key", network_key)});
  ASSERT_TRUE(board_->wait_for_line("ready 0x0A04 keyed", 1s)) << board_->output();
  auto route = sensor_->wait_for_line_containing("route to " + board_id + ":", 20s);
  ASSERT_TRUE(route) << sensor_->output() << board_->output();
  // 12 readings (counted once sent: "sonar" is discovered after the
  // challenges' round trip) make 4 batches; the third is enough here.
  auto batch = sensor_->wait_for_line_containing(
    "collector: sonar batch 3 from sensor: 3 readings", 30s);
  ASSERT_TRUE(batch) << sensor_->output() << board_->output();
  EXPECT_TRUE(board_->wait_for_line("response 12 ok", 10s)) << board_->output();
  auto s = routing_stats();
  ASSERT_TRUE(s.is_object()) << ctl("stats --json");
  EXPECT_GT(s.value("tx_challenges", uint64_t{0}), 0u) << s.dump();
  EXPECT_GT(s.value("tx_challenge_replies", uint64_t{0}), 0u) << s.dump();
  EXPECT_EQ(s.value("rx_auth_failed", uint64_t{0}), 0u) << s.dump();
  EXPECT_EQ(s.value("rx_unsigned", uint64_t{0}), 0u) << s.dump();
  board_->terminate();
  board_->wait(5s);
  auto out = board_->output();
  EXPECT_GT(board_counter(out, "signed"), 0u) << out;
  EXPECT_GT(board_counter(out, "accepted"), 0u) << out;
  EXPECT_EQ(board_counter(out, "challenges_passed"), 1u) << out;
  EXPECT_EQ(board_counter(out, "bad_tag"), 0u) << out;
}

// Another key: hermd refuses every packet of the board (rx_auth_failed) and
// the board every packet of hermd; neither takes the other.
TEST_F(board_keyed, a_board_with_another_key_is_refused_and_counted) {
  start_sensor();
  start_board(keyed_board_bin, {"--key-file", key_file("board.key", other_key)});
  EXPECT_GT(wait_for_count("rx_auth_failed"), 0u) << ctl("stats --json");
  std::this_thread::sleep_for(2s); // hellos and queries go on meanwhile
  EXPECT_FALSE(board_known()) << ctl("neighbors") << ctl("routes");
  auto s = routing_stats();
  EXPECT_EQ(s.value("tx_challenge_replies", uint64_t{0}), 0u) << s.dump();
  board_->terminate();
  board_->wait(5s);
  auto out = board_->output();
  EXPECT_EQ(out.find("response 1 ok"), std::string::npos) << out;
  EXPECT_GT(board_counter(out, "bad_tag"), 0u) << out;
  EXPECT_EQ(board_counter(out, "challenges_passed"), 0u) << out;
}

// No key (the default build, herm-mcu-board): its hellos carry no trailer
// (rx_auth_failed) and its flooded discovery queries are unsigned
// (rx_unsigned); hermd takes none of it.
TEST_F(board_keyed, a_board_without_a_key_is_refused_and_counted) {
  start_sensor();
  start_board(board_bin, {});
  EXPECT_GT(wait_for_count("rx_auth_failed"), 0u) << ctl("stats --json");
  EXPECT_GT(wait_for_count("rx_unsigned"), 0u) << ctl("stats --json");
  EXPECT_FALSE(board_known()) << ctl("neighbors") << ctl("routes");
  board_->terminate();
  board_->wait(5s);
  EXPECT_EQ(board_->output().find("response 1 ok"), std::string::npos)
    << board_->output();
}

// A key file hermd would refuse is refused by the board too, with the reason.
TEST_F(board_keyed, a_key_file_others_may_read_is_refused) {
  auto path = key_file("loose.key", network_key);
  ::chmod(path.c_str(), 0644);
  child_process p{{keyed_board_bin, "--device", cable_->path_b(), "--key-file",
                   path}};
  EXPECT_EQ(p.wait(5s), 2) << p.output();
  EXPECT_NE(p.output().find("group or others"), std::string::npos) << p.output();
}
