// One specification for every link kind: what the link_driver contract
// (channels/link_driver.hpp) promises, checked on each kind in turn. The
// kinds: udp on loopback, serial over a pty null-modem cable, can on the
// emulated bus, emu, inproc, and "pair", a link kind this file defines and
// adds at run time (docs/architecture.md, "Adding a link kind"), which the
// IO manager then opens by name like any other.
//
// A kind's differences are data in its fixture (stations, empty frames,
// counters, addresses outside its address space), never an if in a test.
// What only one medium does (termios, SocketCAN, UDP peers and multicast,
// emu impairments, timing) stays in that kind's own test file.
//
// Every wait is bounded; no test asserts speed.

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/io_manager.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"
#include "channels/testing/loopback.hpp"
#include "channels/testing/null_modem.hpp"
#include "channels/type_ids.hpp"
#include "tests/channels/pair_driver.hpp"
#include "tests/channels/recorder.hpp"
#include "tests/support/temp_dir.hpp"

namespace herm {
namespace {

using namespace std::chrono_literals;
using test::recorder;

// -- "pair": a link kind defined outside the library ---------------------------

// Its driver, test::pair_driver, is in tests/channels/pair_driver.hpp.

/// Ends waiting for their second device, by interface name.
std::mutex pending_mtx;
std::map<std::string, int> pending_ends;

caf::expected<link_driver_ptr> open_pair(const device_config& cfg) {
  option_reader opts{cfg};
  auto profile = opts.profile("usb2.0");
  if (!profile)
    return profile.error();
  if (auto err = opts.finish())
    return err;
  std::lock_guard<std::mutex> guard{pending_mtx};
  if (auto i = pending_ends.find(cfg.interface); i != pending_ends.end()) {
    auto fd = i->second;
    pending_ends.erase(i);
    return link_driver_ptr{
      std::make_shared<test::pair_driver>(cfg.name, fd, 2, *profile)};
  }
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, fds) != 0)
    return opts.fail(ec::device_unavailable, std::strerror(errno));
  pending_ends[cfg.interface] = fds[1];
  return link_driver_ptr{
    std::make_shared<test::pair_driver>(cfg.name, fds[0], 1, *profile)};
}

// [add-link-kind]
const link_kind& pair_link_kind() {
  static const link_kind kind{"pair", "socket pair between two drivers",
                              open_pair};
  return kind;
}

// Before the first device of the kind is added: here at start-up.
const caf::error pair_added = add_link_kind(pair_link_kind());
// [add-link-kind-end]

// -- the link kinds under test, as data -------------------------------------------

/// Defaults for a kind's fixture; each kind overrides what differs. A
/// fixture prepares the medium (prepare: "" or why the test must skip),
/// names station i's device (config), and says what to expect.
struct kind_defaults {
  /// Stations the suite opens: 3 on a multi-access medium, 2 on a line.
  static constexpr size_t stations = 3;
  /// Empty frames are carried (else refused with ec::invalid_parameter).
  static constexpr bool empty_frames = true;
  /// get_param offers "tx_frames" and "rx_frames".
  static constexpr bool frame_counters = true;
  /// get_param offers "rx_malformed".
  static constexpr bool malformed_counter = true;
  /// After stop, send fails with ec::device_failed and start with
  /// ec::device_unavailable.
  static constexpr bool stop_is_final = true;
  /// Errors start with "device 'NAME'".
  static constexpr bool errors_name_the_device = true;
  /// inject_malformed works (a test can put bad bytes on the medium).
  static constexpr bool injects_malformed = false;
  /// Handler calls happen on the event loop's thread (else on the
  /// sender's: inproc).
  static constexpr bool delivers_on_the_loop = true;

  std::string prepare() {
    return "";
  }

  /// The address station `to` has for the others, and the source address
  /// its frames carry when they arrive.
  link_addr dest(const link_driver& to) const {
    return to.local_addr();
  }

  link_addr source(const link_driver& from) const {
    return from.local_addr();
  }

  /// Addresses no station can have: send refuses them.
  std::vector<link_addr> invalid_dests() const {
    return {};
  }

  /// Makes station `to` receive something malformed (its on_malformed runs
  /// at least once), if need be with the help of `from`, another station's
  /// driver; false if that failed.
  bool inject_malformed(size_t, link_driver&) {
    return false;
  }
};

struct udp_kind : kind_defaults {
  static constexpr bool injects_malformed = true;
  static constexpr const char* name = "udp";
  static constexpr const char* profile = "ethernet";
  static constexpr bool empty_frames = false;
  static constexpr bool frame_counters = false;
  static constexpr bool malformed_counter = false;
  uint16_t ports[3] = {};

  std::string prepare() {
    for (auto& p : ports)
      if ((p = test::free_udp_port()) == 0)
        return "no UDP port on 127.0.0.1";
    return "";
  }

  static std::string endpoint(uint16_t port) {
    return "127.0.0.1:" + std::to_string(port);
  }

  device_config config(size_t i) const {
    // Every station's peers list holds the whole segment, itself included,
    // as when all modules share one configuration.
    std::string peers;
    for (auto p : ports)
      peers += (peers.empty() ? "" : ",") + endpoint(p);
    return {"eth" + std::to_string(i), name, endpoint(ports[i]),
            {{"peers", peers}}};
  }

  link_addr local(size_t i) const {
    return (link_addr{0x7F000001} << 16) | ports[i];
  }

  std::vector<link_addr> invalid_dests() const {
    return {link_addr{1} << 48, link_addr{0x7F000001} << 16}; // port 0
  }

  bool inject_malformed(size_t to, link_driver&) {
    int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    sa.sin_port = htons(ports[to]);
    bool ok = fd >= 0
              && ::sendto(fd, "", 0, 0, reinterpret_cast<sockaddr*>(&sa),
                          sizeof(sa))
                   == 0;
    if (fd >= 0)
      ::close(fd);
    return ok; // an empty datagram
  }
};

/// Sends a 3-byte datagram, shorter than any medium header, to a station's
/// socket of the emulated media (emu, can on "emu:DIR").
bool send_runt(const std::string& sock_path) {
  int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un sa{};
  sa.sun_family = AF_UNIX;
  std::strncpy(sa.sun_path, sock_path.c_str(), sizeof(sa.sun_path) - 1);
  bool ok = fd >= 0
            && ::sendto(fd, "abc", 3, 0, reinterpret_cast<sockaddr*>(&sa),
                        sizeof(sa))
                 == 3;
  if (fd >= 0)
    ::close(fd);
  return ok;
}

struct emu_kind : kind_defaults {
  static constexpr bool injects_malformed = true;
  static constexpr const char* name = "emu";
  static constexpr const char* profile = "ieee1394a";
  test::temp_dir dir{"herm-conformance-emu"};

  std::string prepare() {
    return dir.path().empty() ? "cannot create a temporary directory" : "";
  }

  device_config config(size_t i) const {
    return {"fw" + std::to_string(i), name, dir.path() + "/medium",
            {{"station", std::to_string(i + 1)}}};
  }

  link_addr local(size_t i) const {
    return i + 1;
  }

  std::vector<link_addr> invalid_dests() const {
    return {0, 255, link_addr{1} << 40};
  }

  bool inject_malformed(size_t to, link_driver&) {
    return send_runt(dir.path() + "/medium/" + std::to_string(to + 1)
                     + ".sock");
  }
};

struct can_kind : kind_defaults {
  static constexpr bool injects_malformed = true;
  static constexpr const char* name = "can";
  static constexpr const char* profile = "can2.0";
  test::temp_dir dir{"herm-conformance-can"};

  std::string prepare() {
    return dir.path().empty() ? "cannot create a temporary directory" : "";
  }

  device_config config(size_t i) const {
    return {"can" + std::to_string(i), name, "emu:" + dir.path() + "/bus",
            {{"node", std::to_string(i + 1)}}};
  }

  link_addr local(size_t i) const {
    return i + 1;
  }

  std::vector<link_addr> invalid_dests() const {
    return {0, 255, link_addr{1} << 40};
  }

  bool inject_malformed(size_t to, link_driver&) {
    return send_runt(dir.path() + "/bus/" + std::to_string(to + 1) + ".sock");
  }
};

struct serial_kind : kind_defaults {
  static constexpr bool injects_malformed = true;
  static constexpr const char* name = "serial";
  static constexpr const char* profile = "rs232c";
  static constexpr size_t stations = 2;
  static constexpr bool empty_frames = false;
  std::unique_ptr<test::null_modem> cable;

  std::string prepare() {
    std::string error;
    cable = test::null_modem::open({}, error);
    return cable ? "" : "no pseudo-terminals: " + error;
  }

  device_config config(size_t i) const {
    return {"tty" + std::to_string(i), name,
            i == 0 ? cable->path_a() : cable->path_b(), {{"baud", "115200"}}};
  }

  /// Each end calls itself "local" (0) and the other end "peer" (1).
  link_addr local(size_t) const {
    return 0;
  }

  link_addr dest(const link_driver&) const {
    return 1;
  }

  link_addr source(const link_driver&) const {
    return 1;
  }

  std::vector<link_addr> invalid_dests() const {
    return {0, 2};
  }

  /// Line noise: every byte of one frame `from` sends gets a bit flipped.
  bool inject_malformed(size_t to, link_driver& from);
};

struct inproc_kind : kind_defaults {
  static constexpr const char* name = "inproc";
  static constexpr const char* profile = "ethernet";
  static constexpr bool frame_counters = false;
  static constexpr bool malformed_counter = false;
  static constexpr bool stop_is_final = false;
  static constexpr bool delivers_on_the_loop = false;
  static constexpr bool errors_name_the_device = false;

  device_config config(size_t i) const {
    auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    return {"lan" + std::to_string(i), name,
            std::string{"conformance-"} + info->name(),
            {{"station", std::to_string(i + 1)}}};
  }

  link_addr local(size_t i) const {
    return i + 1;
  }
};

struct pair_kind : kind_defaults {
  static constexpr const char* name = "pair";
  static constexpr const char* profile = "usb2.0";
  static constexpr size_t stations = 2;
  static constexpr bool empty_frames = false;
  static constexpr bool frame_counters = false;
  static constexpr bool malformed_counter = false;

  device_config config(size_t i) const {
    auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    return {"pair" + std::to_string(i), name, info->name(), {}};
  }

  link_addr local(size_t i) const {
    return i + 1;
  }

  std::vector<link_addr> invalid_dests() const {
    return {0, 3};
  }
};

// -- the fixture -----------------------------------------------------------------

byte_buffer pattern(size_t size, uint8_t seed) {
  byte_buffer result(size);
  for (size_t i = 0; i < size; ++i)
    result[i] = static_cast<uint8_t>(seed + i * 7);
  return result;
}

byte_buffer bytes_of(const std::string& text) {
  return byte_buffer(text.begin(), text.end());
}

/// A started driver and what it heard.
struct station {
  link_driver_ptr driver;
  std::shared_ptr<recorder> rec = std::make_shared<recorder>();

  caf::error send(link_addr dst, const byte_buffer& bytes) const {
    return driver->send(dst, bytes.data(), bytes.size(), prio_normal);
  }

  /// A counter from get_param; -1 when the driver has none of that name.
  int64_t counter(const std::string& key) const {
    auto x = driver->get_param(key);
    return x ? std::stoll(*x) : -1;
  }

  /// Waits until counter `key` reads `n`.
  bool wait_counter(const std::string& key, int64_t n) const {
    auto deadline = std::chrono::steady_clock::now() + 10s;
    while (counter(key) != n) {
      if (std::chrono::steady_clock::now() > deadline)
        return false;
      std::this_thread::sleep_for(1ms);
    }
    return true;
  }
};

template <class Kind>
class driver_conformance : public ::testing::Test {
protected:
  void SetUp() override {
    if (auto why = kind_.prepare(); !why.empty())
      GTEST_SKIP() << why;
  }

  void TearDown() override {
    for (auto& st : stations_)
      if (st.driver)
        st.driver->stop();
  }

  caf::expected<link_driver_ptr> open(size_t i) {
    auto* kind = find_link_kind(Kind::name);
    if (kind == nullptr)
      return make_error(ec::unknown_link_kind, Kind::name);
    return kind->open(kind_.config(i));
  }

  /// Opens and starts every station on `loop` (default: the process's
  /// shared loop); hooks[i] runs on each frame of i.
  void start_all(
    std::map<size_t, std::function<void(const recorder::frame&)>> hooks = {},
    event_loop* loop = nullptr) {
    stations_.resize(Kind::stations);
    for (size_t i = 0; i < Kind::stations; ++i) {
      auto d = open(i);
      ASSERT_TRUE(d) << "station " << i << ": " << render(d.error());
      stations_[i].driver = *d;
      if (hooks.count(i) > 0)
        stations_[i].rec->on_each_frame(hooks[i]);
      auto& st = stations_[i];
      ASSERT_FALSE(loop != nullptr ? st.driver->start(st.rec, *loop)
                                   : st.driver->start(st.rec))
        << "station " << i;
    }
  }

  station& st(size_t i) {
    return stations_.at(i);
  }

  link_addr dest(size_t to) {
    return kind_.dest(*st(to).driver);
  }

  link_addr source(size_t from) {
    return kind_.source(*st(from).driver);
  }

  /// Sends markers from `from` to `to` until one arrives (bounded): then
  /// everything `to` received before the marker has been handled.
  ::testing::AssertionResult sync(size_t from, size_t to) {
    for (uint8_t k = 0; k < 20; ++k) {
      auto marker = bytes_of("marker");
      marker.push_back(k);
      if (auto err = st(from).send(dest(to), marker))
        return ::testing::AssertionFailure() << render(err);
      if (st(to).rec->wait_frame(marker, 500ms))
        return ::testing::AssertionSuccess();
    }
    return ::testing::AssertionFailure() << "no marker arrived";
  }

  /// Checks the error's code and, where the kind does that, that it names
  /// station `i`'s device.
  void expect_error(const caf::error& err, ec code, size_t i) {
    EXPECT_TRUE(is(err, code)) << render(err);
    if (Kind::errors_name_the_device) {
      EXPECT_NE(render(err).find("device '" + kind_.config(i).name + "'"),
                std::string::npos)
        << render(err);
    }
  }

  Kind kind_;
  std::vector<station> stations_;
};

using link_kinds_under_test
  = ::testing::Types<udp_kind, serial_kind, can_kind, emu_kind, inproc_kind,
                     pair_kind>;

class kind_names {
public:
  template <class T>
  static std::string GetName(int) {
    return T::name;
  }
};

TYPED_TEST_SUITE(driver_conformance, link_kinds_under_test, kind_names);

// -- open --------------------------------------------------------------------------

TYPED_TEST(driver_conformance, opens_stations_with_the_kinds_profile_and_addresses) {
  auto* kind = find_link_kind(TypeParam::name);
  ASSERT_NE(kind, nullptr);
  EXPECT_STREQ(kind->name, TypeParam::name);
  EXPECT_NE(std::string{kind->description}, "");
  this->start_all();
  for (size_t i = 0; i < TypeParam::stations; ++i) {
    auto& d = *this->st(i).driver;
    EXPECT_EQ(d.profile().name, TypeParam::profile);
    EXPECT_GT(d.profile().mtu, 0u);
    EXPECT_EQ(d.get_param("mtu").value(), std::to_string(d.profile().mtu));
    EXPECT_EQ(d.local_addr(), this->kind_.local(i)) << "station " << i;
    // What the channel above does with a peer's address: format and parse.
    for (size_t j = 0; j < TypeParam::stations; ++j) {
      if (j == i)
        continue;
      auto to = this->dest(j);
      auto parsed = d.parse_addr(d.format_addr(to));
      ASSERT_TRUE(parsed) << render(parsed.error());
      EXPECT_EQ(*parsed, to);
    }
    EXPECT_TRUE(this->st(i).rec->failures().empty());
  }
}

TYPED_TEST(driver_conformance, refuses_an_unknown_option_naming_it) {
  auto cfg = this->kind_.config(0);
  cfg.options["colour"] = "blue";
  auto d = find_link_kind(TypeParam::name)->open(cfg);
  ASSERT_FALSE(d);
  EXPECT_TRUE(is(d.error(), ec::invalid_parameter)) << render(d.error());
  EXPECT_NE(render(d.error()).find("'colour'"), std::string::npos)
    << render(d.error());
}

TYPED_TEST(driver_conformance, multi_access_says_whether_more_than_two_stations_share_the_medium) {
  this->start_all();
  EXPECT_EQ(this->st(0).driver->profile().multi_access,
            TypeParam::stations > 2);
}

// -- MTU -------------------------------------------------------------------------

TYPED_TEST(driver_conformance, carries_a_frame_of_exactly_the_mtu_intact) {
  this->start_all();
  auto mtu = this->st(0).driver->profile().mtu;
  EXPECT_EQ(this->st(1).driver->profile().mtu, mtu);
  auto frame = pattern(mtu, 5);
  ASSERT_FALSE(this->st(0).send(this->dest(1), frame));
  ASSERT_TRUE(this->st(1).rec->wait_frames(1));
  auto heard = this->st(1).rec->frames();
  ASSERT_EQ(heard.size(), 1u);
  EXPECT_EQ(heard[0].bytes, frame);
  EXPECT_EQ(heard[0].src, this->source(0));
  EXPECT_TRUE(this->st(1).rec->malformed_frames().empty());
}

TYPED_TEST(driver_conformance, carries_or_refuses_empty_frames_as_the_kind_says) {
  this->start_all();
  auto err = this->st(0).send(this->dest(1), byte_buffer{});
  if (!TypeParam::empty_frames) {
    this->expect_error(err, ec::invalid_parameter, 0);
    return;
  }
  ASSERT_FALSE(err) << render(err);
  ASSERT_TRUE(this->st(1).rec->wait_frames(1));
  EXPECT_TRUE(this->st(1).rec->frames()[0].bytes.empty());
}

TYPED_TEST(driver_conformance, refuses_a_frame_above_the_mtu_naming_both_sizes) {
  this->start_all();
  auto mtu = this->st(0).driver->profile().mtu;
  for (auto dst : {this->dest(1), broadcast_addr}) {
    auto err = this->st(0).send(dst, pattern(mtu + 1, 1));
    this->expect_error(err, ec::packet_too_large, 0);
    EXPECT_NE(render(err).find(std::to_string(mtu + 1)), std::string::npos)
      << render(err);
    EXPECT_NE(render(err).find("MTU of " + std::to_string(mtu)),
              std::string::npos)
      << render(err);
  }
  // Nothing of the refused frames went out.
  ASSERT_TRUE(this->sync(0, 1));
  EXPECT_EQ(this->st(1).rec->frames().size(), 1u);
}

TYPED_TEST(driver_conformance, send_batch_sends_in_order_and_stops_at_a_refused_frame) {
  this->start_all();
  auto& d = *this->st(0).driver;
  auto mtu = d.profile().mtu;
  std::vector<byte_buffer> good;
  for (uint8_t i = 0; i < 5; ++i) {
    good.push_back(pattern(std::min<size_t>(mtu, 1 + i), i));
    good.back()[0] = i;
  }
  auto too_large = pattern(mtu + 1, 9);
  auto to = this->dest(1);
  auto frame = [](link_addr dst, const byte_buffer& b) {
    return tx_frame{dst, b.data(), b.size(), prio_normal};
  };
  std::vector<tx_frame> batch{frame(to, good[0]), frame(broadcast_addr, good[1]),
                              frame(to, good[2]), frame(to, too_large),
                              frame(to, good[3]), frame(to, good[4])};
  caf::error err;
  // The frames before the refused one leave, it does not, the rest wait.
  EXPECT_EQ(d.send_batch(batch.data(), batch.size(), err), 3u);
  this->expect_error(err, ec::packet_too_large, 0);
  EXPECT_EQ(d.send_batch(batch.data() + 4, 2, err), 2u);
  EXPECT_FALSE(err) << render(err);
  ASSERT_TRUE(this->st(1).rec->wait_frames(good.size()));
  EXPECT_EQ(this->st(1).rec->payloads(), good);
  EXPECT_EQ(d.send_batch(batch.data(), 0, err), 0u);
  EXPECT_FALSE(err) << render(err);
}

// -- addressing ----------------------------------------------------------------------

TYPED_TEST(driver_conformance, unicast_reaches_only_its_peer_with_the_senders_address) {
  this->start_all();
  auto n = TypeParam::stations;
  // Station 0 sends one frame to every other station, each names its
  // receiver; every station answers station 0.
  for (size_t to = 1; to < n; ++to)
    ASSERT_FALSE(this->st(0).send(this->dest(to), bytes_of("to " + std::to_string(to))));
  for (size_t to = 1; to < n; ++to) {
    ASSERT_TRUE(this->sync(0, to));
    auto heard = this->st(to).rec->frames();
    ASSERT_EQ(heard.size(), 2u) << "station " << to << " heard another's unicast";
    EXPECT_EQ(heard[0].bytes, bytes_of("to " + std::to_string(to)));
    EXPECT_EQ(heard[0].src, this->source(0));
    ASSERT_FALSE(this->st(to).send(this->dest(0), bytes_of("back")));
  }
  ASSERT_TRUE(this->st(0).rec->wait_frames(n - 1));
  auto at_0 = this->st(0).rec->frames();
  std::multiset<link_addr> srcs;
  for (auto& f : at_0) {
    EXPECT_EQ(f.bytes, bytes_of("back"));
    srcs.insert(f.src);
  }
  std::multiset<link_addr> want;
  for (size_t from = 1; from < n; ++from)
    want.insert(this->source(from));
  EXPECT_EQ(srcs, want);
}

TYPED_TEST(driver_conformance, refuses_addresses_no_station_can_have) {
  this->start_all();
  for (auto dst : this->kind_.invalid_dests())
    this->expect_error(this->st(0).send(dst, bytes_of("x")),
                       ec::invalid_address, 0);
}

TYPED_TEST(driver_conformance, frames_from_one_sender_arrive_in_send_order) {
  this->start_all();
  constexpr size_t n = 50;
  std::vector<byte_buffer> sent;
  for (size_t i = 0; i < n; ++i) {
    sent.push_back(pattern(1 + i % 8, static_cast<uint8_t>(i)));
    sent.back()[0] = static_cast<uint8_t>(i);
    ASSERT_FALSE(this->st(0).send(this->dest(1), sent.back())) << i;
  }
  ASSERT_TRUE(this->st(1).rec->wait_frames(n));
  EXPECT_EQ(this->st(1).rec->payloads(), sent);
}

TYPED_TEST(driver_conformance, broadcast_reaches_every_other_station_but_not_the_sender) {
  this->start_all();
  ASSERT_FALSE(this->st(0).send(broadcast_addr, bytes_of("all")));
  for (size_t to = 1; to < TypeParam::stations; ++to) {
    ASSERT_TRUE(this->st(to).rec->wait_frames(1)) << "station " << to;
    auto heard = this->st(to).rec->frames();
    EXPECT_EQ(heard[0].bytes, bytes_of("all"));
    EXPECT_EQ(heard[0].src, this->source(0));
  }
  // A copy to the sender would have arrived before this marker.
  ASSERT_TRUE(this->sync(1, 0));
  EXPECT_EQ(this->st(0).rec->frames().size(), 1u) << "the sender heard itself";
}

// -- stop ------------------------------------------------------------------------

TYPED_TEST(driver_conformance, stop_from_inside_a_handler_ends_delivery_at_once) {
  std::atomic<bool> stopped{false};
  this->start_all({{1, [&](const recorder::frame&) {
                      this->st(1).driver->stop();
                      stopped = true;
                    }}});
  // Both frames are on their way before the first one is handled.
  ASSERT_FALSE(this->st(0).send(this->dest(1), bytes_of("first")));
  ASSERT_FALSE(this->st(0).send(this->dest(1), bytes_of("second")));
  ASSERT_TRUE(this->st(1).rec->wait_frames(1));
  auto deadline = std::chrono::steady_clock::now() + 10s;
  while (!stopped && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(1ms);
  ASSERT_TRUE(stopped) << "stop did not return inside the handler";
  // Stopping again from outside is harmless.
  this->st(1).driver->stop();
  EXPECT_EQ(this->st(1).rec->payloads(), std::vector<byte_buffer>{bytes_of("first")});
  EXPECT_TRUE(this->st(1).rec->failures().empty());
}

TYPED_TEST(driver_conformance, calls_the_handler_on_the_loop_thread_it_was_started_on) {
  auto io = io_thread::make();
  ASSERT_TRUE(io) << render(io.error());
  auto& loop = (*io)->loop();
  std::atomic<size_t> on_loop{0};
  std::atomic<size_t> elsewhere{0};
  auto where = [&](const recorder::frame&) {
    ++(loop.in_loop_thread() ? on_loop : elsewhere);
  };
  this->start_all({{0, where}, {1, where}}, &loop);
  ASSERT_FALSE(this->st(0).send(this->dest(1), bytes_of("there")));
  ASSERT_TRUE(this->st(1).rec->wait_frames(1));
  ASSERT_FALSE(this->st(1).send(this->dest(0), bytes_of("back")));
  ASSERT_TRUE(this->st(0).rec->wait_frames(1));
  // Stopped before the loop's thread ends.
  for (size_t i = 0; i < TypeParam::stations; ++i)
    this->st(i).driver->stop();
  size_t want_on_loop = TypeParam::delivers_on_the_loop ? 2 : 0;
  EXPECT_EQ(on_loop.load(), want_on_loop);
  EXPECT_EQ(elsewhere.load(), 2 - want_on_loop);
}

TYPED_TEST(driver_conformance, stop_twice_is_harmless_and_final) {
  this->start_all();
  auto& a = this->st(0);
  a.driver->stop();
  a.driver->stop();
  EXPECT_TRUE(a.rec->failures().empty());
  if (!TypeParam::stop_is_final)
    return;
  this->expect_error(a.send(this->dest(1), bytes_of("late")), ec::device_failed,
                     0);
  // Every kind refuses it alike (the code the descriptor drivers and the
  // emulated media share).
  this->expect_error(a.driver->start(std::make_shared<recorder>()),
                     ec::device_unavailable, 0);
}

// -- counters ----------------------------------------------------------------------

TYPED_TEST(driver_conformance, counters_count_frames_bytes_and_drops) {
  this->start_all();
  auto& a = this->st(0);
  auto& b = this->st(1);
  auto mtu = a.driver->profile().mtu;
  std::vector<size_t> sizes{1, mtu / 2 + 1, mtu};
  size_t total = 0;
  for (auto n : sizes) {
    ASSERT_FALSE(a.send(this->dest(1), pattern(n, 3)));
    total += n;
  }
  ASSERT_TRUE(b.rec->wait_frames(sizes.size()));
  EXPECT_EQ(b.rec->bytes(), total);
  int64_t sent = static_cast<int64_t>(sizes.size());
  if (TypeParam::frame_counters) {
    EXPECT_TRUE(a.wait_counter("tx_frames", sent)) << a.counter("tx_frames");
    EXPECT_TRUE(b.wait_counter("rx_frames", sent)) << b.counter("rx_frames");
  }
  // Something malformed for b: reported and counted, never delivered.
  if (!TypeParam::injects_malformed)
    return;
  ASSERT_TRUE(this->kind_.inject_malformed(1, *a.driver));
  ASSERT_TRUE(this->sync(0, 1));
  auto bad = b.rec->malformed_frames();
  EXPECT_GE(bad.size(), 1u);
  if (TypeParam::malformed_counter) {
    EXPECT_EQ(b.counter("rx_malformed"), static_cast<int64_t>(bad.size()));
  }
  auto heard = b.rec->payloads();
  for (size_t i = 0; i < sizes.size(); ++i)
    EXPECT_EQ(heard.at(i), pattern(sizes[i], 3));
  for (size_t i = sizes.size(); i < heard.size(); ++i)
    EXPECT_EQ(heard[i].size(), 7u) << "a malformed frame was delivered";
  EXPECT_TRUE(b.rec->failures().empty());
}

bool serial_kind::inject_malformed(size_t to, link_driver& from) {
  auto flipped = [&] {
    return to == 1 ? cable->a_to_b().flipped : cable->b_to_a().flipped;
  };
  auto before = flipped();
  test::line_faults noise;
  noise.flip = 1;
  cable->set_faults(noise);
  auto frame = bytes_of("garbage");
  auto sent = !from.send(1, frame.data(), frame.size(), prio_normal);
  auto deadline = std::chrono::steady_clock::now() + 10s;
  while (sent && flipped() == before && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(1ms);
  cable->set_faults({});
  return flipped() > before;
}

// -- the added kind outside the suite -------------------------------------------------

TEST(added_link_kind, is_known_once_and_refuses_a_second_kind_of_its_name) {
  EXPECT_FALSE(pair_added) << render(pair_added);
  EXPECT_EQ(find_link_kind("pair"), find_link_kind("pair"));
  ASSERT_NE(find_link_kind("pair"), nullptr);
  EXPECT_EQ(find_link_kind("pair")->open, &open_pair);
  auto kinds = link_kinds();
  ASSERT_FALSE(kinds.empty());
  EXPECT_STREQ(kinds.back()->name, "pair"); // after the built-in kinds
  EXPECT_STREQ(kinds.front()->name, "inproc");
  EXPECT_TRUE(is(add_link_kind(pair_link_kind()), ec::already_exists));
  EXPECT_TRUE(is(add_link_kind({"udp", "another udp", open_pair}),
                 ec::already_exists));
  EXPECT_STREQ(find_link_kind("udp")->description, "UDP/IPv4 (Ethernet)");
  EXPECT_TRUE(is(add_link_kind({nullptr, "nameless", open_pair}),
                 ec::invalid_parameter));
  EXPECT_TRUE(is(add_link_kind({"closed", "no open", nullptr}),
                 ec::invalid_parameter));
  EXPECT_EQ(find_link_kind("closed"), nullptr);
  EXPECT_EQ(link_kinds().size(), kinds.size());
}

TEST(added_link_kind, the_io_manager_opens_its_devices_by_kind_name) {
  caf::actor_system_config cfg;
  cfg.add_message_types<caf::id_block::herm_channels>();
  caf::actor_system sys{cfg};
  caf::scoped_actor self{sys};
  auto io = spawn_io_manager(sys);
  std::vector<channel_actor> channels;
  for (auto name : {"p0", "p1"}) {
    device_config dev{name, "pair", "io-manager-cable", {}};
    self->request(io, 5s, atom::add_v, dev)
      .receive([&](device_info& x) { EXPECT_EQ(x.config.kind, "pair"); },
               [&](caf::error& err) { FAIL() << render(err); });
    self->request(io, 5s, atom::open_v, channel_request{name, "*"})
      .receive(
        [&](channel_actor& ch, channel_info& info) {
          EXPECT_EQ(info.kind, "pair");
          EXPECT_EQ(info.profile.name, "usb2.0");
          channels.push_back(ch);
        },
        [&](caf::error& err) { FAIL() << render(err); });
  }
  ASSERT_EQ(channels.size(), 2u);
  self->request(channels[1], 5s, atom::subscribe_v,
                caf::actor_cast<channel_reader_actor>(self))
    .receive([](channel_info&) {},
             [&](caf::error& err) { FAIL() << render(err); });
  auto packet = pattern(3000, 9); // above the MTU: fragmented and reassembled
  self->send(channels[0], write_packet{2, prio_normal, packet});
  std::optional<packet_received> got;
  auto deadline = std::chrono::steady_clock::now() + 10s;
  while (!got && std::chrono::steady_clock::now() < deadline)
    self->receive([&](packet_received& x) { got = std::move(x); },
                  [](link_event&) {}, caf::after(200ms) >> [] {});
  ASSERT_TRUE(got) << "no packet through the IO manager";
  EXPECT_EQ(got->src, 1u);
  EXPECT_EQ(got->bytes, packet);
  self->send_exit(io, caf::exit_reason::user_shutdown);
}

} // namespace
} // namespace herm
