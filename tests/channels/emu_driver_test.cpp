// Tests of the "emu" link kind (channels/drivers/emu.cpp): an emulated medium
// of unix datagram sockets in a directory. Every test works in its own
// mkdtemp directory and removes it; waits are bounded; timing checks are
// lower bounds only (speed is measured in apps/bench/emu_bandwidth_bench).

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <ftw.h>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/drivers/emu_wire.hpp"
#include "channels/link_driver.hpp"
#include "tests/channels/recorder.hpp"

using namespace herm;
using namespace std::chrono_literals;
using herm::test::recorder;

namespace {

constexpr auto now_ns = recorder::now_ns;

byte_buffer bytes_of(const std::string& str) {
  return byte_buffer(str.begin(), str.end());
}

byte_buffer numbered(uint32_t i, size_t size = 4) {
  byte_buffer result(std::max<size_t>(size, 4), 0);
  std::memcpy(result.data(), &i, 4);
  return result;
}

uint32_t number_of(const byte_buffer& bytes) {
  uint32_t i = 0;
  std::memcpy(&i, bytes.data(), 4);
  return i;
}

bool exists(const std::string& path) {
  struct stat st;
  return ::lstat(path.c_str(), &st) == 0;
}

int remove_entry(const char* path, const struct stat*, int, FTW*) {
  return ::remove(path);
}

void remove_tree(const std::string& path) {
  ::nftw(path.c_str(), remove_entry, 16, FTW_DEPTH | FTW_PHYS);
}

/// A started driver and what it heard.
struct station {
  link_driver_ptr driver;
  std::shared_ptr<recorder> rec;

  caf::error send(link_addr dst, const byte_buffer& bytes) {
    return driver->send(dst, bytes.data(), bytes.size(), prio_normal);
  }
};

class emu_driver_test : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-emu-test-XXXXXX";
    ASSERT_NE(::mkdtemp(tmpl), nullptr) << std::strerror(errno);
    root_ = tmpl;
    medium_ = root_ + "/medium";
  }

  void TearDown() override {
    for (auto& d : drivers_)
      d->stop();
    drivers_.clear();
    if (!root_.empty())
      remove_tree(root_);
  }

  caf::expected<link_driver_ptr> open(const std::string& name,
                                      option_map options,
                                      const std::string& dir = "") {
    auto* kind = find_link_kind("emu");
    if (kind == nullptr)
      return make_error(ec::unknown_link_kind, "emu");
    device_config cfg{name, "emu", dir.empty() ? medium_ : dir,
                      std::move(options)};
    auto result = kind->open(cfg);
    if (result)
      drivers_.push_back(*result);
    return result;
  }

  /// Opens and starts a station; an empty driver on failure (recorded).
  station start(const std::string& name, option_map options,
                const std::string& dir = "") {
    station result;
    auto d = open(name, std::move(options), dir);
    if (!d) {
      ADD_FAILURE() << "cannot open " << name << ": " << render(d.error());
      return result;
    }
    result.driver = *d;
    result.rec = std::make_shared<recorder>();
    if (auto err = result.driver->start(result.rec)) {
      ADD_FAILURE() << "cannot start " << name << ": " << render(err);
      result.driver = nullptr;
    }
    return result;
  }

  std::string sock_path(uint64_t station) const {
    return medium_ + "/" + std::to_string(station) + ".sock";
  }

  /// Waits until get_param(key) of `d` reads `value`.
  static bool wait_param(const link_driver_ptr& d, const std::string& key,
                         const std::string& value,
                         std::chrono::milliseconds timeout = 10s) {
    auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      auto x = d->get_param(key);
      if (x && *x == value)
        return true;
      if (std::chrono::steady_clock::now() > deadline)
        return false;
      std::this_thread::sleep_for(1ms);
    }
  }

  std::string root_;
  std::string medium_;
  std::vector<link_driver_ptr> drivers_;
};

// -- basic exchange ----------------------------------------------------------------

TEST_F(emu_driver_test, unicast_to_an_absent_station_goes_nowhere) {
  auto a = start("fw0", {{"station", "1"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_FALSE(a.send(77, bytes_of("void")));
  EXPECT_FALSE(a.send(1, bytes_of("self")));
  ASSERT_FALSE(a.send(2, bytes_of("real")));
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_EQ(b.rec->frames()[0].bytes, bytes_of("real"));
  EXPECT_TRUE(a.rec->failures().empty());
  EXPECT_TRUE(a.rec->frames().empty());
}

// -- send errors --------------------------------------------------------------------

TEST_F(emu_driver_test, full_transmit_queue_refuses_frames) {
  // 100 bit/s: the first frame occupies the medium for 2.56 s, so nothing
  // leaves the queue while the test fills it. stop() must cut that short.
  auto a = start("slow0", {{"profile", "rs232c"},
                           {"bandwidth", "100"},
                           {"queue", "2"},
                           {"station", "1"}});
  ASSERT_TRUE(a.driver);
  size_t refused = 0;
  for (int i = 0; i < 4; ++i) {
    auto err = a.send(2, byte_buffer(32, 0)); // 2.56 s on the medium
    if (err) {
      EXPECT_TRUE(is(err, ec::queue_full)) << render(err);
      EXPECT_NE(render(err).find("device 'slow0'"), std::string::npos);
      ++refused;
    }
  }
  // Capacity: 2 queued plus at most 1 on the medium.
  EXPECT_GE(refused, 1u);
  a.driver->stop();
  auto err = a.send(2, bytes_of("late"));
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
}

// -- malformed input ----------------------------------------------------------------

TEST_F(emu_driver_test, malformed_datagrams_are_dropped_and_the_driver_keeps_working) {
  auto a = start("fw0", {{"station", "1"}, {"profile", "can2.0"}});
  auto b = start("fw1", {{"station", "2"}, {"profile", "can2.0"}});
  ASSERT_TRUE(a.driver && b.driver);
  int raw = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(raw, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  auto path = sock_path(2);
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  auto send_raw = [&](const byte_buffer& bytes) {
    return ::sendto(raw, bytes.data(), bytes.size(), 0,
                    reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
  };
  auto datagram = [](emu::wire_header hdr, size_t payload) {
    byte_buffer result(emu::wire_header_size + payload, 0x5A);
    emu::encode(hdr, result.data());
    return result;
  };
  emu::wire_header good;
  good.src = 9;
  good.deliver_at_ns = now_ns();
  auto bad_magic = good;
  bad_magic.magic = 0x1234;
  auto bad_version = good;
  bad_version.version = 99;
  auto bad_source = good;
  bad_source.src = 0;
  auto far_ahead = good;
  far_ahead.deliver_at_ns = now_ns() + 3600LL * 1'000'000'000;
  auto bad_flags = good;
  bad_flags.flags = 0x80;
  std::vector<byte_buffer> garbage{
    byte_buffer{1, 2, 3},   // shorter than the header
    datagram(good, 8 + 1),  // payload above the MTU of 8
    datagram(good, 4096),   // far above: read truncated, caught by MSG_TRUNC
    datagram(bad_magic, 4), datagram(bad_version, 4), datagram(bad_source, 4),
    datagram(far_ahead, 4), datagram(bad_flags, 4),
  };
  for (auto& g : garbage)
    ASSERT_EQ(send_raw(g), static_cast<ssize_t>(g.size()))
      << std::strerror(errno);
  ::close(raw);
  ASSERT_TRUE(b.rec->wait_malformed(garbage.size()));
  auto bad = b.rec->malformed_frames();
  ASSERT_EQ(bad.size(), garbage.size());
  EXPECT_EQ(bad[0].src, 0u); // no header, no source
  EXPECT_EQ(bad[1].src, 9u);
  for (auto& m : bad)
    EXPECT_NE(m.why.find("emu: "), std::string::npos) << m.why;
  EXPECT_NE(bad[0].why.find("shorter"), std::string::npos) << bad[0].why;
  EXPECT_NE(bad[1].why.find("MTU"), std::string::npos) << bad[1].why;
  EXPECT_NE(bad[2].why.find("MTU"), std::string::npos) << bad[2].why;
  EXPECT_NE(bad[3].why.find("magic"), std::string::npos) << bad[3].why;
  EXPECT_NE(bad[4].why.find("version"), std::string::npos) << bad[4].why;
  EXPECT_NE(bad[5].why.find("source"), std::string::npos) << bad[5].why;
  EXPECT_NE(bad[6].why.find("future"), std::string::npos) << bad[6].why;
  EXPECT_NE(bad[7].why.find("flags"), std::string::npos) << bad[7].why;
  // Still working: a real frame arrives, nothing bad was delivered.
  ASSERT_FALSE(a.send(2, bytes_of("ok")));
  ASSERT_TRUE(b.rec->wait_frames(1));
  auto frames = b.rec->frames();
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].bytes, bytes_of("ok"));
  EXPECT_TRUE(b.rec->failures().empty());
  EXPECT_EQ(*b.driver->get_param("rx_malformed"),
            std::to_string(garbage.size()));
}

// -- impairments ----------------------------------------------------------------------

TEST_F(emu_driver_test, loss_one_delivers_nothing_and_loss_zero_delivers_all) {
  auto a = start("fw0", {{"station", "1"}, {"loss", "1"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  constexpr uint32_t n = 20;
  for (uint32_t i = 0; i < n; ++i)
    ASSERT_FALSE(a.send(2, numbered(i)));
  // Every frame has been through the medium: all lost, so no datagram left.
  ASSERT_TRUE(wait_param(a.driver, "tx_lost", std::to_string(n)));
  ASSERT_FALSE(a.driver->set_param("loss", "0"));
  EXPECT_EQ(*a.driver->get_param("loss"), "0");
  for (uint32_t i = n; i < 2 * n; ++i)
    ASSERT_FALSE(a.send(2, numbered(i)));
  ASSERT_TRUE(b.rec->wait_frames(n));
  auto frames = b.rec->frames();
  ASSERT_EQ(frames.size(), n);
  for (uint32_t i = 0; i < n; ++i)
    EXPECT_EQ(number_of(frames[i].bytes), n + i);
  EXPECT_EQ(*a.driver->get_param("tx_lost"), std::to_string(n));
}

TEST_F(emu_driver_test, jitter_reorders_frames_but_delivers_all) {
  auto a = start("fw0", {{"station", "1"}, {"jitter_us", "20000"},
                         {"seed", "42"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  constexpr uint32_t n = 50;
  for (uint32_t i = 0; i < n; ++i)
    ASSERT_FALSE(a.send(2, numbered(i)));
  ASSERT_TRUE(b.rec->wait_frames(n));
  std::vector<uint32_t> order;
  for (auto& f : b.rec->frames())
    order.push_back(number_of(f.bytes));
  ASSERT_EQ(order.size(), n);
  EXPECT_FALSE(std::is_sorted(order.begin(), order.end()));
  std::sort(order.begin(), order.end());
  for (uint32_t i = 0; i < n; ++i)
    EXPECT_EQ(order[i], i);
}

TEST_F(emu_driver_test, duplicate_one_delivers_every_frame_twice) {
  auto a = start("fw0", {{"station", "1"}, {"duplicate", "1"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  for (uint32_t i = 0; i < 5; ++i)
    ASSERT_FALSE(a.send(2, numbered(i)));
  ASSERT_TRUE(b.rec->wait_frames(10));
  auto frames = b.rec->frames();
  ASSERT_EQ(frames.size(), 10u);
  for (uint32_t i = 0; i < 10; ++i)
    EXPECT_EQ(number_of(frames[i].bytes), i / 2);
}

TEST_F(emu_driver_test, a_corrupted_frame_fails_the_receivers_frame_check) {
  // As on Ethernet, IEEE 1394 or USB, whose frames carry a CRC: a frame
  // with a flipped bit is dropped by the receiving interface and counted.
  auto a = start("fw0", {{"station", "1"}, {"corrupt", "1"}, {"seed", "7"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  byte_buffer sent(64, 0);
  for (int i = 0; i < 10; ++i)
    ASSERT_FALSE(a.send(2, sent));
  ASSERT_TRUE(b.rec->wait_malformed(10));
  EXPECT_TRUE(b.rec->frames().empty());
}

TEST_F(emu_driver_test, corrupt_one_flips_exactly_one_payload_bit) {
  // Without the frame check (frame_check: false) the corrupted frame is
  // delivered, so the layers above can be tested against it.
  auto a = start("fw0", {{"station", "1"}, {"corrupt", "1"}, {"seed", "7"}});
  auto b = start("fw1", {{"station", "2"}, {"frame_check", "false"}});
  ASSERT_TRUE(a.driver && b.driver);
  byte_buffer sent(64, 0);
  for (int i = 0; i < 10; ++i)
    ASSERT_FALSE(a.send(2, sent));
  ASSERT_TRUE(b.rec->wait_frames(10));
  for (auto& f : b.rec->frames()) {
    ASSERT_EQ(f.bytes.size(), sent.size());
    int flipped = 0;
    for (auto byte : f.bytes)
      flipped += __builtin_popcount(byte);
    EXPECT_EQ(flipped, 1);
  }
}

// -- timing (lower bounds only) ---------------------------------------------------------

TEST_F(emu_driver_test, sending_n_frames_takes_at_least_n_frame_times) {
  // 80,000 bit/s, 100-byte frames, no overhead: 10 ms per frame.
  option_map opts{{"profile", "usb1.1"}, {"bandwidth", "80000"},
                  {"frame_overhead_bits", "0"}};
  auto a_opts = opts;
  a_opts["station"] = "1";
  auto b_opts = opts;
  b_opts["station"] = "2";
  auto a = start("usb0", a_opts);
  auto b = start("usb1", b_opts);
  ASSERT_TRUE(a.driver && b.driver);
  constexpr uint32_t n = 20;
  constexpr int64_t frame_ns = 10'000'000;
  auto t0 = now_ns();
  for (uint32_t i = 0; i < n; ++i)
    ASSERT_FALSE(a.send(2, numbered(i, 100)));
  ASSERT_TRUE(b.rec->wait_frames(n));
  auto frames = b.rec->frames();
  for (uint32_t i = 0; i < n; ++i)
    EXPECT_GE(frames[i].at_ns - t0, int64_t(i + 1) * frame_ns) << "frame " << i;
}

TEST_F(emu_driver_test, latency_delays_every_frame_by_at_least_its_value) {
  auto a = start("fw0", {{"station", "1"}, {"latency_us", "50000"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  auto t0 = now_ns();
  ASSERT_FALSE(a.send(2, bytes_of("late")));
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_GE(b.rec->frames()[0].at_ns - t0, 50'000'000);
}

// -- failure and recovery ------------------------------------------------------------

TEST_F(emu_driver_test, removing_the_socket_file_reports_failure_exactly_once) {
  auto a = start("fw0", {{"station", "1"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  ASSERT_EQ(::unlink(sock_path(2).c_str()), 0);
  ASSERT_TRUE(b.rec->wait_failures(1));
  // Several liveness periods (100 ms) later there is still only one.
  std::this_thread::sleep_for(400ms);
  auto failures = b.rec->failures();
  ASSERT_EQ(failures.size(), 1u);
  EXPECT_TRUE(is(failures[0], ec::device_failed)) << render(failures[0]);
  auto text = render(failures[0]);
  EXPECT_NE(text.find("device 'fw1'"), std::string::npos) << text;
  EXPECT_NE(text.find(sock_path(2) + " removed"), std::string::npos) << text;
  EXPECT_TRUE(is(b.send(1, bytes_of("x")), ec::device_failed));
  EXPECT_TRUE(a.rec->failures().empty());
}

TEST_F(emu_driver_test, a_recreated_medium_directory_opens_again) {
  auto a = start("fw0", {{"station", "1"}});
  auto b = start("fw1", {{"station", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  remove_tree(medium_);
  ASSERT_TRUE(a.rec->wait_failures(1));
  ASSERT_TRUE(b.rec->wait_failures(1));
  auto c = start("fw2", {{"station", "1"}});
  auto d = start("fw3", {{"station", "2"}});
  ASSERT_TRUE(c.driver && d.driver);
  // Stopping the old drivers must not remove the new stations' files.
  a.driver->stop();
  b.driver->stop();
  EXPECT_TRUE(exists(sock_path(1)));
  EXPECT_TRUE(exists(sock_path(2)));
  ASSERT_FALSE(c.send(2, bytes_of("again")));
  ASSERT_TRUE(d.rec->wait_frames(1));
  EXPECT_EQ(d.rec->frames()[0].bytes, bytes_of("again"));
  EXPECT_TRUE(c.rec->failures().empty());
  EXPECT_TRUE(d.rec->failures().empty());
}

TEST_F(emu_driver_test, stop_is_idempotent_and_removes_only_the_socket_file) {
  auto a = start("fw0", {{"station", "4"}});
  ASSERT_TRUE(a.driver);
  EXPECT_TRUE(exists(sock_path(4)));
  a.driver->stop();
  a.driver->stop();
  EXPECT_FALSE(exists(sock_path(4)));
  EXPECT_TRUE(exists(medium_ + "/medium"));
  EXPECT_TRUE(a.rec->failures().empty());
  auto again = a.driver->start(a.rec);
  EXPECT_TRUE(is(again, ec::device_unavailable)) << render(again);
  EXPECT_NE(render(again).find("device 'fw0': already stopped"),
            std::string::npos)
    << render(again);
}

TEST_F(emu_driver_test, stale_socket_file_of_a_dead_station_is_taken_over) {
  ASSERT_EQ(::mkdir(medium_.c_str(), 0700), 0);
  // A socket file nobody is bound to any more, as a crashed process leaves.
  int raw = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(raw, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  auto path = sock_path(1);
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  ASSERT_EQ(::bind(raw, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  ::close(raw);
  ASSERT_TRUE(exists(path));
  auto a = start("fw0", {{"station", "1"}});
  ASSERT_TRUE(a.driver);
  EXPECT_EQ(a.driver->local_addr(), 1u);
}

// -- opening: stations, forms, errors ------------------------------------------------

TEST_F(emu_driver_test, default_station_is_the_lowest_free_number) {
  auto a = start("fw0", {});
  auto b = start("fw1", {});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_EQ(a.driver->local_addr(), 1u);
  EXPECT_EQ(b.driver->local_addr(), 2u);
  a.driver->stop();
  auto c = start("fw2", {});
  ASSERT_TRUE(c.driver);
  EXPECT_EQ(c.driver->local_addr(), 1u);
}

TEST_F(emu_driver_test, a_taken_station_is_refused) {
  auto a = start("fw0", {{"station", "3"}});
  ASSERT_TRUE(a.driver);
  auto b = open("fw1", {{"station", "3"}});
  ASSERT_FALSE(b);
  EXPECT_TRUE(is(b.error(), ec::already_exists)) << render(b.error());
  auto text = render(b.error());
  EXPECT_NE(text.find("device 'fw1'"), std::string::npos) << text;
  EXPECT_NE(text.find("station 3"), std::string::npos) << text;
  EXPECT_NE(text.find(medium_), std::string::npos) << text;
}

TEST_F(emu_driver_test, point_to_point_medium_refuses_a_third_station) {
  auto a = start("usb0", {{"profile", "usb1.1"}});
  auto b = start("usb1", {{"profile", "usb1.1"}});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_EQ(*a.driver->get_param("form"), "p2p");
  auto c = open("usb2", {{"profile", "usb1.1"}});
  ASSERT_FALSE(c);
  EXPECT_TRUE(is(c.error(), ec::device_unavailable)) << render(c.error());
  auto text = render(c.error());
  EXPECT_NE(text.find("device 'usb2'"), std::string::npos) << text;
  EXPECT_NE(text.find(medium_), std::string::npos) << text;
  EXPECT_NE(text.find("point-to-point"), std::string::npos) << text;
  // A bus device cannot join a medium in use as a p2p link either.
  auto d = open("usb3", {{"profile", "usb1.1"}, {"form", "bus"}});
  ASSERT_FALSE(d);
  EXPECT_TRUE(is(d.error(), ec::device_unavailable)) << render(d.error());
  // Once a station leaves, there is room again.
  b.driver->stop();
  auto e = open("usb4", {{"profile", "usb1.1"}});
  EXPECT_TRUE(e) << render(e.error());
}

TEST_F(emu_driver_test, point_to_point_stations_exchange_in_both_directions) {
  auto a = start("usb0", {{"profile", "usb1.1"}});
  auto b = start("usb1", {{"profile", "usb1.1"}});
  ASSERT_TRUE(a.driver && b.driver);
  ASSERT_FALSE(a.send(broadcast_addr, bytes_of("to b")));
  ASSERT_FALSE(b.send(a.driver->local_addr(), bytes_of("to a")));
  ASSERT_TRUE(a.rec->wait_frames(1));
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_EQ(a.rec->frames()[0].bytes, bytes_of("to a"));
  EXPECT_EQ(b.rec->frames()[0].bytes, bytes_of("to b"));
}

struct option_error_case {
  option_map options;
  ec code;
  const char* mentions; // besides "device 'fw9'"
};

TEST_F(emu_driver_test, option_errors_name_the_device_and_the_option) {
  std::vector<option_error_case> cases{
    {{{"loss", "2"}}, ec::invalid_parameter, "'loss'"},
    {{{"loss", "lots"}}, ec::invalid_parameter, "'loss'"},
    {{{"duplicate", "-0.5"}}, ec::invalid_parameter, "'duplicate'"},
    {{{"corrupt", "1.5"}}, ec::invalid_parameter, "'corrupt'"},
    {{{"station", "0"}}, ec::invalid_parameter, "'station'"},
    {{{"station", "255"}}, ec::invalid_parameter, "'station'"},
    {{{"form", "ring"}}, ec::invalid_parameter, "'form'"},
    {{{"queue", "0"}}, ec::invalid_parameter, "'queue'"},
    {{{"latency_us", "-1"}}, ec::invalid_parameter, "'latency_us'"},
    {{{"jitter_us", "99999999999"}}, ec::invalid_parameter, "'jitter_us'"},
    {{{"seed", "x"}}, ec::invalid_parameter, "'seed'"},
    {{{"create", "maybe"}}, ec::invalid_parameter, "'create'"},
    {{{"profile", "token-ring"}}, ec::invalid_parameter, "'profile'"},
    {{{"mtu", "0"}}, ec::invalid_parameter, "'mtu'"},
    {{{"lose", "0.1"}}, ec::invalid_parameter, "'lose'"},
  };
  for (auto& c : cases) {
    auto d = open("fw9", c.options);
    ASSERT_FALSE(d) << c.mentions;
    auto text = render(d.error());
    EXPECT_TRUE(is(d.error(), c.code)) << text;
    EXPECT_NE(text.find("device 'fw9'"), std::string::npos) << text;
    EXPECT_NE(text.find(c.mentions), std::string::npos) << text;
  }
  // Nothing was created for refused options.
  EXPECT_FALSE(exists(medium_));
}

TEST_F(emu_driver_test, opening_errors_name_the_device_and_the_medium) {
  auto missing = open("fw0", {{"create", "false"}});
  ASSERT_FALSE(missing);
  EXPECT_TRUE(is(missing.error(), ec::device_unavailable));
  auto text = render(missing.error());
  EXPECT_NE(text.find("device 'fw0'"), std::string::npos) << text;
  EXPECT_NE(text.find(medium_), std::string::npos) << text;
  EXPECT_NE(text.find("does not exist"), std::string::npos) << text;

  auto file = root_ + "/plain";
  ASSERT_EQ(::close(::open(file.c_str(), O_CREAT | O_WRONLY, 0600)), 0);
  auto not_dir = open("fw2", {}, file);
  ASSERT_FALSE(not_dir);
  EXPECT_TRUE(is(not_dir.error(), ec::device_unavailable));
  EXPECT_NE(render(not_dir.error()).find("not a directory"), std::string::npos)
    << render(not_dir.error());

  auto too_long = open("fw3", {}, root_ + "/" + std::string(120, 'x'));
  ASSERT_FALSE(too_long);
  EXPECT_TRUE(is(too_long.error(), ec::invalid_parameter));
  EXPECT_NE(render(too_long.error()).find("too long"), std::string::npos);

  auto foreign = root_ + "/foreign";
  ASSERT_EQ(::mkdir(foreign.c_str(), 0700), 0);
  int fd = ::open((foreign + "/medium").c_str(), O_CREAT | O_WRONLY, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::write(fd, "hello", 5), 5);
  ::close(fd);
  auto bad_medium = open("fw4", {}, foreign);
  ASSERT_FALSE(bad_medium);
  EXPECT_TRUE(is(bad_medium.error(), ec::device_unavailable));
  EXPECT_NE(render(bad_medium.error()).find("not an emu medium file"),
            std::string::npos)
    << render(bad_medium.error());
}

// -- parameters and addresses --------------------------------------------------------

TEST_F(emu_driver_test, parameters_change_at_run_time) {
  auto a = start("fw0", {{"latency_us", "10"}});
  ASSERT_TRUE(a.driver);
  EXPECT_EQ(*a.driver->get_param("bandwidth"), "400000000");
  EXPECT_EQ(*a.driver->get_param("mtu"), "4096");
  EXPECT_EQ(*a.driver->get_param("latency_us"), "10");
  ASSERT_FALSE(a.driver->set_param("bandwidth", "1000000"));
  ASSERT_FALSE(a.driver->set_param("latency_us", "2500"));
  ASSERT_FALSE(a.driver->set_param("jitter_us", "30"));
  ASSERT_FALSE(a.driver->set_param("loss", "0.25"));
  EXPECT_EQ(*a.driver->get_param("bandwidth"), "1000000");
  EXPECT_EQ(*a.driver->get_param("latency_us"), "2500");
  EXPECT_EQ(*a.driver->get_param("jitter_us"), "30");
  EXPECT_EQ(*a.driver->get_param("loss"), "0.25");
  auto bad = a.driver->set_param("loss", "3");
  EXPECT_TRUE(is(bad, ec::invalid_parameter));
  EXPECT_NE(render(bad).find("'loss'"), std::string::npos) << render(bad);
  EXPECT_NE(render(bad).find("device 'fw0'"), std::string::npos);
  auto fixed = a.driver->set_param("mtu", "100");
  EXPECT_TRUE(is(fixed, ec::invalid_parameter));
  EXPECT_NE(render(fixed).find("'mtu'"), std::string::npos) << render(fixed);
  auto unknown = a.driver->get_param("colour");
  ASSERT_FALSE(unknown);
  EXPECT_TRUE(is(unknown.error(), ec::invalid_parameter));
}

TEST_F(emu_driver_test, addresses_are_station_numbers) {
  auto a = start("fw0", {});
  ASSERT_TRUE(a.driver);
  EXPECT_EQ(a.driver->format_addr(3), "3");
  EXPECT_EQ(*a.driver->parse_addr("3"), 3u);
  EXPECT_EQ(*a.driver->parse_addr("254"), 254u);
  for (auto text : {"0", "255", "", "abc", "-1", "3x", " 3", "1000"}) {
    auto x = a.driver->parse_addr(text);
    ASSERT_FALSE(x) << text;
    EXPECT_TRUE(is(x.error(), ec::invalid_address));
    EXPECT_NE(render(x.error()).find(std::string{"'"} + text + "'"),
              std::string::npos)
      << render(x.error());
  }
}

// -- across processes ---------------------------------------------------------------

/// Child side of the multi-process test: station 2 echoes every frame back
/// to its sender until it hears "quit". Never returns.
[[noreturn]] void run_echo_child(const std::string& medium, int ready_fd) {
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  ::alarm(60); // never outlive a broken parent for long
  struct echo : frame_handler {
    std::mutex mtx;
    std::condition_variable cv;
    link_driver* driver = nullptr;
    bool quit = false;
    bool send_failed = false;
    void on_frame(link_addr src, const uint8_t* data, size_t size) override {
      std::lock_guard<std::mutex> guard{mtx};
      if (std::string(data, data + size) == "quit") {
        quit = true;
        cv.notify_all();
      } else if (driver->send(src, data, size, prio_normal)) {
        send_failed = true;
      }
    }
    void on_malformed(link_addr, const char*) override {}
    void on_event(link_event_kind, link_addr, std::string) override {}
    void on_failure(caf::error) override {
      std::lock_guard<std::mutex> guard{mtx};
      send_failed = true;
      quit = true;
      cv.notify_all();
    }
  };
  auto handler = std::make_shared<echo>();
  int status = 1;
  // A loop of its own: the process's shared io thread, if the parent had
  // started it before the fork, does not run in the child.
  auto io = io_thread::make();
  if (io) {
    device_config cfg{"child0", "emu", medium, {{"station", "2"}}};
    auto d = find_link_kind("emu")->open(cfg);
    if (d) {
      handler->driver = d->get();
      if (!(*d)->start(handler, (*io)->loop())) {
        char ok = 'R';
        if (::write(ready_fd, &ok, 1) == 1) {
          std::unique_lock<std::mutex> lk{handler->mtx};
          if (handler->cv.wait_for(lk, 30s, [&] { return handler->quit; })
              && !handler->send_failed)
            status = 0;
        }
      }
      (*d)->stop();
    }
  }
  ::close(ready_fd);
  ::_exit(status);
}

TEST_F(emu_driver_test, a_station_in_another_process_echoes_frames) {
  // Fork before this process starts any driver thread.
  int pipe_fds[2];
  ASSERT_EQ(::pipe(pipe_fds), 0);
  auto pid = ::fork();
  ASSERT_GE(pid, 0) << std::strerror(errno);
  if (pid == 0) {
    ::close(pipe_fds[0]);
    run_echo_child(medium_, pipe_fds[1]);
  }
  ::close(pipe_fds[1]);
  auto reap = [pid](std::chrono::milliseconds timeout) {
    // Waits for the child; kills it when it does not exit in time.
    auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    for (;;) {
      auto rc = ::waitpid(pid, &status, WNOHANG);
      if (rc == pid)
        return status;
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &status, 0);
        return -1;
      }
      std::this_thread::sleep_for(5ms);
    }
  };
  pollfd pfd{pipe_fds[0], POLLIN, 0};
  char ready = 0;
  bool child_ready = ::poll(&pfd, 1, 10'000) == 1
                     && ::read(pipe_fds[0], &ready, 1) == 1 && ready == 'R';
  ::close(pipe_fds[0]);
  if (!child_ready) {
    reap(0ms);
    FAIL() << "the child did not open its station";
  }
  auto a = start("fw0", {{"station", "1"}});
  if (!a.driver) {
    reap(0ms);
    FAIL() << "cannot open the parent's station";
  }
  constexpr uint32_t n = 50;
  for (uint32_t i = 0; i < n; ++i)
    EXPECT_FALSE(a.send(2, numbered(i, 256)));
  bool echoed = a.rec->wait_frames(n);
  EXPECT_FALSE(a.send(2, bytes_of("quit")));
  auto status = reap(echoed ? 10s : 0ms);
  ASSERT_TRUE(echoed) << "got " << a.rec->frames().size() << " of " << n;
  ASSERT_NE(status, -1) << "the child did not exit and was killed";
  ASSERT_TRUE(WIFEXITED(status)) << "child status " << status;
  EXPECT_EQ(WEXITSTATUS(status), 0);
  auto frames = a.rec->frames();
  ASSERT_EQ(frames.size(), n);
  for (uint32_t i = 0; i < n; ++i) {
    EXPECT_EQ(frames[i].src, 2u);
    EXPECT_EQ(frames[i].bytes, numbered(i, 256));
  }
  // The child removed its socket file when it stopped.
  EXPECT_FALSE(exists(sock_path(2)));
}

// -- pure helpers ----------------------------------------------------------------------

TEST(emu_wire, header_round_trips) {
  emu::wire_header h;
  h.flags = emu::flag_broadcast;
  h.src = 17;
  h.deliver_at_ns = 123'456'789'012;
  uint8_t buf[emu::wire_header_size];
  emu::encode(h, buf);
  auto g = emu::decode(buf);
  EXPECT_EQ(g.magic, emu::wire_magic);
  EXPECT_EQ(g.version, emu::wire_version);
  EXPECT_EQ(g.flags, h.flags);
  EXPECT_EQ(g.src, 17);
  EXPECT_EQ(g.deliver_at_ns, h.deliver_at_ns);
}

TEST(emu_wire, frame_time_counts_payload_and_overhead_bits) {
  struct {
    size_t payload;
    uint32_t overhead;
    uint64_t bandwidth;
    int64_t expected_ns;
  } cases[] = {
    {8, 47, 1'000'000, 111'000},            // can2.0: 111 bits at 1 Mbit/s
    {1500, 528, 100'000'000, 125'280},       // ethernet
    {4096, 160, 400'000'000, 82'320},        // ieee1394a
    {32, 0, 19'200, 13'333'334},             // rs232c, rounded up
    {0, 0, 1'000'000, 0},
  };
  for (auto& c : cases)
    EXPECT_EQ(emu::frame_time_ns(c.payload, c.overhead, c.bandwidth),
              c.expected_ns)
      << c.payload << " bytes at " << c.bandwidth;
}

TEST(emu_wire, transmission_starts_back_to_back_within_the_credit) {
  struct {
    int64_t busy, enqueued, now, credit, expected;
  } cases[] = {
    {100, 50, 120, 1000, 100},  // queued behind the previous frame
    {100, 150, 160, 1000, 150}, // medium idle when queued: starts then
    {0, 50, 5000, 1000, 4000},  // long stall: credit bounds the backlog
    {9000, 50, 5000, 1000, 9000}, // busy in the future: wait for it
  };
  for (auto& c : cases)
    EXPECT_EQ(emu::transmission_start(c.busy, c.enqueued, c.now, c.credit),
              c.expected);
}

} // namespace
