#pragma once

// What the multi-process tests of the C client share: a paced 19,200-baud
// pseudo-terminal cable, a real hermd as the paper's sensor module (0x40) on
// one end, a board process (herm-mcu-board, keyed or not) on the other, and
// hermctl on the sensor module's control socket. Every wait is bounded.

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string>
#include <vector>

#include "channels/testing/null_modem.hpp"
#include "tests/support/process.hpp"

namespace herm::test {

class board_network : public ::testing::Test {
protected:
  /// The board's module id (herm-mcu-board's default) as hermd prints it.
  static inline const std::string board_id = "0xA04";

  void SetUp() override {
    char tmpl[] = "/tmp/herm-board-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
  }

  void TearDown() override {
    board_.reset();
    sensor_.reset();
    cable_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  /// The cable: 19,200 baud, 10 bits per byte, `faults` on every byte.
  void plug(line_faults faults = {}, uint64_t seed = 17) {
    null_modem::config c;
    c.baud = 19200;
    c.faults = faults;
    c.seed = seed;
    std::string err;
    cable_ = null_modem::open(c, err);
    ASSERT_TRUE(cable_) << err;
  }

  /// hermd as the sensor module: the board's line (rs1) and `channels`
  /// (more YAML list entries), top-level `sections` (e.g. auth), the sonar
  /// APO without a local line (readings come from the board, batch 3) and
  /// a collector.
  void start_sensor(const std::string& sections = "",
                    const std::string& channels = "") {
    auto cfg = dir_ + "/sensor.yaml";
    std::ofstream{cfg}
      << "module:\n  name: sensor\n  id: 0x40\n  hello_interval_ms: 500\n"
         "control:\n  socket: " << sock() << "\n"
      << sections
      << "channels:\n"
         "  - name: rs1\n    kind: serial\n    interface: " << cable_->path_a()
      << "\n    baud: 19200\n"
      << channels
      << "apos:\n"
         "  - name: sonar\n    kind: srf04_batcher\n"
         "    options: { batch: 3, target: collector }\n"
         "  - name: collector\n    kind: collector\n";
    sensor_ = std::make_unique<child_process>(
      std::vector<std::string>{HERMD_BIN, cfg});
    ASSERT_TRUE(sensor_->started());
  }

  /// The board program `bin` on the cable's other end with `args`; waits
  /// for its "ready" line.
  void start_board(const std::string& bin, std::vector<std::string> args) {
    std::vector<std::string> argv{bin, "--device", cable_->path_b(), "--baud",
                                  "19200"};
    argv.insert(argv.end(), args.begin(), args.end());
    board_ = std::make_unique<child_process>(argv);
    ASSERT_TRUE(board_->started());
    ASSERT_TRUE(board_->wait_for_line("ready", std::chrono::seconds(5)))
      << board_->output();
  }

  std::string sock() const {
    return dir_ + "/sensor.sock";
  }

  /// hermctl's output (stdout and stderr) for `args` on the sensor module.
  std::string ctl(const std::string& args) {
    child_process p{{"/bin/sh", "-c", std::string{HERMCTL_BIN} + " -s "
                                        + sock() + " " + args + " 2>&1"}};
    p.wait(std::chrono::seconds(20));
    return p.output();
  }

  /// The counters of the sensor module's channel on device `device`
  /// (`hermctl channels --json`), or null.
  nlohmann::json channel_stats(const std::string& device) {
    auto rows = nlohmann::json::parse(ctl("channels --json"), nullptr, false);
    if (rows.is_array())
      for (auto& c : rows)
        if (c.value("device", std::string{}) == device && c.contains("stats"))
          return c["stats"];
    return nullptr;
  }

  /// A number the board printed on its "counters", "link" or "auth" line.
  static uint64_t board_counter(const std::string& out, const std::string& k) {
    std::smatch m;
    if (std::regex_search(out, m, std::regex{" " + k + " ([0-9]+)"}))
      return std::stoull(m[1]);
    return 0;
  }

  std::string dir_;
  std::unique_ptr<null_modem> cable_;
  std::unique_ptr<child_process> sensor_;
  std::unique_ptr<child_process> board_;
};

} // namespace herm::test
