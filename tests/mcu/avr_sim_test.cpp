// herm-avr-sim and the sonar board's board support: the harness's pure parts
// (distance script, echo width, stack scan, EEPROM file) as specifications, then the
// self-test firmware (tests/mcu/firmware/srf04_selftest.c) run in the
// harness against a scripted distance, read on the pty like a host would.
// Skips, saying why, when avr-gcc or libsimavr was not found at configure
// time (then the firmware or the harness was not built).
#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "apps/mcu/sim/distance_script.hpp"
#include "apps/mcu/sim/eeprom_file.hpp"
#include "apps/mcu/sim/stack_report.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

using namespace herm::avr_sim;
using namespace std::chrono_literals;

// -- the distance script ------------------------------------------------------

TEST(distance_script, parses_times_and_distances_skipping_comments_and_blanks) {
  auto s = parse_distance_script("# t_ms distance_mm\n0 500\n\n  1000\t1500 \n"
                                 "2000 4500\r\n");
  ASSERT_EQ(s.error, "");
  ASSERT_EQ(s.points.size(), 3u);
  EXPECT_EQ(s.points[1].t_ms, 1000u);
  EXPECT_EQ(s.points[1].distance_mm, 1500u);
  EXPECT_EQ(s.points[2].distance_mm, 4500u);
}

TEST(distance_script, rejects_a_bad_line_naming_it_and_keeps_no_points) {
  struct {
    const char* text;
    const char* error;
  } cases[] = {
    {"0 500\n1000\n", "line 2: expected `t_ms distance_mm` (two unsigned numbers)"},
    {"0 500 7\n", "line 1: expected `t_ms distance_mm` (two unsigned numbers)"},
    {"0 -5\n", "line 1: expected `t_ms distance_mm` (two unsigned numbers)"},
    {"0 5x\n", "line 1: expected `t_ms distance_mm` (two unsigned numbers)"},
    {"0 99999999999\n", "line 1: expected `t_ms distance_mm` (two unsigned numbers)"},
    {"100 500\n# back\n50 600\n", "line 3: time 50 ms goes back"},
  };
  for (const auto& c : cases) {
    auto s = parse_distance_script(c.text);
    EXPECT_EQ(s.error, c.error) << c.text;
    EXPECT_TRUE(s.points.empty()) << c.text;
  }
}

TEST(distance_script, refuses_more_than_the_bound_of_points) {
  std::string text;
  for (size_t i = 0; i <= max_script_points; ++i)
    text += std::to_string(i) + " 1\n";
  auto s = parse_distance_script(text);
  EXPECT_EQ(s.error, "line " + std::to_string(max_script_points + 1)
                       + ": more than " + std::to_string(max_script_points)
                       + " points");
}

TEST(distance_script, a_distance_holds_from_its_time_until_the_next_point) {
  std::vector<distance_point> p{{100, 500}, {1000, 1500}, {1000, 1600}, {2000, 4500}};
  EXPECT_EQ(distance_at(p, 0, 777), 777u);
  EXPECT_EQ(distance_at(p, 99, 777), 777u);
  EXPECT_EQ(distance_at(p, 100, 777), 500u);
  EXPECT_EQ(distance_at(p, 999, 777), 500u);
  EXPECT_EQ(distance_at(p, 1000, 777), 1600u); // the last of equal times wins
  EXPECT_EQ(distance_at(p, 5000, 777), 4500u);
  EXPECT_EQ(distance_at({}, 5000, 777), 777u);
}

TEST(distance_script, echo_width_follows_the_protocol_and_is_36_ms_beyond_4_m) {
  EXPECT_EQ(echo_width_us(1768), 10309u); // docs/protocol.md's example reading
  EXPECT_EQ(echo_width_us(0), 0u);
  EXPECT_EQ(echo_width_us(4000), 23323u);
  EXPECT_EQ(echo_width_us(4001), 36000u);
}

// -- the stack scan -----------------------------------------------------------

TEST(stack_report, the_lowest_byte_without_paint_is_the_deepest_use) {
  std::vector<uint8_t> ram(0x110, stack_paint_byte);
  ram[0x10F] = 1; // the top of the stack (ramend)
  ram[0x108] = 0; // the deepest push
  ram[0x109] = stack_paint_byte; // a byte pushed with the paint's value
  auto use = measure_stack(ram.data(), 0x100, 0x10F);
  EXPECT_TRUE(use.painted);
  EXPECT_EQ(use.used, 8u);
  EXPECT_EQ(use.headroom, 8u);
}

TEST(stack_report, a_bottom_without_paint_says_the_area_was_not_painted) {
  std::vector<uint8_t> ram(0x110, 0);
  auto use = measure_stack(ram.data(), 0x100, 0x10F);
  EXPECT_FALSE(use.painted);
  EXPECT_EQ(use.used, 16u);
  EXPECT_EQ(use.headroom, 0u);
  EXPECT_EQ(measure_stack(ram.data(), 0x111, 0x10F).used, 0u);
}

// -- the EEPROM file -----------------------------------------------------------

TEST(eeprom_file, a_missing_file_is_an_erased_eeprom_not_an_error) {
  herm::test::temp_dir dir{"herm-eeprom"};
  auto img = load_eeprom(dir.path() + "/none.bin", 4096);
  EXPECT_FALSE(img.found);
  EXPECT_EQ(img.error, "");
  EXPECT_TRUE(img.bytes.empty());
}

TEST(eeprom_file, saves_atomically_and_loads_back_the_same_bytes) {
  herm::test::temp_dir dir{"herm-eeprom"};
  auto path = dir.path() + "/board.eeprom";
  std::vector<uint8_t> ee(4096, 0xFF);
  ee[0] = 2; // the sonar firmware's boot counter, little endian
  ee[4095] = 0x5A;
  ASSERT_EQ(save_eeprom(path, ee.data(), ee.size()), "");
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  auto img = load_eeprom(path, ee.size());
  EXPECT_TRUE(img.found);
  EXPECT_EQ(img.error, "");
  EXPECT_EQ(img.bytes, ee);
  ee[0] = 3; // a later run replaces the image
  ASSERT_EQ(save_eeprom(path, ee.data(), ee.size()), "");
  EXPECT_EQ(load_eeprom(path, ee.size()).bytes, ee);
}

TEST(eeprom_file, a_shorter_file_fills_the_first_bytes_a_longer_one_is_refused) {
  herm::test::temp_dir dir{"herm-eeprom"};
  auto path = dir.path() + "/board.eeprom";
  std::ofstream{path, std::ios::binary} << "\x01\x02\x03";
  auto img = load_eeprom(path, 4);
  EXPECT_EQ(img.error, "");
  EXPECT_EQ(img.bytes, (std::vector<uint8_t>{1, 2, 3}));
  std::ofstream{path, std::ios::binary} << "12345";
  img = load_eeprom(path, 4);
  EXPECT_TRUE(img.found);
  EXPECT_EQ(img.error, "--eeprom " + path + " holds more than the EEPROM's 4 bytes");
  EXPECT_TRUE(img.bytes.empty());
}

TEST(eeprom_file, a_file_that_cannot_be_written_says_which_and_keeps_the_old_one) {
  herm::test::temp_dir dir{"herm-eeprom"};
  uint8_t ee[4] = {1, 2, 3, 4};
  auto err = save_eeprom(dir.path() + "/no/such/dir/board.eeprom", ee, sizeof(ee));
  EXPECT_EQ(err.rfind("cannot write " + dir.path() + "/no/such/dir/board.eeprom.tmp: ", 0),
            0u)
    << err;
  // A directory in the file's place: the rename fails, the old entry stays.
  auto path = dir.path() + "/board.eeprom";
  std::filesystem::create_directory(path);
  err = save_eeprom(path, ee, sizeof(ee));
  EXPECT_EQ(err.rfind("cannot rename " + path + ".tmp to " + path + ": ", 0), 0u) << err;
  EXPECT_TRUE(std::filesystem::is_directory(path));
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
}

// -- the self-test firmware in the harness -----------------------------------

namespace {

/// The board's serial line, as a host opens it: raw, non-blocking.
class pty_reader {
public:
  explicit pty_reader(const std::string& path) {
    fd_ = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0)
      return;
    termios tio{};
    ::tcgetattr(fd_, &tio);
    ::cfmakeraw(&tio);
    ::tcsetattr(fd_, TCSANOW, &tio);
  }
  ~pty_reader() {
    if (fd_ >= 0)
      ::close(fd_);
  }
  bool ok() const {
    return fd_ >= 0;
  }
  void write_all(const std::string& s) {
    size_t done = 0;
    while (done < s.size()) {
      auto n = ::write(fd_, s.data() + done, s.size() - done);
      if (n > 0)
        done += static_cast<size_t>(n);
      else
        ::usleep(1000);
    }
  }
  /// The next complete line, or nothing by the deadline.
  std::optional<std::string> line(std::chrono::steady_clock::time_point deadline) {
    for (;;) {
      auto nl = buf_.find('\n');
      if (nl != std::string::npos) {
        auto l = buf_.substr(0, nl);
        buf_.erase(0, nl + 1);
        return l;
      }
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0)
        return std::nullopt;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) <= 0)
        continue;
      char tmp[512];
      auto n = ::read(fd_, tmp, sizeof(tmp));
      if (n > 0)
        buf_.append(tmp, static_cast<size_t>(n));
      else
        ::usleep(1000); // EIO while the harness sets up, EAGAIN
    }
  }

private:
  int fd_ = -1;
  std::string buf_;
};

struct reading {
  uint32_t seq, distance_mm, echo_us, t_ms;
};

} // namespace

TEST(avr_sim, the_self_test_firmware_measures_the_scripted_distances) {
#if !defined(HERM_AVR_SIM_BIN) || !defined(HERM_SRF04_SELFTEST_ELF)
  GTEST_SKIP() << HERM_AVR_SKIP_REASON;
#else
  herm::test::temp_dir dir{"herm-avr-sim"};
  ASSERT_FALSE(dir.path().empty());
  // 0.5 m, 1.5 m, nothing in range (4.5 m), 2.345 m; a reading every 100 ms.
  const std::vector<distance_point> script{{0, 500}, {1000, 1500}, {2000, 4500},
                                           {3000, 2345}};
  std::string script_path = dir.path() + "/distance.txt";
  {
    std::ofstream out{script_path};
    out << "# t_ms distance_mm\n";
    for (auto& p : script)
      out << p.t_ms << " " << p.distance_mm << "\n";
  }
  std::string link = dir.path() + "/board";
  herm::test::child_process sim{{HERM_AVR_SIM_BIN, "--firmware",
                                 HERM_SRF04_SELFTEST_ELF, "--script", script_path,
                                 "--pty-link", link, "--max-seconds", "6",
                                 "--report-stack"}};
  ASSERT_TRUE(sim.started());
  auto pty = sim.wait_for_line("pty ", 10s);
  ASSERT_TRUE(pty) << sim.output();
  pty_reader line{link}; // the symlink leads to the same pty
  ASSERT_TRUE(line.ok()) << *pty;

  auto deadline = std::chrono::steady_clock::now() + 30s;
  std::vector<reading> readings;
  std::string stats;
  bool asked = false;
  while (auto l = line.line(deadline)) {
    reading r{};
    if (std::sscanf(l->c_str(), "reading %u %u %u %u", &r.seq, &r.distance_mm,
                    &r.echo_us, &r.t_ms) == 4)
      readings.push_back(r);
    EXPECT_NE(l->rfind("failed", 0), 0u) << *l;
    if (l->rfind("stats ", 0) == 0) {
      stats = *l;
      break;
    }
    // Past the third segment, send the board a few lines (host -> board
    // at the line rate) and ask for its counters.
    if (!asked && r.t_ms >= 3500) {
      asked = true;
      std::string burst;
      for (int i = 0; i < 8; ++i)
        burst += "line " + std::to_string(i) + " abcdefghijklmnopqrstuvwxyz\n";
      line.write_all(burst + "stats\n");
    }
  }
  ASSERT_FALSE(stats.empty()) << "no stats line; readings so far: " << readings.size();
  // Nothing the host sent was lost on the board.
  EXPECT_NE(stats.find("rx_dropped=0 rx_overruns=0 rx_framing_errors=0 "
                       "srf04_failures=0"),
            std::string::npos)
    << stats;

  ASSERT_GE(readings.size(), 30u);
  int per_segment[4] = {0, 0, 0, 0};
  for (size_t i = 0; i < readings.size(); ++i) {
    const auto& r = readings[i];
    if (i > 0) {
      EXPECT_EQ(r.seq, readings[i - 1].seq + 1) << "a reading went missing";
    }
    // The firmware stamps the trigger with its own clock; skip readings
    // taken within 2 ms of a change of distance.
    bool near_change = false;
    for (auto& p : script)
      near_change |= r.t_ms + 2 >= p.t_ms && r.t_ms <= p.t_ms + 2 && p.t_ms > 0;
    if (near_change)
      continue;
    auto want = distance_at(script, r.t_ms, 0);
    for (int s = 0; s < 4; ++s)
      if (want == script[static_cast<size_t>(s)].distance_mm)
        ++per_segment[s];
    if (want > srf04_range_mm) {
      EXPECT_EQ(r.distance_mm, 65535u) << "reading " << r.seq;
      EXPECT_NEAR(r.echo_us, srf04_no_echo_us, 2) << "reading " << r.seq;
    } else {
      EXPECT_NEAR(r.distance_mm, want, 1) << "reading " << r.seq << " at " << r.t_ms;
      EXPECT_NEAR(r.echo_us, echo_width_us(want), 2) << "reading " << r.seq;
    }
  }
  for (int s = 0; s < 4; ++s)
    EXPECT_GE(per_segment[s], 5) << "segment " << s;

  EXPECT_EQ(sim.wait(20s), 0) << sim.output();
  auto out = sim.output();
  EXPECT_NE(out.find("stopped reason=max-seconds board_ms=6000"), std::string::npos) << out;
  unsigned used = 0, headroom = 0;
  auto at = out.find("stack used=");
  ASSERT_NE(at, std::string::npos) << out;
  ASSERT_EQ(std::sscanf(out.c_str() + at, "stack used=%u headroom=%u", &used, &headroom), 2);
  EXPECT_NE(out.find("painted=yes"), std::string::npos) << out;
  EXPECT_GT(used, 10u);   // at least main's frame and an interrupt's
  EXPECT_LT(used, 512u);  // issue 17's stack target
  EXPECT_NE(out.find("srf04 measurements="), std::string::npos) << out;
#endif
}
