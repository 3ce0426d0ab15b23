// Multi-process tests of the Network Interface Layer: real herm-link
// processes, each with its own actor system, IO manager, device and channel,
// exchange packets of random sizes over UDP on loopback and over emulated
// media, fragmenting where the MTU is small. Every echo is verified byte for
// byte by the sender.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;

namespace {

const std::string herm_link = HERM_LINK_BIN;

std::string field(const std::string& line, const std::string& key) {
  auto pos = line.find(key + "=");
  if (pos == std::string::npos)
    return "";
  auto start = pos + key.size() + 1;
  return line.substr(start, line.find(' ', start) - start);
}

class temp_dir {
public:
  temp_dir() {
    char tmpl[] = "/tmp/herm-mp-XXXXXX";
    path_ = ::mkdtemp(tmpl);
  }
  ~temp_dir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const {
    return path_;
  }

private:
  std::string path_;
};

/// Starts an echo process, then a sender expecting every echo back intact.
void exchange(std::vector<std::string> echo_args,
              std::vector<std::string> send_args, const std::string& to_field,
              const std::string& count, const std::string& max_size,
              std::vector<std::string> send_opts = {}) {
  std::vector<std::string> e{herm_link};
  e.insert(e.end(), echo_args.begin(), echo_args.end());
  e.push_back("echo");
  child_process echo{e};
  ASSERT_TRUE(echo.started());
  auto ready = echo.wait_for_line("ready", 10s);
  ASSERT_TRUE(ready) << echo.output();
  std::vector<std::string> s{herm_link};
  s.insert(s.end(), send_args.begin(), send_args.end());
  if (!to_field.empty()) {
    s.push_back("-a");
    s.push_back(field(*ready, to_field));
  }
  for (auto x : {"send", "--expect-echo", "--count"})
    s.push_back(x);
  s.push_back(count);
  s.push_back("--max-size");
  s.push_back(max_size);
  s.insert(s.end(), send_opts.begin(), send_opts.end());
  child_process sender{{s}};
  auto status = sender.wait(120s);
  EXPECT_EQ(status, 0) << sender.output();
  auto done = sender.wait_for_line("done", 1s);
  ASSERT_TRUE(done) << sender.output();
  EXPECT_EQ(field(*done, "echoed"), count) << *done;
  EXPECT_EQ(field(*done, "bad"), "0") << *done;
  echo.terminate();
  EXPECT_EQ(echo.wait(10s), 0) << echo.output();
}

} // namespace

// UDP is lossy: a burst larger than the receiver's socket buffer is dropped
// by the kernel (end-to-end reliability is the reliable mode's job), so this
// test keeps one packet (up to 45 datagrams) in flight.
TEST(multiprocess, udp_processes_exchange_packets_up_to_64_kib_on_loopback) {
  exchange({"-k", "udp", "-i", "127.0.0.1:0", "-o", "rcvbuf=1048576"},
           {"-k", "udp", "-i", "127.0.0.1:0", "-o", "rcvbuf=1048576",
            "--timeout", "20"},
           "local", "40", "65536", {"--window", "1"});
}

TEST(multiprocess, emulated_can_bus_processes_exchange_fragmented_packets) {
  temp_dir dir;
  exchange({"-k", "emu", "-i", dir.path(), "-o", "profile=can2.0", "-o",
            "station=2"},
           {"-k", "emu", "-i", dir.path(), "-o", "profile=can2.0", "-o",
            "station=1", "--timeout", "30"},
           "local", "20", "600");
}

TEST(multiprocess, emulated_ieee1394_processes_exchange_large_packets) {
  temp_dir dir;
  exchange({"-k", "emu", "-i", dir.path(), "-o", "profile=ieee1394a", "-o",
            "station=2"},
           {"-k", "emu", "-i", dir.path(), "-o", "profile=ieee1394a", "-o",
            "station=1"},
           "local", "40", "65536");
}

TEST(multiprocess, emulated_rs232c_line_carries_fragmented_packets) {
  temp_dir dir;
  exchange({"-k", "emu", "-i", dir.path(), "-o", "profile=rs232c", "-o",
            "station=2"},
           {"-k", "emu", "-i", dir.path(), "-o", "profile=rs232c", "-o",
            "station=1", "--timeout", "30"},
           "local", "4", "100");
}

TEST(multiprocess, opening_a_bad_device_exits_with_a_typed_error) {
  child_process p{{herm_link, "-k", "udp", "-i", "300.1.2.3:1", "recv"}};
  EXPECT_EQ(p.wait(20s), 2) << p.output();
  EXPECT_NE(p.output().find("error herm.invalid_address"), std::string::npos)
    << p.output();
  EXPECT_NE(p.output().find("300.1.2.3"), std::string::npos) << p.output();
}

// Bursts far beyond the driver's transmit queue (8 packets of up to 3 KB in
// flight: thousands of 8-byte frames against a queue of 256): the channel
// holds the overflow in its backlog and loses nothing.
TEST(multiprocess, emulated_can_bus_bursts_beyond_the_driver_queue_lose_nothing) {
  temp_dir dir;
  auto bus = "emu:" + dir.path();
  exchange({"-k", "can", "-i", bus, "-o", "node=2"},
           {"-k", "can", "-i", bus, "-o", "node=1", "--timeout", "30"},
           "local", "20", "3000", {"--window", "8"});
}
