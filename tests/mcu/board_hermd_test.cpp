// The C client against the C++ stack, as real processes: herm-mcu-board (the
// client's host build, apps/mcu/host) on one end of a paced pseudo-terminal
// cable at 19,200 baud, a real hermd on the other, and herm-apo-peer on UDP
// behind that hermd as the far module. Requests and responses, a topic,
// readings to hermd's sonar APO, fragmentation at the serial MTU of 32
// bytes, corrupted and dropped bytes, the board rebooting and the neighbour
// restarting. Every wait is bounded; nothing asserts on timing.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string>

#include "channels/testing/loopback.hpp"
#include "tests/mcu/board_fixture.hpp"

using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string apo_peer = HERM_APO_PEER_BIN;
const std::string board_bin = HERM_MCU_BOARD_BIN;

class board_hermd : public board_network {
protected:
  void SetUp() override {
    board_network::SetUp();
    udp_ = free_udp_port();
    peer_udp_ = free_udp_port();
  }

  void TearDown() override {
    peer_.reset();
    board_network::TearDown();
  }

  /// The sensor module, with a UDP channel to the far module.
  void start_sensor() {
    board_network::start_sensor(
      "", "  - name: eth0\n    kind: udp\n    interface: 127.0.0.1:"
            + std::to_string(udp_) + "\n    peers: 127.0.0.1:"
            + std::to_string(peer_udp_) + "\n");
  }

  void start_board(std::vector<std::string> args) {
    board_network::start_board(board_bin, std::move(args));
  }

  /// herm-apo-peer as module 0x31 behind the sensor module, on UDP.
  std::unique_ptr<child_process> peer(std::vector<std::string> args) {
    std::vector<std::string> argv{apo_peer,
                                  "--id",
                                  "0x31",
                                  "--udp",
                                  "127.0.0.1:" + std::to_string(peer_udp_)
                                    + "=127.0.0.1:" + std::to_string(udp_),
                                  "--timeout",
                                  "30"};
    argv.insert(argv.end(), args.begin(), args.end());
    return std::make_unique<child_process>(argv);
  }

  /// The board's instance as its neighbour, the sensor module, holds it
  /// (0: not a neighbour).
  uint64_t board_instance() {
    auto j = nlohmann::json::parse(ctl("neighbors --json"), nullptr, false);
    if (!j.is_array())
      return 0;
    for (auto& n : j)
      if (n.value("module", std::string{}) == board_id)
        return n.value("instance", uint64_t{0});
    return 0;
  }

  /// The sensor module routes to the board (its hellos and update arrived
  /// and were accepted).
  void expect_route_to_board() {
    auto line = sensor_->wait_for_line_containing("route to " + board_id + ":",
                                                  20s);
    ASSERT_TRUE(line) << sensor_->output() << board_->output();
  }

  /// Runs the peer to its end and returns its output; expects exit 0.
  static std::string finish(child_process& p, std::chrono::seconds bound) {
    auto status = p.wait(bound);
    EXPECT_EQ(status, 0) << p.output();
    return p.output();
  }

  uint16_t udp_ = 0;
  uint16_t peer_udp_ = 0;
  std::unique_ptr<child_process> peer_;
};

} // namespace

// A request from a module two hops away (over UDP, then RS232C) reaches the
// board's APO by name and the response comes back: discovery (a flooded
// query answered by the board), routing to a leaf, fragmentation both ways
// (the 60-byte strings make packets of about 90 bytes, three frames at the
// serial MTU of 32).
TEST_F(board_hermd, requests_from_a_far_module_reach_the_boards_apo) {
  plug();
  start_sensor();
  start_board({"--echo", "echo"});
  expect_route_to_board();
  auto routes = ctl("routes");
  EXPECT_NE(routes.find(board_id), std::string::npos) << routes;
  auto call = peer({"call", "--name", "echo", "--count", "20", "--size", "60"});
  auto out = finish(*call, 60s);
  EXPECT_NE(out.find("done ok=20 failed=0"), std::string::npos) << out;
  // The serial channel carried multi-frame packets both ways.
  auto rs1 = channel_stats("rs1");
  ASSERT_TRUE(rs1.is_object()) << ctl("channels --json");
  EXPECT_GT(rs1.value("tx_frames", 0u), rs1.value("tx_packets", 0u)) << rs1.dump();
  EXPECT_GT(rs1.value("rx_frames", 0u), rs1.value("rx_packets", 0u)) << rs1.dump();
  board_->terminate();
  board_->wait(5s);
  EXPECT_EQ(board_counter(board_->output(), "served"), 20u) << board_->output();
  EXPECT_EQ(board_counter(board_->output(), "rx_malformed"), 0u);
}

// A topic the board publishes reaches a subscriber on the far module.
TEST_F(board_hermd, a_topic_from_the_board_reaches_a_far_subscriber) {
  plug();
  start_sensor();
  start_board({"--publish", "board/count", "--period-ms", "200"});
  expect_route_to_board();
  auto sub = peer({"subscribe", "--topic", "board/count", "--count", "5"});
  auto out = finish(*sub, 60s);
  std::smatch m;
  std::string rest = out;
  int values = 0;
  int last = 0;
  while (std::regex_search(rest, m, std::regex{"value ([0-9]+)"})) {
    auto v = std::stoi(m[1]);
    EXPECT_GT(v, last) << out; // in order
    last = v;
    ++values;
    rest = m.suffix();
  }
  EXPECT_GE(values, 5) << out;
}

// The board's readings go to hermd's sonar APO (a request carrying
// herm::hermd::srf04_reading, answered), which batches them to the
// collector.
TEST_F(board_hermd, readings_from_the_board_reach_the_collector) {
  plug();
  start_sensor();
  start_board({"--send", "sonar", "--period-ms", "200", "--count", "9"});
  auto batch = sensor_->wait_for_line_containing(
    "collector: sonar batch 3 from sensor: 3 readings", 30s);
  ASSERT_TRUE(batch) << sensor_->output() << board_->output();
  EXPECT_TRUE(board_->wait_for_line("response 9 ok", 10s)) << board_->output();
}

// Line noise: corrupted and dropped bytes cost the packets they hit, which
// both ends drop and count; nothing else is lost and both recover. The
// board's echo keeps answering once the line is clean again.
TEST_F(board_hermd, corrupted_and_dropped_bytes_are_counted_and_survived) {
  plug();
  start_sensor();
  start_board({"--echo", "echo", "--publish", "noise", "--period-ms", "50"});
  expect_route_to_board();
  // A subscriber on the far module, so that the board's publications cross
  // the line: hellos alone are too few bytes for the noise to hit surely.
  auto sub = peer({"subscribe", "--topic", "noise", "--count", "100000"});
  ASSERT_TRUE(sub->wait_for_line_containing("value ", 30s)) << sub->output();
  herm::test::line_faults noisy;
  noisy.drop = 0.003;
  noisy.flip = 0.003;
  cable_->set_faults(noisy);
  // The board talks (hellos, a publication every 50 ms) through the noise.
  std::this_thread::sleep_for(4s);
  cable_->set_faults({});
  sub->terminate();
  sub->wait(10s);
  auto call = peer({"call", "--name", "echo", "--count", "10", "--size", "60"});
  auto out = finish(*call, 60s);
  EXPECT_NE(out.find("done ok=10 failed=0"), std::string::npos) << out;
  // hermd's serial channel counted what the noise broke...
  auto rs1 = channel_stats("rs1");
  ASSERT_TRUE(rs1.is_object()) << ctl("channels --json");
  EXPECT_GT(rs1.value("rx_malformed", 0u) + rs1.value("rx_reassembly_dropped", 0u),
            0u)
    << rs1.dump();
  // ... and so did the board.
  board_->terminate();
  board_->wait(5s);
  auto& board_out = board_->output();
  uint64_t board_bad = 0;
  for (auto k : {"bad_cobs", "too_short", "oversized", "bad_crc", "malformed",
                 "orphans", "lost", "bad_checksum", "timed_out"})
    board_bad += board_counter(board_out, k);
  EXPECT_GT(board_bad, 0u) << board_out;
}

// The board reboots mid-stream (killed while a request is on the line, then
// started again as a new instance): hermd takes the new instance as a
// restarted neighbour, routes to it again, and requests work again.
TEST_F(board_hermd, the_board_rebooting_mid_stream_is_a_new_instance) {
  plug();
  start_sensor();
  start_board({"--echo", "echo"});
  expect_route_to_board();
  auto call = peer({"call", "--name", "echo", "--count", "3", "--size", "60"});
  finish(*call, 60s);
  auto before = board_instance();
  ASSERT_NE(before, 0u) << ctl("neighbors --json");
  // A long request on the line (sent once the caller has bound the APO),
  // then the board dies.
  auto busy = peer({"call", "--name", "echo", "--count", "1", "--size", "90"});
  ASSERT_TRUE(busy->wait_for_line("bound echo", 30s)) << busy->output();
  board_->signal(SIGKILL);
  board_->wait(5s);
  busy.reset();
  start_board({"--echo", "echo"});
  auto again = peer({"call", "--name", "echo", "--count", "5", "--size", "60",
                     "--rebind"});
  auto out = finish(*again, 60s);
  EXPECT_NE(out.find("done ok=5 failed=0"), std::string::npos) << out;
  // hermd holds the new instance: the board was taken as restarted.
  EXPECT_NE(board_instance(), before) << ctl("neighbors --json");
  EXPECT_NE(board_instance(), 0u);
}

// The neighbour (hermd) restarts: the board notices the new instance, says
// hello and advertises itself again, and the new hermd routes to it.
TEST_F(board_hermd, the_neighbour_restarting_is_met_again) {
  plug();
  start_sensor();
  start_board({"--echo", "echo"});
  expect_route_to_board();
  sensor_->terminate();
  ASSERT_EQ(sensor_->wait(10s), 0) << sensor_->output();
  start_sensor();
  expect_route_to_board();
  auto call = peer({"call", "--name", "echo", "--count", "5", "--size", "60"});
  auto out = finish(*call, 60s);
  EXPECT_NE(out.find("done ok=5 failed=0"), std::string::npos) << out;
  board_->terminate();
  board_->wait(5s);
  EXPECT_GE(board_counter(board_->output(), "neighbour_changes"), 2u)
    << board_->output();
}
