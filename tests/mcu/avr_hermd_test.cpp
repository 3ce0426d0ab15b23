// The sonar board's firmware (apps/mcu/firmware, an ATmega128 ELF) running in
// simavr (herm-avr-sim) against real hermd processes, over a paced
// pseudo-terminal cable at 19,200 baud: the paper's AVR board as a module
// of its own. The scripted obstacle's distances reach the collector on the
// main controller through the sensor module's sonar APO; a board run again
// from its EEPROM (herm-avr-sim --eeprom) is a new instance to its
// neighbour. Skips, saying why, when avr-gcc or libsimavr was not found at
// configure time. Every wait is bounded; nothing asserts on timing.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "apps/mcu/sim/distance_script.hpp"
#include "channels/testing/loopback.hpp"
#include "channels/testing/null_modem.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

#if defined(HERM_AVR_SIM_BIN) && defined(HERM_SRF04_FIRMWARE_ELF)
#define SKIP_WITHOUT_AVR() (void)0
#else
#define SKIP_WITHOUT_AVR() GTEST_SKIP() << HERM_AVR_SKIP_REASON
#define HERM_AVR_SIM_BIN ""
#define HERM_SRF04_FIRMWARE_ELF ""
#endif

namespace {

/// The firmware's module id (SRF04_MODULE_ID) as hermd prints it.
const std::string board_id = "0xA04";

/// The firmware's instance: its boot count (EEPROM bytes 0..3) << 16 | id.
constexpr uint64_t instance_of_boot(uint64_t boots) {
  return boots << 16 | 0x0A04u;
}

/// Every line of `p` holding `part`, read for at most `dt` (also keeps the
/// child's pipe drained: hermd at debug level writes a line per packet).
std::vector<std::string> lines_with(child_process& p, const std::string& part,
                                    std::chrono::milliseconds dt) {
  std::vector<std::string> out;
  auto deadline = std::chrono::steady_clock::now() + dt;
  for (;;) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0)
      return out;
    auto l = p.wait_for_line_containing(part, left);
    if (!l)
      return out;
    out.push_back(*l);
  }
}

bool near_one_of(long mm, const std::set<long>& want) {
  for (auto w : want)
    if (mm >= w - 1 && mm <= w + 1)
      return true;
  return false;
}

class avr_hermd : public ::testing::Test {
protected:
  void SetUp() override {
    ASSERT_FALSE(dir_.path().empty());
    herm::test::null_modem::config c;
    c.baud = 19200;
    std::string err;
    cable_ = herm::test::null_modem::open(c, err);
    ASSERT_TRUE(cable_) << err;
    main_udp_ = free_udp_port();
    sensor_udp_ = free_udp_port();
  }

  void TearDown() override {
    sim_.reset();
    sensor_.reset();
    main_.reset();
    cable_.reset();
  }

  std::string sock(const std::string& module) const {
    return dir_.path() + "/" + module + ".sock";
  }

  /// The sensor module (0x40): the board's line (rs1), UDP to the main
  /// controller, and the sonar APO without a local line, batching 3.
  void start_sensor() {
    auto cfg = dir_.path() + "/sensor.yaml";
    std::ofstream{cfg}
      << "module:\n  name: sensor\n  id: 0x40\n  hello_interval_ms: 300\n"
         "log:\n  level: debug\n"
         "control:\n  socket: " << sock("sensor") << "\n"
         "channels:\n"
         "  - name: rs1\n    kind: serial\n    interface: " << cable_->path_a()
      << "\n    baud: 19200\n"
         "  - name: eth0\n    kind: udp\n    interface: 127.0.0.1:" << sensor_udp_
      << "\n    peers: 127.0.0.1:" << main_udp_ << "\n"
         "apos:\n"
         "  - name: sonar\n    kind: srf04_batcher\n"
         "    options: { batch: 3, target: collector }\n";
    sensor_ = std::make_unique<child_process>(std::vector<std::string>{HERMD_BIN, cfg});
    ASSERT_TRUE(sensor_->started());
    ASSERT_TRUE(sensor_->wait_for_line_containing("running as 0x40", 20s))
      << sensor_->output();
  }

  /// The main controller (0x4E) with the collector, on UDP.
  void start_main() {
    auto cfg = dir_.path() + "/main.yaml";
    std::ofstream{cfg}
      << "module:\n  name: main\n  id: 0x4E\n  hello_interval_ms: 300\n"
         "control:\n  socket: " << sock("main") << "\n"
         "channels:\n"
         "  - name: eth0\n    kind: udp\n    interface: 127.0.0.1:" << main_udp_
      << "\n    peers: 127.0.0.1:" << sensor_udp_ << "\n"
         "apos:\n  - name: collector\n    kind: collector\n";
    main_ = std::make_unique<child_process>(std::vector<std::string>{HERMD_BIN, cfg});
    ASSERT_TRUE(main_->started());
    ASSERT_TRUE(main_->wait_for_line_containing("running as 0x4E", 20s))
      << main_->output();
  }

  /// herm-avr-sim running the firmware on the cable's other end.
  void start_board(std::vector<std::string> args) {
    std::vector<std::string> argv{HERM_AVR_SIM_BIN, "--firmware",
                                  HERM_SRF04_FIRMWARE_ELF, "--device",
                                  cable_->path_b()};
    argv.insert(argv.end(), args.begin(), args.end());
    sim_ = std::make_unique<child_process>(argv);
    ASSERT_TRUE(sim_->started());
    ASSERT_TRUE(sim_->wait_for_line("ready ", 10s)) << sim_->output();
  }

  /// The board's instance as the sensor module's neighbour table holds it
  /// (0: not a neighbour).
  uint64_t board_instance() {
    child_process p{{"/bin/sh", "-c",
                     std::string{HERMCTL_BIN} + " -s " + sock("sensor")
                       + " --json neighbours 2>&1"}};
    p.wait(20s);
    auto j = nlohmann::json::parse(p.output(), nullptr, false);
    if (!j.is_array())
      return 0;
    for (auto& n : j)
      if (n.value("module", std::string{}) == board_id)
        return n.value("instance", uint64_t{0});
    return 0;
  }

  /// Polls the sensor module until the board is its neighbour with an
  /// instance other than `other`; returns it (0 if none came in 30 s).
  uint64_t wait_instance_other_than(uint64_t other) {
    for (auto deadline = std::chrono::steady_clock::now() + 30s;
         std::chrono::steady_clock::now() < deadline;) {
      lines_with(*sensor_, "\x01", 200ms); // drain the log meanwhile
      auto inst = board_instance();
      if (inst != 0 && inst != other)
        return inst;
    }
    return 0;
  }

  herm::test::temp_dir dir_{"herm-avr-hermd"};
  std::unique_ptr<herm::test::null_modem> cable_;
  uint16_t main_udp_ = 0;
  uint16_t sensor_udp_ = 0;
  std::unique_ptr<child_process> main_;
  std::unique_ptr<child_process> sensor_;
  std::unique_ptr<child_process> sim_;
};

} // namespace

// The paper's data path with the real firmware: the SRF04 part answers the
// board's triggers with echoes for the scripted obstacle (0.5 m, 1.5 m,
// 2.345 m), the firmware sends each reading as a request to the sensor
// module's sonar APO (discovered over RS232C), and batches of three reach
// the collector on the main controller over UDP. Every reading the APO took
// and every batch's range is one of the scripted distances; every distance
// arrives; no batch is lost.
TEST_F(avr_hermd, readings_with_the_scripted_distances_reach_the_collector) {
  SKIP_WITHOUT_AVR();
  ASSERT_NO_FATAL_FAILURE(start_main());
  ASSERT_NO_FATAL_FAILURE(start_sensor());
  const std::vector<herm::avr_sim::distance_point> script{
    {0, 500}, {3000, 1500}, {6000, 2345}};
  const std::set<long> want{500, 1500, 2345};
  auto script_path = dir_.path() + "/distance.txt";
  {
    std::ofstream out{script_path};
    for (auto& p : script)
      out << p.t_ms << " " << p.distance_mm << "\n";
  }
  ASSERT_NO_FATAL_FAILURE(start_board({"--script", script_path, "--max-seconds", "9"}));

  const std::regex batch_re{
    R"(collector: sonar batch (\d+) from sensor: 3 readings \(seq (\d+)\.\.\), (\d+)\.\.(\d+) mm)"};
  const std::regex reading_re{R"(sonar: SRF04 reading (\d+): (\d+) mm \((\d+) us\))"};
  std::set<long> seen;
  long batches = 0;
  long last_seq = 0;
  long readings = 0;
  for (auto deadline = std::chrono::steady_clock::now() + 40s;
       std::chrono::steady_clock::now() < deadline && seen != want;) {
    for (auto& l : lines_with(*main_, "collector: sonar batch", 100ms)) {
      std::smatch m;
      ASSERT_TRUE(std::regex_search(l, m, batch_re)) << l;
      EXPECT_EQ(std::stol(m[1]), ++batches) << "a batch went missing: " << l;
      EXPECT_GT(std::stol(m[2]), last_seq) << l;
      last_seq = std::stol(m[2]);
      for (long mm : {std::stol(m[3]), std::stol(m[4])}) {
        EXPECT_TRUE(near_one_of(mm, want)) << l;
        for (auto w : want)
          if (mm >= w - 1 && mm <= w + 1)
            seen.insert(w);
      }
    }
    for (auto& l : lines_with(*sensor_, "sonar: SRF04 reading", 100ms)) {
      std::smatch m;
      ASSERT_TRUE(std::regex_search(l, m, reading_re)) << l;
      ++readings;
      auto mm = std::stol(m[2]);
      EXPECT_TRUE(near_one_of(mm, want)) << l;
      EXPECT_NEAR(std::stol(m[3]),
                  herm::avr_sim::echo_width_us(static_cast<uint32_t>(mm)), 2)
        << l;
    }
  }
  EXPECT_EQ(seen, want) << "distances seen at the collector: " << seen.size()
                        << "\n" << main_->output();
  EXPECT_GE(batches, 3);
  EXPECT_GE(readings, 3 * batches);
  EXPECT_EQ(sim_->wait(30s), 0) << sim_->output();
  EXPECT_NE(sim_->output().find("stopped reason=max-seconds"), std::string::npos)
    << sim_->output();
  EXPECT_NE(sim_->output().find("dropped_to_host=0"), std::string::npos)
    << sim_->output();
}

// The firmware counts its boots in EEPROM and makes its instance of the
// count. herm-avr-sim --eeprom keeps the EEPROM in a file, so a second run
// is the same board rebooted: its neighbour sees instance 0x10A04, then
// 0x20A04, and the file holds the count.
TEST_F(avr_hermd, a_board_run_again_from_its_eeprom_is_a_new_instance) {
  SKIP_WITHOUT_AVR();
  ASSERT_NO_FATAL_FAILURE(start_sensor());
  auto eeprom = dir_.path() + "/board.eeprom";
  ASSERT_NO_FATAL_FAILURE(start_board({"--eeprom", eeprom}));
  auto first = wait_instance_other_than(0);
  EXPECT_EQ(first, instance_of_boot(1)) << sensor_->output();
  sim_->terminate();
  EXPECT_EQ(sim_->wait(20s), 0) << sim_->output();
  EXPECT_NE(sim_->output().find("eeprom saved " + eeprom + " bytes=4096"),
            std::string::npos)
    << sim_->output();

  ASSERT_NO_FATAL_FAILURE(start_board({"--eeprom", eeprom}));
  auto second = wait_instance_other_than(first);
  EXPECT_EQ(second, instance_of_boot(2)) << sensor_->output();
  sim_->terminate();
  EXPECT_EQ(sim_->wait(20s), 0) << sim_->output();
  std::ifstream in{eeprom, std::ios::binary};
  std::string bytes{std::istreambuf_iterator<char>{in}, std::istreambuf_iterator<char>{}};
  ASSERT_EQ(bytes.size(), 4096u);
  EXPECT_EQ(bytes.substr(0, 4), std::string("\x02\x00\x00\x00", 4)); // two boots
}
