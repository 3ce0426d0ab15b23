// The sonar board's firmware (apps/mcu/firmware, an ATmega128 ELF) running in
// simavr (herm-avr-sim) against real hermd processes, over a paced
// pseudo-terminal cable at 19,200 baud: the paper's AVR board as a module
// of its own. The scripted obstacle's distances reach the collector on the
// main controller through the sensor module's sonar APO; a module beyond the
// main controller finds the board's own APO `srf04` by name and asks it for
// the last reading; a board run again from its EEPROM (herm-avr-sim
// --eeprom) is a new instance to its neighbour. Skips, saying why, when avr-gcc or libsimavr was not found at
// configure time. Every wait is bounded; nothing asserts on timing.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <memory>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/hermd/testbed_types.hpp"
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
    main_udp2_ = free_udp_port();
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

  /// The main controller (0x4E) with the collector, on UDP to the sensor
  /// module; when `extra_peer` is not 0, a second UDP channel (eth1, a link
  /// of its own, so floods are relayed between the two) to a module in
  /// this process at that port.
  void start_main(uint16_t extra_peer = 0) {
    auto cfg = dir_.path() + "/main.yaml";
    std::ofstream out{cfg};
    out << "module:\n  name: main\n  id: 0x4E\n  hello_interval_ms: 300\n"
         "control:\n  socket: " << sock("main") << "\n"
         "channels:\n"
         "  - name: eth0\n    kind: udp\n    interface: 127.0.0.1:" << main_udp_
      << "\n    peers: 127.0.0.1:" << sensor_udp_ << "\n";
    if (extra_peer != 0)
      out << "  - name: eth1\n    kind: udp\n    interface: 127.0.0.1:"
          << main_udp2_ << "\n    peers: 127.0.0.1:" << extra_peer << "\n";
    out << "apos:\n  - name: collector\n    kind: collector\n";
    out.close();
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
  uint16_t main_udp2_ = 0;
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

// The board's own APO: `srf04` (type herm.srf04) answers any request with
// its last reading. A C++ module in this process (0x31), whose only link is
// a UDP channel of its own to the main controller, binds it by name (a discovery flooded through
// the main controller and the sensor module over RS232C, answered by the
// firmware, answered back the same way) and asks it: the reading's distance is the scripted obstacle's
// and its echo time the SRF04 part's pulse for it. Its application table
// then lists the board's APO as hermctl's `apps` shows it.
TEST_F(avr_hermd, the_boards_own_apo_answers_a_far_module_with_its_last_reading) {
  SKIP_WITHOUT_AVR();
  const uint16_t asker_udp = herm::test::free_udp_port();
  ASSERT_NO_FATAL_FAILURE(start_main(asker_udp));
  ASSERT_NO_FATAL_FAILURE(start_sensor());
  auto script_path = dir_.path() + "/distance.txt";
  std::ofstream{script_path} << "0 1234\n";
  ASSERT_NO_FATAL_FAILURE(
    start_board({"--script", script_path, "--max-seconds", "60", "--report-stack"}));

  caf::actor_system_config cfg;
  herm::configure(cfg);
  cfg.add_message_types<caf::id_block::herm_apos>();
  caf::actor_system sys{cfg};
  herm::module_config mc;
  mc.routing.id = 0x31;
  mc.routing.hello_interval = 300ms;
  mc.devices.push_back(herm::device_config{
    "udp0", "udp", "127.0.0.1:" + std::to_string(asker_udp),
    {{"peers", "127.0.0.1:" + std::to_string(main_udp2_)}}});
  auto m = herm::run_module(sys, mc);
  ASSERT_TRUE(m) << herm::render(m.error());
  caf::scoped_actor self{sys};

  // Bound once the routes over RS232C have formed (not_found or no_route
  // until then).
  caf::actor proxy;
  std::string last_error;
  for (auto deadline = std::chrono::steady_clock::now() + 40s;
       !proxy && std::chrono::steady_clock::now() < deadline;) {
    lines_with(*sensor_, "\x01", 100ms); // keep hermd's debug log drained
    self->request((*m)->apps, 5s, herm::atom::bind_v,
                  herm::bind_request{herm::query_by::name, "srf04", 1000})
      .receive([&](caf::actor& p) { proxy = p; },
               [&](caf::error& e) { last_error = herm::render(e); });
  }
  ASSERT_TRUE(proxy) << "srf04 never bound: " << last_error << "\n"
                     << sensor_->output();

  // Any request is answered with the last reading; seq 0 means none taken
  // yet (asked right after boot), so ask until one is there.
  herm::hermd::srf04_reading reading{};
  for (auto deadline = std::chrono::steady_clock::now() + 20s;
       reading.seq == 0 && std::chrono::steady_clock::now() < deadline;) {
    self->request(proxy, 5s, std::string{"reading?"})
      .receive([&](herm::hermd::srf04_reading& r) { reading = r; },
               [&](caf::error& e) { last_error = herm::render(e); });
    if (reading.seq == 0)
      lines_with(*sensor_, "\x01", 200ms);
  }
  ASSERT_GT(reading.seq, 0u) << "no reading from srf04: " << last_error;
  EXPECT_NEAR(reading.distance_mm, 1234, 1);
  EXPECT_NEAR(static_cast<double>(reading.echo_us),
              herm::avr_sim::echo_width_us(1234), 2);

  std::vector<herm::apo_info> apps;
  self->request((*m)->apps, 5s, herm::atom::get_v, herm::atom::apps_v)
    .receive([&](std::vector<herm::apo_info>& rows) { apps = rows; },
             [&](caf::error& e) { FAIL() << herm::render(e); });
  bool listed = false;
  for (auto& a : apps)
    listed = listed
             || (a.ref.name == "srf04" && a.ref.type == "herm.srf04"
                 && a.ref.module == 0x0A04 && !a.local);
  EXPECT_TRUE(listed) << "the board's APO is not in the application table";
  m->stop();

  // Serving its APO as well as sending readings, the board's stack stays
  // within issue 17's bound (painted stack, herm-avr-sim --report-stack).
  sim_->terminate();
  EXPECT_EQ(sim_->wait(20s), 0) << sim_->output();
  std::smatch used;
  auto out = sim_->output();
  ASSERT_TRUE(std::regex_search(out, used, std::regex{R"(stack used=(\d+))"})) << out;
  EXPECT_LT(std::stol(used[1]), 512) << out;
  std::cout << "board stack high-water mark serving srf04: " << used[1] << " B\n";
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
