// Tests of the "can" link kind (channels/drivers/can.cpp) and its pure
// helpers (can_id.hpp, can_emu_wire.hpp).
//
//  * can_id.*, can_emu_wire.*: table-driven tests of the identifier layout,
//    frame checks, bit timing and the emulated bus's datagram header.
//  * can_options.*: option parsing and the link profile.
//  * can_emu.*: the emulated bus (interface "emu:DIR") across threads and
//    processes. Each test works in its own mkdtemp directory and removes it;
//    waits are bounded; timing checks are lower bounds only (speed is
//    measured in apps/bench/can_efficiency_bench.cpp).
//  * socketcan.*: the SocketCAN backend against a real kernel. They need a
//    vcan0 interface (and root, for the tests that create their own
//    interfaces) and skip, saying so, where there is none: on hosts without
//    CAN, tests/qemu/run-can-kernel-test.sh runs them in a Debian kernel
//    under qemu (--gtest_filter='socketcan*').

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
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
#include <net/if.h>
#include <poll.h>
#include <signal.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <linux/if_link.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/drivers/can_emu_wire.hpp"
#include "channels/drivers/can_id.hpp"
#include "channels/link_driver.hpp"
#include "tests/channels/recorder.hpp"

using namespace herm;
using namespace std::chrono_literals;
using herm::test::recorder;

namespace {

// -- helpers ---------------------------------------------------------------------

constexpr auto now_ns = recorder::now_ns;

byte_buffer bytes_of(const std::string& str) {
  return byte_buffer(str.begin(), str.end());
}

std::string text_of(const byte_buffer& bytes) {
  return std::string(bytes.begin(), bytes.end());
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

bool contains(const std::string& haystack, const std::string& needle) {
  return haystack.find(needle) != std::string::npos;
}

/// A started driver and what it heard.
struct station {
  link_driver_ptr driver;
  std::shared_ptr<recorder> rec;

  caf::error send(link_addr dst, const byte_buffer& bytes,
                  uint8_t priority = prio_normal) {
    return driver->send(dst, bytes.data(), bytes.size(), priority);
  }

  uint64_t counter(const std::string& key) const {
    auto x = driver->get_param(key);
    return x ? std::stoull(*x) : ~uint64_t{0};
  }
};

/// Waits until the driver's counter `key` reaches at least `min`.
bool wait_counter(const station& s, const std::string& key, uint64_t min,
                  std::chrono::milliseconds timeout = 10s) {
  auto deadline = std::chrono::steady_clock::now() + timeout;
  while (s.counter(key) < min || s.counter(key) == ~uint64_t{0}) {
    if (std::chrono::steady_clock::now() > deadline)
      return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

/// Opens a device of kind "can"; registers it in `opened` for cleanup.
caf::expected<link_driver_ptr> open_can(std::vector<link_driver_ptr>& opened,
                                        const std::string& name,
                                        const std::string& interface,
                                        option_map options) {
  auto* kind = find_link_kind("can");
  if (kind == nullptr)
    return make_error(ec::unknown_link_kind, "can");
  auto result = kind->open(device_config{name, "can", interface,
                                         std::move(options)});
  if (result)
    opened.push_back(*result);
  return result;
}

station start_can(std::vector<link_driver_ptr>& opened, const std::string& name,
                  const std::string& interface, option_map options) {
  station result;
  auto d = open_can(opened, name, interface, std::move(options));
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

// -- can_id: identifier layout ----------------------------------------------------

using can::frame_id;
using can::id_format;
using can::id_status;

TEST(can_id, fields_sit_at_the_documented_bit_positions) {
  struct {
    id_format format;
    frame_id id;
    uint32_t expected;
  } cases[] = {
    // priority 28..26, dst 25..18, src 17..10, tag 0b100101 9..4, pad 3..0
    {id_format::ext29, {0, 1, 1, 0}, 0x00040000 | 0x400 | 0x250},
    {id_format::ext29, {7, 0xFF, 254, 15}, 0x1C000000 | 0x03FC0000 | 0x3F800
                                              | 0x250 | 0xF},
    {id_format::ext29, {2, 0x12, 0x34, 3}, 0x08000000 | 0x00480000 | 0xD000
                                              | 0x250 | 0x3},
    // priority 10..8, dst 7..4, src 3..0
    {id_format::std11, {0, 1, 2, 0}, 0x012},
    {id_format::std11, {7, 0xF, 14, 0}, 0x7FE},
    {id_format::std11, {5, 3, 9, 0}, 0x539},
  };
  for (auto& c : cases) {
    EXPECT_TRUE(can::valid(c.format, c.id));
    EXPECT_EQ(can::encode_id(c.format, c.id), c.expected)
      << std::hex << c.expected;
    auto can_id = can::to_can_id(c.format, c.id);
    EXPECT_EQ((can_id & CAN_EFF_FLAG) != 0, c.format == id_format::ext29);
  }
}

TEST(can_id, a_lower_priority_value_gives_a_numerically_lower_id) {
  for (auto f : {id_format::ext29, id_format::std11}) {
    auto max = can::max_node(f);
    uint8_t nodes[] = {1, 2, static_cast<uint8_t>(max / 2), max,
                       can::broadcast_node(f)};
    for (uint8_t p = 0; p < can::max_priority; ++p)
      for (auto d1 : nodes)
        for (auto s1 : nodes)
          for (auto d2 : nodes)
            for (auto s2 : nodes) {
              frame_id urgent{p, d1, s1 == can::broadcast_node(f) ? max : s1,
                              0};
              frame_id bulk{static_cast<uint8_t>(p + 1), d2,
                            s2 == can::broadcast_node(f) ? max : s2, 0};
              auto a = can::to_can_id(f, urgent);
              auto b = can::to_can_id(f, bulk);
              ASSERT_LT(a & CAN_EFF_MASK, b & CAN_EFF_MASK);
              ASSERT_LT(can::arbitration_key(a), can::arbitration_key(b));
            }
  }
}

TEST(can_id, every_field_combination_round_trips) {
  size_t checked = 0;
  for (auto f : {id_format::ext29, id_format::std11}) {
    std::vector<uint8_t> dsts;
    for (int n = 1; n <= can::max_node(f); ++n)
      dsts.push_back(static_cast<uint8_t>(n));
    dsts.push_back(can::broadcast_node(f));
    for (uint8_t p = 0; p <= can::max_priority; ++p)
      for (auto dst : dsts)
        for (int src = 1; src <= can::max_node(f); src += (f == id_format::ext29 ? 23 : 1))
          for (uint8_t pad = 0; pad <= (f == id_format::ext29 ? 15 : 0);
               pad += 5) {
            frame_id x{p, dst, static_cast<uint8_t>(src), pad};
            ASSERT_TRUE(can::valid(f, x));
            frame_id y;
            ASSERT_EQ(can::decode_id(f, can::to_can_id(f, x), y),
                      id_status::ok);
            ASSERT_EQ(x, y);
            ++checked;
          }
  }
  EXPECT_GT(checked, 10'000u);
}

TEST(can_id, broadcast_is_the_all_ones_destination_and_every_node_accepts_it) {
  EXPECT_EQ(can::broadcast_node(id_format::ext29), 0xFF);
  EXPECT_EQ(can::broadcast_node(id_format::std11), 0x0F);
  for (auto f : {id_format::ext29, id_format::std11}) {
    auto b = can::broadcast_node(f);
    frame_id x{1, b, 3, 0};
    frame_id y;
    ASSERT_EQ(can::decode_id(f, can::to_can_id(f, x), y), id_status::ok);
    EXPECT_EQ(y.dst, b);
    EXPECT_TRUE(can::accepts(f, 3, b));
    EXPECT_TRUE(can::accepts(f, 7, b));
    EXPECT_TRUE(can::accepts(f, 7, 7));
    EXPECT_FALSE(can::accepts(f, 7, 8));
  }
}

TEST(can_id, the_lane_is_the_priority_and_whether_the_frame_is_a_broadcast) {
  // Frames of one lane share an identifier (but for CAN FD padding), so
  // they keep their order in any transmit queue; the receiver reassembles
  // per lane (docs/protocol.md, "CAN identifier layout").
  struct {
    uint8_t priority;
    bool broadcast;
    uint8_t lane;
  } cases[] = {
    {0, false, 0}, {0, true, 1},  {1, false, 2},  {2, true, 5},
    {3, false, 6}, {3, true, 7},  {7, false, 14}, {7, true, 15},
  };
  for (auto f : {id_format::ext29, id_format::std11}) {
    for (auto& c : cases) {
      SCOPED_TRACE(std::to_string(c.priority) + (c.broadcast ? " broadcast" : ""));
      frame_id x{c.priority, c.broadcast ? can::broadcast_node(f) : uint8_t{4},
                 3, 0};
      EXPECT_EQ(can::lane_of(f, x), c.lane);
      // The receiver computes it from the decoded identifier.
      frame_id y;
      ASSERT_EQ(can::decode_id(f, can::to_can_id(f, x), y), id_status::ok);
      EXPECT_EQ(can::lane_of(f, y), c.lane);
      EXPECT_LT(c.lane, max_lanes);
    }
  }
}

TEST(can_id, foreign_and_impossible_identifiers_are_rejected) {
  auto herm29 = [](uint32_t prio, uint32_t dst, uint32_t src, uint32_t tag,
                   uint32_t pad) {
    return CAN_EFF_FLAG | prio << 26 | dst << 18 | src << 10 | tag << 4 | pad;
  };
  struct {
    id_format format;
    canid_t can_id;
    id_status expected;
  } cases[] = {
    {id_format::ext29, herm29(1, 2, 3, can::herm_tag, 0), id_status::ok},
    {id_format::ext29, herm29(1, 2, 3, 0x00, 0), id_status::foreign},
    {id_format::ext29, herm29(1, 2, 3, 0x3F, 0), id_status::foreign},
    {id_format::ext29, herm29(1, 2, 3, 0x24, 0), id_status::foreign},
    {id_format::ext29, 0x18FEF100 | CAN_EFF_FLAG, id_status::foreign}, // J1939
    {id_format::ext29, 0x123, id_status::standard_id},
    {id_format::ext29, herm29(1, 2, 3, can::herm_tag, 0) | CAN_RTR_FLAG,
     id_status::remote_frame},
    {id_format::ext29, CAN_ERR_FLAG | CAN_ERR_BUSOFF, id_status::error_frame},
    {id_format::ext29, herm29(1, 2, 0, can::herm_tag, 0),
     id_status::bad_source},
    {id_format::ext29, herm29(1, 2, 255, can::herm_tag, 0),
     id_status::bad_source},
    {id_format::ext29, herm29(1, 0, 3, can::herm_tag, 0),
     id_status::bad_destination},
    {id_format::std11, 0x123, id_status::ok},
    {id_format::std11, 0x123 | CAN_EFF_FLAG, id_status::extended_id},
    {id_format::std11, 0x120, id_status::bad_source},
    {id_format::std11, 0x12F, id_status::bad_source},
    {id_format::std11, 0x103, id_status::bad_destination},
    {id_format::std11, 0x123 | CAN_RTR_FLAG, id_status::remote_frame},
  };
  for (auto& c : cases) {
    frame_id out;
    EXPECT_EQ(can::decode_id(c.format, c.can_id, out), c.expected)
      << can::to_string(c.format) << " id 0x" << std::hex << c.can_id;
  }
}

TEST(can_id, frame_lengths_and_padding_are_checked) {
  auto id = [](uint8_t pad) {
    return can::to_can_id(id_format::ext29, frame_id{2, 5, 6, pad});
  };
  struct {
    canid_t can_id;
    size_t len;
    bool fd;
    id_status expected;
    size_t payload;
  } cases[] = {
    {id(0), 0, false, id_status::ok, 0},
    {id(0), 8, false, id_status::ok, 8},
    {id(0), 9, false, id_status::bad_length, 0},
    {id(0), 15, false, id_status::bad_length, 0},
    {id(1), 8, false, id_status::bad_padding, 0}, // no padding in classic
    {id(0), 64, true, id_status::ok, 64},
    {id(0), 13, true, id_status::bad_length, 0}, // no such CAN FD length
    {id(0), 65, true, id_status::bad_length, 0},
    {id(3), 12, true, id_status::ok, 9},
    {id(15), 64, true, id_status::ok, 49},
    {id(1), 48, true, id_status::ok, 47},
    {id(4), 12, true, id_status::bad_padding, 0}, // 8 bytes need no padding
    {id(13), 12, true, id_status::bad_padding, 0}, // more padding than data
    {id(2), 8, true, id_status::bad_padding, 0},
  };
  for (auto& c : cases) {
    frame_id out;
    size_t payload = 999;
    EXPECT_EQ(can::decode_frame(id_format::ext29, c.can_id, c.len, c.fd, out,
                                payload),
              c.expected)
      << "len " << c.len << " fd " << c.fd << " pad " << (c.can_id & 0xF);
    if (c.expected == id_status::ok) {
      EXPECT_EQ(payload, c.payload);
    }
  }
}

TEST(can_id, fd_lengths_round_up_to_the_next_dlc_length) {
  struct {
    size_t n, expected;
  } cases[] = {{0, 0},   {7, 7},   {8, 8},   {9, 12},  {12, 12}, {13, 16},
               {17, 20}, {21, 24}, {25, 32}, {32, 32}, {33, 48}, {49, 64},
               {64, 64}};
  for (auto& c : cases) {
    EXPECT_EQ(can::fd_round_up(c.n), c.expected) << c.n;
    EXPECT_TRUE(can::is_fd_len(c.expected));
  }
  for (size_t n = 0; n <= 64; ++n)
    EXPECT_LE(can::fd_round_up(n) - n, 15u) << n; // fits the 4 padding bits
}

TEST(can_id, arbitration_puts_a_standard_frame_before_an_extended_one) {
  // Same 11 base bits: the standard frame's dominant IDE bit wins.
  canid_t std_id = 0x123;
  canid_t ext_same_base = CAN_EFF_FLAG | 0x123u << 18 | 0x00001;
  canid_t ext_lower_base = CAN_EFF_FLAG | 0x122u << 18 | 0x3FFFF;
  EXPECT_LT(can::arbitration_key(std_id), can::arbitration_key(ext_same_base));
  EXPECT_LT(can::arbitration_key(ext_lower_base), can::arbitration_key(std_id));
  EXPECT_LT(can::arbitration_key(CAN_EFF_FLAG | 5),
            can::arbitration_key(CAN_EFF_FLAG | 6));
}

TEST(can_id, kernel_filter_passes_own_and_broadcast_destinations_only) {
  auto f = id_format::ext29;
  auto own = can::destination_filter(f, 7);
  auto all = can::destination_filter(f, can::broadcast_node(f));
  auto passes = [&](canid_t id) {
    return (id & own.mask) == (own.id & own.mask)
           || (id & all.mask) == (all.id & all.mask);
  };
  EXPECT_TRUE(passes(can::to_can_id(f, frame_id{3, 7, 1, 0})));
  EXPECT_TRUE(passes(can::to_can_id(f, frame_id{0, 0xFF, 9, 0})));
  EXPECT_FALSE(passes(can::to_can_id(f, frame_id{3, 8, 1, 0})));
  // Standard frames never pass a 29-bit filter.
  EXPECT_FALSE(passes(0x7FF));
  // A foreign frame with our destination bits passes (and is counted).
  EXPECT_TRUE(passes(CAN_EFF_FLAG | 7u << 18));
  auto s = id_format::std11;
  auto own11 = can::destination_filter(s, 7);
  auto id11 = can::to_can_id(s, frame_id{3, 7, 1, 0});
  EXPECT_EQ(id11 & own11.mask, own11.id & own11.mask);
  EXPECT_NE((id11 | CAN_EFF_FLAG) & own11.mask, own11.id & own11.mask);
}

TEST(can_id, frame_bits_follow_the_can_frame_format) {
  struct {
    id_format f;
    size_t len;
    bool stuffing;
    uint32_t bits;
  } cases[] = {
    {id_format::std11, 0, false, 47},  {id_format::std11, 8, false, 111},
    {id_format::ext29, 0, false, 67},  {id_format::ext29, 8, false, 131},
    {id_format::std11, 8, true, 135},  {id_format::ext29, 8, true, 160},
    {id_format::std11, 0, true, 55},   {id_format::ext29, 1, true, 90},
    {id_format::ext29, 64, false, 579},
  };
  for (auto& c : cases)
    EXPECT_EQ(can::frame_bits(c.f, c.len, c.stuffing), c.bits)
      << can::to_string(c.f) << " len " << c.len << " stuffing " << c.stuffing;
  // The physical limit at 1 Mbit/s: about 9,000 (11-bit) and 7,600 (29-bit)
  // full frames per second before stuffing.
  EXPECT_EQ(1'000'000'000 / can::bits_time_ns(111, 1'000'000), 9009);
  EXPECT_EQ(1'000'000'000 / can::bits_time_ns(131, 1'000'000), 7633);
  EXPECT_EQ(can::bits_time_ns(131, 3), 43'666'666'667); // rounded up
}

// -- can_emu_wire: datagram header ---------------------------------------------------

TEST(can_emu_wire, header_round_trips) {
  can::wire::header h;
  h.flags = can::wire::flag_error;
  h.deliver_at_ns = 123'456'789'012;
  uint8_t buf[can::wire::header_size];
  can::wire::encode(h, buf);
  auto g = can::wire::decode(buf);
  EXPECT_EQ(g.magic, can::wire::magic);
  EXPECT_EQ(g.version, can::wire::version);
  EXPECT_EQ(g.flags, h.flags);
  EXPECT_EQ(g.reserved, 0u);
  EXPECT_EQ(g.deliver_at_ns, h.deliver_at_ns);
}

TEST(can_emu_wire, check_accepts_exactly_can_mtu_and_canfd_mtu_frames) {
  auto now = int64_t{1'000'000'000'000};
  auto datagram = [](can::wire::header h, size_t frame_size) {
    std::vector<uint8_t> buf(can::wire::header_size + frame_size, 0);
    can::wire::encode(h, buf.data());
    return buf;
  };
  can::wire::header good;
  good.deliver_at_ns = now;
  auto bad_magic = good;
  bad_magic.magic = 0x1234;
  auto bad_version = good;
  bad_version.version = 9;
  auto bad_flags = good;
  bad_flags.flags = 0x80;
  auto bad_reserved = good;
  bad_reserved.reserved = 1;
  auto far = good;
  far.deliver_at_ns = now + can::wire::max_hold_ns + 1;
  struct {
    std::vector<uint8_t> bytes;
    can::wire::status expected;
  } cases[] = {
    {datagram(good, CAN_MTU), can::wire::status::ok},
    {datagram(good, CANFD_MTU), can::wire::status::ok},
    {datagram(good, CAN_MTU + 1), can::wire::status::bad_size},
    {datagram(good, 8), can::wire::status::bad_size},
    {datagram(good, 0), can::wire::status::bad_size},
    {std::vector<uint8_t>(5, 0), can::wire::status::too_short},
    {datagram(bad_magic, CAN_MTU), can::wire::status::bad_magic},
    {datagram(bad_version, CAN_MTU), can::wire::status::bad_version},
    {datagram(bad_flags, CAN_MTU), can::wire::status::bad_header},
    {datagram(bad_reserved, CAN_MTU), can::wire::status::bad_header},
    {datagram(far, CAN_MTU), can::wire::status::too_far_ahead},
  };
  for (auto& c : cases) {
    can::wire::header h;
    EXPECT_EQ(can::wire::check(c.bytes.data(), c.bytes.size(), now, h),
              c.expected)
      << c.bytes.size() << " bytes: " << can::wire::to_string(c.expected);
  }
}

// -- options and profile -----------------------------------------------------------

class can_emu_test : public ::testing::Test {
protected:
  void SetUp() override {
    char tmpl[] = "/tmp/herm-can-test-XXXXXX";
    ASSERT_NE(::mkdtemp(tmpl), nullptr) << std::strerror(errno);
    root_ = tmpl;
    bus_dir_ = root_ + "/bus";
    bus_ = "emu:" + bus_dir_;
  }

  void TearDown() override {
    for (auto& d : drivers_)
      d->stop();
    drivers_.clear();
    if (!root_.empty())
      remove_tree(root_);
  }

  caf::expected<link_driver_ptr> open(const std::string& name,
                                      option_map options) {
    return open_can(drivers_, name, bus_, std::move(options));
  }

  station start(const std::string& name, option_map options) {
    return start_can(drivers_, name, bus_, std::move(options));
  }

  std::string sock_path(uint64_t node) const {
    return bus_dir_ + "/" + std::to_string(node) + ".sock";
  }

  std::string root_;
  std::string bus_dir_;
  std::string bus_;
  std::vector<link_driver_ptr> drivers_;
};

TEST_F(can_emu_test, bad_options_are_refused_naming_the_option) {
  struct {
    option_map options;
    std::string interface;
    ec code;
    std::string mention;
  } cases[] = {
    {{}, bus_, ec::invalid_parameter, "option 'node' is required"},
    {{{"node", "0"}}, bus_, ec::invalid_parameter, "option 'node'"},
    {{{"node", "255"}}, bus_, ec::invalid_parameter, "option 'node'"},
    {{{"node", "15"}, {"id_format", "11bit"}}, bus_, ec::invalid_parameter,
     "option 'node' expects an integer in [1, 14]"},
    {{{"node", "1"}, {"id_format", "12bit"}}, bus_, ec::invalid_parameter,
     "option 'id_format' expects 29bit or 11bit, got '12bit'"},
    {{{"node", "1"}, {"id_format", "11bit"}, {"fd", "true"}}, bus_,
     ec::invalid_parameter, "option 'fd' needs id_format=29bit"},
    {{{"node", "1"}, {"fd", "maybe"}}, bus_, ec::invalid_parameter,
     "option 'fd'"},
    {{{"node", "1"}, {"bitrate", "fast"}}, bus_, ec::invalid_parameter,
     "option 'bitrate'"},
    {{{"node", "1"}, {"bitrate", "0"}}, bus_, ec::invalid_parameter,
     "option 'bitrate'"},
    {{{"node", "1"}, {"loss", "2"}}, bus_, ec::invalid_parameter,
     "option 'loss'"},
    {{{"node", "1"}, {"error_rate", "1"}}, bus_, ec::invalid_parameter,
     "option 'error_rate'"},
    {{{"node", "1"}, {"bitrat", "1000"}}, bus_, ec::invalid_parameter,
     "'bitrat'"},
    // SocketCAN-only and emulator-only options are refused on the other.
    {{{"node", "1"}, {"filter", "false"}}, bus_, ec::invalid_parameter,
     "'filter'"},
    {{{"node", "1"}, {"loss", "0.1"}}, "vcan0", ec::invalid_parameter,
     "'loss'"},
    {{{"node", "1"}}, "emu:", ec::invalid_address, "names no bus directory"},
    {{{"node", "1"}}, "", ec::invalid_address, "interface ''"},
    {{{"node", "1"}}, "can0/x", ec::invalid_address, "interface 'can0/x'"},
    {{{"node", "1"}}, "averyveryverylongname0", ec::invalid_address,
     "averyveryverylongname0"},
  };
  for (auto& c : cases) {
    auto d = open_can(drivers_, "can9", c.interface, c.options);
    ASSERT_FALSE(d) << c.mention;
    EXPECT_TRUE(is(d.error(), c.code)) << render(d.error());
    EXPECT_TRUE(contains(render(d.error()), c.mention)) << render(d.error());
    EXPECT_TRUE(contains(render(d.error()), "device 'can9'"))
      << render(d.error());
  }
}

TEST_F(can_emu_test, profile_is_can2_0_at_the_configured_bit_rate) {
  auto classic = open("can0", {{"node", "1"}});
  ASSERT_TRUE(classic) << render(classic.error());
  auto& p = (*classic)->profile();
  EXPECT_EQ(p.name, "can2.0");
  EXPECT_EQ(p.bandwidth_bps, 1'000'000u);
  EXPECT_EQ(p.mtu, 8u);
  EXPECT_TRUE(p.multi_access);
  EXPECT_EQ(p.frame_overhead_bits, 67u); // 29-bit identifiers
  EXPECT_EQ((*classic)->local_addr(), 1u);
  EXPECT_EQ(*(*classic)->get_param("bandwidth"), "1000000");
  EXPECT_EQ(*(*classic)->get_param("mtu"), "8");
  EXPECT_EQ(*(*classic)->get_param("backend"), "emu");
}

TEST_F(can_emu_test, stations_must_share_the_bus_bit_rate_and_node_ids_are_unique) {
  auto a = open("can0", {{"node", "1"}, {"bitrate", "500000"}});
  ASSERT_TRUE(a) << render(a.error());
  EXPECT_EQ((*a)->profile().bandwidth_bps, 500'000u);
  auto b = open("can1", {{"node", "2"}, {"bitrate", "250000"}});
  ASSERT_FALSE(b);
  EXPECT_TRUE(is(b.error(), ec::device_unavailable)) << render(b.error());
  EXPECT_TRUE(contains(render(b.error()), "runs at 500000 bit/s"))
    << render(b.error());
  auto c = open("can2", {{"node", "1"}, {"bitrate", "500000"}});
  ASSERT_FALSE(c);
  EXPECT_TRUE(is(c.error(), ec::already_exists)) << render(c.error());
  EXPECT_TRUE(contains(render(c.error()), "node 1 is already on bus"))
    << render(c.error());
  // Once everybody left, the next station sets a new bit rate.
  (*a)->stop();
  auto d = open("can3", {{"node", "3"}, {"bitrate", "250000"}});
  EXPECT_TRUE(d) << render(d.error());
}

TEST_F(can_emu_test, profile_follows_identifier_format_fd_and_stuffing) {
  struct {
    option_map options;
    std::string name;
    uint32_t mtu;
    uint32_t overhead;
  } cases[] = {
    {{{"node", "1"}}, "can2.0", 8, 67},
    {{{"node", "2"}, {"id_format", "11bit"}}, "can2.0", 8, 47},
    {{{"node", "3"}, {"stuffing", "true"}}, "can2.0", 8, 160 - 64},
    {{{"node", "4"}, {"id_format", "11bit"}, {"stuffing", "true"}}, "can2.0",
     8, 135 - 64},
    {{{"node", "5"}, {"fd", "true"}}, "canfd", 64, 67},
  };
  for (auto& c : cases) {
    auto d = open("can" + c.options["node"], c.options);
    ASSERT_TRUE(d) << render(d.error());
    EXPECT_EQ((*d)->profile().name, c.name);
    EXPECT_EQ((*d)->profile().mtu, c.mtu);
    EXPECT_EQ((*d)->profile().frame_overhead_bits, c.overhead);
    EXPECT_EQ((*d)->profile().bandwidth_bps, 1'000'000u);
  }
}

TEST_F(can_emu_test, addresses_are_node_ids) {
  auto a = open("can0", {{"node", "1"}});
  ASSERT_TRUE(a) << render(a.error());
  EXPECT_EQ((*a)->format_addr(17), "17");
  EXPECT_EQ((*a)->format_addr(broadcast_addr), "*");
  auto x = (*a)->parse_addr("254");
  ASSERT_TRUE(x);
  EXPECT_EQ(*x, 254u);
  for (std::string text : {"0", "255", "", "1a", "-1", "1000"}) {
    auto y = (*a)->parse_addr(text);
    ASSERT_FALSE(y) << text;
    EXPECT_TRUE(is(y.error(), ec::invalid_address));
    EXPECT_TRUE(contains(render(y.error()), "'" + text + "'"));
  }
  auto b = open("can1", {{"node", "2"}, {"id_format", "11bit"}});
  ASSERT_TRUE(b) << render(b.error());
  EXPECT_FALSE((*b)->parse_addr("15"));
  EXPECT_TRUE((*b)->parse_addr("14"));
}

// -- the emulated bus ---------------------------------------------------------------

TEST_F(can_emu_test, every_station_hears_every_frame_and_counts_unicasts_for_others_as_filtered) {
  // Delivery by destination is the conformance suite's; this is the counter.
  auto a = start("can0", {{"node", "1"}});
  auto b = start("can1", {{"node", "2"}});
  auto c = start("can2", {{"node", "3"}});
  ASSERT_TRUE(a.driver && b.driver && c.driver);
  ASSERT_FALSE(a.send(broadcast_addr, bytes_of("all")));
  ASSERT_FALSE(a.send(2, bytes_of("to b")));
  ASSERT_FALSE(a.send(3, bytes_of("to c")));
  ASSERT_TRUE(b.rec->wait_frames(2));
  ASSERT_TRUE(c.rec->wait_frames(2));
  EXPECT_TRUE(wait_counter(b, "rx_filtered", 1));
  EXPECT_TRUE(wait_counter(c, "rx_filtered", 1));
  EXPECT_EQ(b.counter("rx_filtered"), 1u);
  EXPECT_EQ(c.counter("rx_filtered"), 1u);
}

TEST_F(can_emu_test, receivers_hear_each_frame_in_the_lane_its_sender_chose) {
  auto a = start("can0", {{"node", "1"}});
  auto b = start("can1", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  struct {
    link_addr dst;
    uint8_t priority;
  } sends[] = {{2, prio_bulk}, {2, prio_control}, {broadcast_addr, prio_bulk},
               {broadcast_addr, prio_control}, {2, 9}};
  for (auto& x : sends)
    ASSERT_FALSE(a.send(x.dst, bytes_of("x"), x.priority));
  ASSERT_TRUE(b.rec->wait_frames(std::size(sends)));
  std::multiset<uint8_t> want;
  for (auto& x : sends)
    want.insert(a.driver->lane(x.dst, x.priority));
  EXPECT_EQ(want, (std::multiset<uint8_t>{0, 1, 6, 7, 14}));
  std::multiset<uint8_t> heard;
  for (auto& f : b.rec->frames())
    heard.insert(f.lane);
  EXPECT_EQ(heard, want);
}

TEST_F(can_emu_test, fd_stations_carry_up_to_64_bytes_of_any_length) {
  auto a = start("can0", {{"node", "1"}, {"fd", "true"}});
  auto b = start("can1", {{"node", "2"}, {"fd", "true"}});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_TRUE(is(a.send(2, byte_buffer(65, 1)), ec::packet_too_large));
  std::vector<size_t> sizes{0, 8, 9, 13, 33, 49, 63, 64};
  for (auto n : sizes) {
    byte_buffer payload(n);
    for (size_t i = 0; i < n; ++i)
      payload[i] = static_cast<uint8_t>(n + i);
    ASSERT_FALSE(a.send(2, payload)) << n;
  }
  ASSERT_TRUE(b.rec->wait_frames(sizes.size()));
  auto frames = b.rec->frames();
  for (size_t k = 0; k < sizes.size(); ++k) {
    ASSERT_EQ(frames[k].bytes.size(), sizes[k]) << "padding was not removed";
    for (size_t i = 0; i < sizes[k]; ++i)
      ASSERT_EQ(frames[k].bytes[i], static_cast<uint8_t>(sizes[k] + i));
  }
}

TEST_F(can_emu_test, an_fd_station_takes_classic_frames_but_not_the_reverse) {
  auto fd = start("can0", {{"node", "1"}, {"fd", "true"}});
  auto classic = start("can1", {{"node", "2"}});
  ASSERT_TRUE(fd.driver && classic.driver);
  ASSERT_FALSE(classic.send(1, bytes_of("classic")));
  ASSERT_TRUE(fd.rec->wait_frames(1));
  EXPECT_EQ(text_of(fd.rec->frames()[0].bytes), "classic");
  ASSERT_FALSE(fd.send(2, bytes_of("fd")));
  ASSERT_TRUE(classic.rec->wait_malformed(1));
  EXPECT_TRUE(contains(classic.rec->malformed_frames()[0].why, "CAN FD"));
  EXPECT_EQ(classic.rec->malformed_frames()[0].src, 1u);
  EXPECT_TRUE(classic.rec->frames().empty());
}

TEST_F(can_emu_test, eleven_bit_stations_exchange_frames) {
  auto a = start("can0", {{"node", "1"}, {"id_format", "11bit"}});
  auto b = start("can1", {{"node", "14"}, {"id_format", "11bit"}});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_TRUE(is(a.send(15, bytes_of("x")), ec::invalid_address));
  ASSERT_FALSE(a.send(14, bytes_of("eleven")));
  ASSERT_FALSE(a.send(broadcast_addr, bytes_of("all")));
  ASSERT_TRUE(b.rec->wait_frames(2));
  EXPECT_EQ(b.rec->frames()[0].src, 1u);
  EXPECT_EQ(text_of(b.rec->frames()[0].bytes), "eleven");
  EXPECT_EQ(text_of(b.rec->frames()[1].bytes), "all");
}

TEST_F(can_emu_test, lowest_identifier_wins_when_several_stations_wait_for_the_bus) {
  // At 1,000 bit/s an 8-byte frame occupies the bus for 131 ms. Station 1
  // queues a bulk frame on the idle bus; right after it, stations 2..5 queue
  // frames of priorities 3, 1, 2 and 1. The bulk frame became ready first,
  // so it is sent first (a frame on the bus is never preempted); when it
  // ends, the four wait for the bus and arbitrate: priority 1 from node 3,
  // priority 1 from node 5 (same priority and destination: the lower source
  // wins), priority 2, priority 3.
  option_map slow{{"bitrate", "1000"}};
  auto opts = [&](const char* node) {
    auto o = slow;
    o["node"] = node;
    return o;
  };
  auto rx = start("can9", opts("9"));
  auto s1 = start("can1", opts("1"));
  auto s2 = start("can2", opts("2"));
  auto s3 = start("can3", opts("3"));
  auto s4 = start("can4", opts("4"));
  auto s5 = start("can5", opts("5"));
  ASSERT_TRUE(rx.driver && s1.driver && s2.driver && s3.driver && s4.driver
              && s5.driver);
  auto t0 = now_ns();
  ASSERT_FALSE(s1.send(9, bytes_of("bulk7"), 7));
  ASSERT_FALSE(s2.send(9, bytes_of("prio3"), 3));
  ASSERT_FALSE(s3.send(9, bytes_of("prio1"), 1));
  ASSERT_FALSE(s4.send(9, bytes_of("prio2"), 2));
  ASSERT_FALSE(s5.send(9, bytes_of("prio1b"), 1));
  auto queued_within = now_ns() - t0;
  ASSERT_TRUE(rx.rec->wait_frames(5, 20s));
  auto frames = rx.rec->frames();
  std::vector<std::string> order;
  std::vector<link_addr> srcs;
  for (auto& f : frames) {
    order.push_back(text_of(f.bytes));
    srcs.push_back(f.src);
  }
  // Only meaningful if the test thread queued everything during the first
  // frame; it did unless it was descheduled for over 100 ms.
  ASSERT_LT(queued_within, 100'000'000) << "test thread too slow to judge";
  EXPECT_EQ(order, (std::vector<std::string>{"bulk7", "prio1", "prio1b",
                                             "prio2", "prio3"}));
  EXPECT_EQ(srcs, (std::vector<link_addr>{1, 3, 5, 4, 2}));
  // Frames never overlap on the bus: frame i ends at least i + 1 frame
  // times (of the shortest, 5-byte frame) after the first was queued.
  auto frame_ns = can::bits_time_ns(can::frame_bits(id_format::ext29, 5,
                                                    false),
                                    1000);
  for (size_t i = 0; i < frames.size(); ++i)
    EXPECT_GE(frames[i].at_ns - t0, static_cast<int64_t>(i + 1) * frame_ns)
      << "frame " << i;
}

TEST_F(can_emu_test, a_station_sends_its_most_urgent_queued_frame_first) {
  // Station 1 holds the bus for 131 ms; meanwhile station 2 queues five
  // bulk frames and then one control frame: the control frame goes first.
  option_map slow{{"bitrate", "1000"}};
  auto opts = [&](const char* node) {
    auto o = slow;
    o["node"] = node;
    return o;
  };
  auto rx = start("can9", opts("9"));
  auto s1 = start("can1", opts("1"));
  auto s2 = start("can2", opts("2"));
  ASSERT_TRUE(rx.driver && s1.driver && s2.driver);
  auto t0 = now_ns();
  ASSERT_FALSE(s1.send(9, bytes_of("hold"), prio_control));
  for (int i = 0; i < 3; ++i)
    ASSERT_FALSE(s2.send(9, bytes_of("bulk" + std::to_string(i)), prio_bulk));
  ASSERT_FALSE(s2.send(9, bytes_of("control"), prio_control));
  auto queued_within = now_ns() - t0;
  ASSERT_TRUE(rx.rec->wait_frames(5, 20s));
  ASSERT_LT(queued_within, 100'000'000) << "test thread too slow to judge";
  std::vector<std::string> order;
  for (auto& f : rx.rec->frames())
    order.push_back(text_of(f.bytes));
  EXPECT_EQ(order, (std::vector<std::string>{"hold", "control", "bulk0",
                                             "bulk1", "bulk2"}));
}

TEST_F(can_emu_test, frames_take_at_least_their_bit_time_on_the_bus) {
  // 100 kbit/s: a 29-bit frame with 8 bytes is 131 bits = 1.31 ms. Two
  // stations each send n frames: they share one bus, so the last frame
  // cannot arrive before 2 n frame times after the first send.
  constexpr int n = 40;
  option_map base{{"bitrate", "100000"}};
  auto opts = [&](const char* node) {
    auto o = base;
    o["node"] = node;
    return o;
  };
  auto rx = start("can9", opts("9"));
  auto a = start("can1", opts("1"));
  auto b = start("can2", opts("2"));
  ASSERT_TRUE(rx.driver && a.driver && b.driver);
  auto frame_ns = can::bits_time_ns(131, 100'000);
  ASSERT_EQ(frame_ns, 1'310'000);
  auto t0 = now_ns();
  for (int i = 0; i < n; ++i) {
    ASSERT_FALSE(a.send(9, byte_buffer(8, 0xA0), prio_normal));
    ASSERT_FALSE(b.send(9, byte_buffer(8, 0xB0), prio_normal));
  }
  ASSERT_TRUE(rx.rec->wait_frames(2 * n, 20s));
  auto frames = rx.rec->frames();
  EXPECT_GE(frames.back().at_ns - t0, 2 * n * frame_ns);
  // Each station's own frames are at least one frame time apart, too.
  std::vector<int64_t> from_a;
  for (auto& f : frames)
    if (f.src == 1)
      from_a.push_back(f.at_ns);
  ASSERT_EQ(from_a.size(), size_t{n});
  EXPECT_GE(from_a.back() - t0, n * frame_ns);
}

TEST_F(can_emu_test, bit_stuffing_lengthens_frames_to_the_worst_case) {
  constexpr int n = 30;
  auto rx = start("can9", {{"node", "9"}, {"bitrate", "100000"}});
  auto a = start("can1",
                 {{"node", "1"}, {"bitrate", "100000"}, {"stuffing", "true"}});
  ASSERT_TRUE(rx.driver && a.driver);
  auto t0 = now_ns();
  for (int i = 0; i < n; ++i)
    ASSERT_FALSE(a.send(9, byte_buffer(8, 0)));
  ASSERT_TRUE(rx.rec->wait_frames(n, 20s));
  EXPECT_GE(rx.rec->frames().back().at_ns - t0,
            n * can::bits_time_ns(160, 100'000));
}

TEST_F(can_emu_test, full_transmit_queue_refuses_frames) {
  // 1,000 bit/s: nothing leaves the queue while the test fills it.
  auto a = start("can0", {{"node", "1"}, {"bitrate", "1000"}, {"queue", "2"}});
  ASSERT_TRUE(a.driver);
  size_t refused = 0;
  for (int i = 0; i < 5; ++i) {
    auto err = a.send(2, byte_buffer(8, 0));
    if (err) {
      EXPECT_TRUE(is(err, ec::queue_full)) << render(err);
      EXPECT_TRUE(contains(render(err), "device 'can0'")) << render(err);
      ++refused;
    }
  }
  EXPECT_GE(refused, 2u); // capacity: 2 queued plus at most 1 on the bus
  a.driver->stop();
  auto err = a.send(2, bytes_of("late"));
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
}

TEST_F(can_emu_test, malformed_datagrams_are_dropped_and_counted) {
  auto a = start("can0", {{"node", "1"}});
  auto b = start("can1", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  int raw = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(raw, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  auto path = sock_path(2);
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  auto send_raw = [&](const std::vector<uint8_t>& bytes) {
    return ::sendto(raw, bytes.data(), bytes.size(), 0,
                    reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
  };
  auto datagram = [](canid_t id, uint8_t len, size_t frame_size = CAN_MTU) {
    std::vector<uint8_t> buf(can::wire::header_size + frame_size, 0);
    can::wire::header h;
    h.deliver_at_ns = now_ns();
    can::wire::encode(h, buf.data());
    canfd_frame f{};
    f.can_id = id;
    f.len = len;
    std::memcpy(buf.data() + can::wire::header_size, &f, frame_size);
    return buf;
  };
  auto good_id = [](uint8_t dst, uint8_t src) {
    return can::to_can_id(id_format::ext29, frame_id{2, dst, src, 0});
  };
  std::vector<std::vector<uint8_t>> garbage{
    {1, 2, 3},                                         // too short
    std::vector<uint8_t>(can::wire::header_size + CAN_MTU, 0), // bad magic
    datagram(good_id(2, 1), 4, 10),                    // neither MTU
    datagram(CAN_EFF_FLAG | 2u << 18 | 1u << 10, 4),   // foreign tag
    datagram(0x123, 4),                                // standard id
    datagram(good_id(2, 1) | CAN_RTR_FLAG, 0),         // remote frame
    datagram(good_id(2, 1), 9),                        // length 9
    datagram(good_id(2, 1), 8, CANFD_MTU),             // FD at classic
    datagram(good_id(2, 2), 1),                        // our own node id
    datagram(good_id(2, 0), 1),                        // source 0
  };
  for (auto& g : garbage)
    ASSERT_EQ(send_raw(g), static_cast<ssize_t>(g.size()));
  // Well-formed, but for node 3: filtered, not malformed.
  ASSERT_EQ(send_raw(datagram(good_id(3, 1), 1)),
            static_cast<ssize_t>(can::wire::header_size + CAN_MTU));
  ::close(raw);
  ASSERT_TRUE(b.rec->wait_malformed(garbage.size()))
    << b.rec->malformed_frames().size();
  ASSERT_FALSE(a.send(2, bytes_of("still ok")));
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_EQ(text_of(b.rec->frames()[0].bytes), "still ok");
  auto bad = b.rec->malformed_frames();
  EXPECT_EQ(bad.size(), garbage.size());
  EXPECT_TRUE(contains(bad[3].why, "not a HERM identifier")) << bad[3].why;
  EXPECT_TRUE(contains(bad[4].why, "standard 11-bit")) << bad[4].why;
  EXPECT_TRUE(contains(bad[5].why, "remote")) << bad[5].why;
  EXPECT_TRUE(contains(bad[6].why, "length")) << bad[6].why;
  EXPECT_EQ(bad[6].src, 1u);
  EXPECT_EQ(b.counter("rx_malformed"), garbage.size());
  EXPECT_EQ(b.counter("rx_filtered"), 1u);
  EXPECT_TRUE(b.rec->failures().empty());
}

TEST_F(can_emu_test, injected_errors_are_reported_and_frames_retransmitted) {
  auto a = start("can0", {{"node", "1"}, {"error_rate", "0.5"}, {"seed", "7"}});
  auto b = start("can1", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  constexpr int n = 40;
  for (int i = 0; i < n; ++i)
    ASSERT_FALSE(a.send(2, bytes_of("f" + std::to_string(i))));
  ASSERT_TRUE(b.rec->wait_frames(n));
  auto frames = b.rec->frames();
  for (int i = 0; i < n; ++i)
    EXPECT_EQ(text_of(frames[i].bytes), "f" + std::to_string(i));
  auto errors = a.counter("tx_errors");
  EXPECT_GT(errors, 0u);
  ASSERT_TRUE(b.rec->wait_events(errors));
  for (auto& e : b.rec->events())
    EXPECT_EQ(e.kind, link_event_kind::error_frame);
  // The transmitter sees its own error frames, too.
  EXPECT_TRUE(a.rec->wait_events(errors));
}

TEST_F(can_emu_test, loss_drops_frames_per_receiver) {
  auto a = start("can0", {{"node", "1"}});
  auto b = start("can1", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  ASSERT_FALSE(a.driver->set_param("loss", "1"));
  EXPECT_EQ(*a.driver->get_param("loss"), "1");
  for (int i = 0; i < 5; ++i)
    ASSERT_FALSE(a.send(2, bytes_of("lost")));
  ASSERT_TRUE(wait_counter(a, "tx_frames", 5)); // all on the bus
  ASSERT_FALSE(a.driver->set_param("loss", "0"));
  ASSERT_FALSE(a.send(2, bytes_of("kept")));
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_EQ(text_of(b.rec->frames()[0].bytes), "kept");
  EXPECT_EQ(a.counter("tx_lost"), 5u);
  auto err = a.driver->set_param("bitrate", "5");
  EXPECT_TRUE(is(err, ec::invalid_parameter)) << render(err);
  EXPECT_TRUE(contains(render(err), "'bitrate'"));
}

TEST_F(can_emu_test, removing_the_bus_directory_fails_every_station_once) {
  auto a = start("can0", {{"node", "1"}});
  auto b = start("can1", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  remove_tree(bus_dir_);
  ASSERT_TRUE(a.rec->wait_failures(1));
  ASSERT_TRUE(b.rec->wait_failures(1));
  std::this_thread::sleep_for(300ms); // a second report would come by now
  auto failures = a.rec->failures();
  ASSERT_EQ(failures.size(), 1u);
  EXPECT_TRUE(is(failures[0], ec::device_failed)) << render(failures[0]);
  EXPECT_TRUE(contains(render(failures[0]), "removed"))
    << render(failures[0]);
  EXPECT_TRUE(contains(render(failures[0]), "device 'can0'"));
  EXPECT_EQ(b.rec->failures().size(), 1u);
  auto err = a.send(2, bytes_of("x"));
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
}

TEST_F(can_emu_test, removing_a_station_socket_fails_that_station_only) {
  auto a = start("can0", {{"node", "1"}});
  auto b = start("can1", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  ASSERT_EQ(::unlink(sock_path(2).c_str()), 0);
  ASSERT_TRUE(b.rec->wait_failures(1));
  EXPECT_TRUE(contains(render(b.rec->failures()[0]), "2.sock"));
  std::this_thread::sleep_for(300ms);
  EXPECT_TRUE(a.rec->failures().empty());
}

TEST_F(can_emu_test, stop_is_idempotent_and_removes_the_station) {
  auto a = start("can0", {{"node", "1"}});
  ASSERT_TRUE(a.driver);
  EXPECT_TRUE(exists(sock_path(1)));
  a.driver->stop();
  a.driver->stop();
  EXPECT_FALSE(exists(sock_path(1)));
  auto err = a.driver->start(std::make_shared<recorder>());
  EXPECT_TRUE(err);
}

TEST_F(can_emu_test, a_dead_station_does_not_block_the_bus_for_ever) {
  // A child process joins the bus, publishes urgent frames and is killed
  // with them pending. Its slot keeps the lowest identifier on the bus, but
  // without a heartbeat arbitration ignores it after a second.
  int go[2];
  int ready[2];
  ASSERT_EQ(::pipe(go), 0);
  ASSERT_EQ(::pipe(ready), 0);
  auto pid = ::fork(); // before this process starts any driver thread
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    ::alarm(30);
    ::close(go[1]);
    ::close(ready[0]);
    char c = 0;
    if (::read(go[0], &c, 1) != 1)
      ::_exit(1);
    device_config cfg{"dead", "can", bus_,
                      {{"node", "1"}, {"bitrate", "1000"}}};
    auto d = find_link_kind("can")->open(cfg);
    if (d) {
      for (int i = 0; i < 3; ++i)
        (*d)->send(2, reinterpret_cast<const uint8_t*>("x"), 1, prio_control);
      char ok = 'R';
      [[maybe_unused]] auto n = ::write(ready[1], &ok, 1);
    }
    ::pause();
    ::_exit(0);
  }
  ::close(go[0]);
  ::close(ready[1]);
  auto rx = start("can2", {{"node", "2"}, {"bitrate", "1000"}});
  auto tx = start("can3", {{"node", "3"}, {"bitrate", "1000"}});
  char c = 'G';
  bool child_ready = ::write(go[1], &c, 1) == 1;
  pollfd pfd{ready[0], POLLIN, 0};
  child_ready = child_ready && ::poll(&pfd, 1, 10'000) == 1
                && ::read(ready[0], &c, 1) == 1;
  ::close(go[1]);
  ::close(ready[0]);
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  ASSERT_TRUE(child_ready) << "the child did not queue its frames";
  ASSERT_TRUE(rx.driver && tx.driver);
  auto t0 = now_ns();
  ASSERT_FALSE(tx.send(2, bytes_of("alive"), prio_bulk));
  ASSERT_TRUE(rx.rec->wait_frames(1, 10s));
  auto frames = rx.rec->frames();
  if (frames.back().src != 3) { // the child's first frame made it
    ASSERT_TRUE(rx.rec->wait_frames(frames.size() + 1, 10s));
  }
  EXPECT_EQ(text_of(rx.rec->frames().back().bytes), "alive");
  EXPECT_LT(now_ns() - t0, 5'000'000'000);
}

// -- across processes ---------------------------------------------------------------

/// Child side of the multi-process test: node 2 echoes every frame back to
/// its sender until it hears "quit". Never returns.
[[noreturn]] void run_echo_child(const std::string& bus, int ready_fd) {
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
      } else if (src != 1 || driver->send(src, data, size, prio_normal)) {
        send_failed = true;
      }
    }
    void on_malformed(link_addr, const char*) override {
      std::lock_guard<std::mutex> guard{mtx};
      send_failed = true;
    }
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
    device_config cfg{"child0", "can", bus, {{"node", "2"}, {"queue", "256"}}};
    auto d = find_link_kind("can")->open(cfg);
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

TEST_F(can_emu_test, a_station_in_another_process_echoes_frames) {
  // Fork before this process starts any driver thread.
  int pipe_fds[2];
  ASSERT_EQ(::pipe(pipe_fds), 0);
  auto pid = ::fork();
  ASSERT_GE(pid, 0) << std::strerror(errno);
  if (pid == 0) {
    ::close(pipe_fds[0]);
    run_echo_child(bus_, pipe_fds[1]);
  }
  ::close(pipe_fds[1]);
  auto reap = [pid](std::chrono::milliseconds timeout) {
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
  auto a = start("can0", {{"node", "1"}, {"queue", "256"}});
  auto c = start("can3", {{"node", "3"}});
  if (!a.driver || !c.driver) {
    reap(0ms);
    FAIL() << "cannot open the parent's stations";
  }
  constexpr uint32_t n = 50;
  for (uint32_t i = 0; i < n; ++i)
    EXPECT_FALSE(a.send(2, bytes_of("#" + std::to_string(i))));
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
    EXPECT_EQ(text_of(frames[i].bytes), "#" + std::to_string(i));
  }
  // Node 3 heard the whole conversation on the bus and took none of it.
  EXPECT_TRUE(wait_counter(c, "rx_filtered", 2 * n));
  EXPECT_TRUE(c.rec->frames().empty());
  // The child removed its socket file when it stopped.
  EXPECT_FALSE(exists(sock_path(2)));
}

// -- SocketCAN --------------------------------------------------------------------

/// Talks to the kernel: creates and deletes vcan interfaces (rtnetlink),
/// sets them up or down and changes their MTU (ioctl). Needs CAP_NET_ADMIN.
namespace netdev {

bool rtnl(nlmsghdr* msg, std::string& error) {
  int fd = ::socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_ROUTE);
  if (fd < 0) {
    error = std::string{"netlink socket: "} + std::strerror(errno);
    return false;
  }
  msg->nlmsg_flags |= NLM_F_REQUEST | NLM_F_ACK;
  msg->nlmsg_seq = 1;
  bool ok = false;
  if (::send(fd, msg, msg->nlmsg_len, 0) < 0) {
    error = std::string{"netlink send: "} + std::strerror(errno);
  } else {
    alignas(nlmsghdr) char buf[4096];
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 5000) != 1) {
      error = "netlink: no answer";
    } else {
      auto n = ::recv(fd, buf, sizeof(buf), 0);
      auto* h = reinterpret_cast<nlmsghdr*>(buf);
      if (n < static_cast<ssize_t>(sizeof(nlmsghdr)) || h->nlmsg_type != NLMSG_ERROR) {
        error = "netlink: unexpected answer";
      } else {
        auto* e = static_cast<nlmsgerr*>(NLMSG_DATA(h));
        ok = e->error == 0;
        if (!ok)
          error = std::string{"netlink: "} + std::strerror(-e->error);
      }
    }
  }
  ::close(fd);
  return ok;
}

struct request {
  nlmsghdr hdr;
  ifinfomsg ifi;
  char attrs[512];
};

rtattr* add_attr(request& req, unsigned short type, const void* data,
                 size_t len) {
  auto* rta = reinterpret_cast<rtattr*>(reinterpret_cast<char*>(&req)
                                        + NLMSG_ALIGN(req.hdr.nlmsg_len));
  rta->rta_type = type;
  rta->rta_len = static_cast<unsigned short>(RTA_LENGTH(len));
  if (len > 0)
    std::memcpy(RTA_DATA(rta), data, len);
  req.hdr.nlmsg_len = NLMSG_ALIGN(req.hdr.nlmsg_len) + RTA_ALIGN(rta->rta_len);
  return rta;
}

bool create_vcan(const std::string& name, std::string& error) {
  request req{};
  req.hdr.nlmsg_len = NLMSG_LENGTH(sizeof(ifinfomsg));
  req.hdr.nlmsg_type = RTM_NEWLINK;
  req.hdr.nlmsg_flags = NLM_F_CREATE | NLM_F_EXCL;
  req.ifi.ifi_family = AF_UNSPEC;
  add_attr(req, IFLA_IFNAME, name.c_str(), name.size() + 1);
  auto* info = add_attr(req, IFLA_LINKINFO, nullptr, 0);
  add_attr(req, IFLA_INFO_KIND, "vcan", 4);
  info->rta_len = static_cast<unsigned short>(
    reinterpret_cast<char*>(&req) + req.hdr.nlmsg_len
    - reinterpret_cast<char*>(info));
  return rtnl(&req.hdr, error);
}

bool delete_link(const std::string& name) {
  auto index = ::if_nametoindex(name.c_str());
  if (index == 0)
    return false;
  request req{};
  req.hdr.nlmsg_len = NLMSG_LENGTH(sizeof(ifinfomsg));
  req.hdr.nlmsg_type = RTM_DELLINK;
  req.ifi.ifi_family = AF_UNSPEC;
  req.ifi.ifi_index = static_cast<int>(index);
  std::string error;
  return rtnl(&req.hdr, error);
}

bool ioctl_ifreq(unsigned long op, ifreq& ifr) {
  int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0)
    return false;
  bool ok = ::ioctl(fd, op, &ifr) == 0;
  ::close(fd);
  return ok;
}

bool set_up(const std::string& name, bool up) {
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, name.c_str(), IFNAMSIZ - 1);
  if (!ioctl_ifreq(SIOCGIFFLAGS, ifr))
    return false;
  if (up)
    ifr.ifr_flags = static_cast<short>(ifr.ifr_flags | IFF_UP);
  else
    ifr.ifr_flags = static_cast<short>(ifr.ifr_flags & ~IFF_UP);
  return ioctl_ifreq(SIOCSIFFLAGS, ifr);
}

bool set_mtu(const std::string& name, int mtu) {
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, name.c_str(), IFNAMSIZ - 1);
  ifr.ifr_mtu = mtu;
  return ioctl_ifreq(SIOCSIFMTU, ifr);
}

} // namespace netdev

/// A vcan interface this test created; deleted when it goes out of scope.
class scoped_vcan {
public:
  /// Creates the interface with MTU `mtu` (0: the kernel's default, which
  /// is CANFD_MTU for vcan) and sets it up.
  explicit scoped_vcan(std::string name, int mtu = 0)
    : name_(std::move(name)) {
    netdev::delete_link(name_); // left behind by a killed run
    if (!netdev::create_vcan(name_, error_))
      return;
    created_ = true;
    if (mtu != 0 && !netdev::set_mtu(name_, mtu)) {
      error_ = "cannot set MTU " + std::to_string(mtu) + ": "
               + std::strerror(errno);
      return;
    }
    if (!netdev::set_up(name_, true)) {
      error_ = std::string{"cannot set it up: "} + std::strerror(errno);
      return;
    }
    ok_ = true;
  }

  ~scoped_vcan() {
    if (created_)
      netdev::delete_link(name_);
  }

  bool ok() const {
    return ok_;
  }

  const std::string& error() const {
    return error_;
  }

  const std::string& name() const {
    return name_;
  }

private:
  std::string name_;
  std::string error_;
  bool created_ = false;
  bool ok_ = false;
};

/// A raw CAN socket for the test's own frames (injecting, sniffing).
class raw_can {
public:
  explicit raw_can(const std::string& ifname, bool fd_frames = false) {
    fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
    if (fd_ < 0)
      return;
    if (fd_frames) {
      int on = 1;
      ::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof(on));
    }
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = static_cast<int>(::if_nametoindex(ifname.c_str()));
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }

  ~raw_can() {
    if (fd_ >= 0)
      ::close(fd_);
  }

  bool ok() const {
    return fd_ >= 0;
  }

  bool send(canid_t id, const byte_buffer& data) {
    can_frame f{};
    f.can_id = id;
    f.len = static_cast<uint8_t>(data.size());
    std::memcpy(f.data, data.data(), std::min<size_t>(data.size(), 8));
    return ::write(fd_, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f));
  }

  /// Reads one frame within `timeout`; returns its size (0 on timeout).
  size_t receive(canfd_frame& f, std::chrono::milliseconds timeout = 5s) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1)
      return 0;
    auto n = ::read(fd_, &f, sizeof(f));
    return n > 0 ? static_cast<size_t>(n) : 0;
  }

private:
  int fd_ = -1;
};

/// Runs against vcan0. Skips where the kernel has no vcan0 (the ordinary
/// host run); tests/qemu/run-can-kernel-test.sh provides one.
class socketcan : public ::testing::Test {
protected:
  void SetUp() override {
    if (::if_nametoindex("vcan0") == 0)
      GTEST_SKIP() << "no vcan0 interface on this kernel (SocketCAN tests run "
                      "in tests/qemu/run-can-kernel-test.sh, or create one: "
                      "ip link add dev vcan0 type vcan && ip link set vcan0 "
                      "up)";
  }

  void TearDown() override {
    for (auto& d : drivers_)
      d->stop();
    drivers_.clear();
  }

  station start(const std::string& name, const std::string& ifname,
                option_map options) {
    return start_can(drivers_, name, ifname, std::move(options));
  }

  std::vector<link_driver_ptr> drivers_;
};

// These two need no CAN in the kernel: they run on every host.

TEST(socketcan_open, an_unknown_interface_is_a_typed_error_naming_it) {
  std::vector<link_driver_ptr> opened;
  auto d = open_can(opened, "can7", "hermnope7", {{"node", "1"}});
  ASSERT_FALSE(d);
  EXPECT_TRUE(is(d.error(), ec::device_unavailable)) << render(d.error());
  EXPECT_TRUE(contains(render(d.error()), "'hermnope7'")) << render(d.error());
  EXPECT_TRUE(contains(render(d.error()), "device 'can7'"))
    << render(d.error());
}

TEST(socketcan_open, a_network_interface_that_is_not_can_is_refused) {
  std::vector<link_driver_ptr> opened;
  auto d = open_can(opened, "can7", "lo", {{"node", "1"}});
  ASSERT_FALSE(d);
  EXPECT_TRUE(is(d.error(), ec::device_unavailable)) << render(d.error());
  EXPECT_TRUE(contains(render(d.error()), "not a CAN interface"))
    << render(d.error());
}

TEST_F(socketcan, two_drivers_exchange_frames_with_herm_identifiers) {
  raw_can sniffer{"vcan0"};
  ASSERT_TRUE(sniffer.ok()) << std::strerror(errno);
  auto a = start("can0", "vcan0", {{"node", "1"}});
  auto b = start("can1", "vcan0", {{"node", "2"}});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_EQ(*a.driver->get_param("backend"), "socketcan");
  EXPECT_EQ(a.driver->profile().mtu, 8u);
  ASSERT_FALSE(a.send(2, bytes_of("hello"), prio_high));
  ASSERT_FALSE(b.send(1, byte_buffer(8, 0x5A), prio_bulk));
  ASSERT_FALSE(a.send(2, byte_buffer{}, prio_control));
  ASSERT_TRUE(b.rec->wait_frames(2));
  ASSERT_TRUE(a.rec->wait_frames(1));
  EXPECT_EQ(b.rec->frames()[0].src, 1u);
  EXPECT_EQ(b.rec->frames()[0].bytes, bytes_of("hello"));
  EXPECT_TRUE(b.rec->frames()[1].bytes.empty());
  EXPECT_EQ(a.rec->frames()[0].src, 2u);
  EXPECT_EQ(a.rec->frames()[0].bytes, byte_buffer(8, 0x5A));
  // On the wire: 29-bit ids with priority, destination, source and tag.
  struct {
    frame_id id;
    size_t len;
  } expected[] = {{{prio_high, 2, 1, 0}, 5},
                  {{prio_bulk, 1, 2, 0}, 8},
                  {{prio_control, 2, 1, 0}, 0}};
  for (auto& e : expected) {
    canfd_frame f{};
    ASSERT_EQ(sniffer.receive(f), size_t{CAN_MTU});
    EXPECT_EQ(f.can_id, can::to_can_id(id_format::ext29, e.id))
      << std::hex << f.can_id;
    EXPECT_EQ(f.len, e.len);
  }
  EXPECT_TRUE(a.rec->malformed_frames().empty());
  EXPECT_TRUE(b.rec->malformed_frames().empty());
}

TEST_F(socketcan, broadcast_reaches_every_other_node_and_unicast_only_its_own) {
  auto a = start("can0", "vcan0", {{"node", "1"}});
  auto b = start("can1", "vcan0", {{"node", "2"}});
  auto c = start("can2", "vcan0", {{"node", "3"}});
  ASSERT_TRUE(a.driver && b.driver && c.driver);
  ASSERT_FALSE(a.send(broadcast_addr, bytes_of("all")));
  ASSERT_FALSE(a.send(2, bytes_of("to b")));
  ASSERT_FALSE(a.send(3, bytes_of("to c")));
  ASSERT_TRUE(b.rec->wait_frames(2));
  ASSERT_TRUE(c.rec->wait_frames(2));
  EXPECT_EQ(text_of(b.rec->frames()[0].bytes), "all");
  EXPECT_EQ(text_of(b.rec->frames()[1].bytes), "to b");
  EXPECT_EQ(text_of(c.rec->frames()[0].bytes), "all");
  EXPECT_EQ(text_of(c.rec->frames()[1].bytes), "to c");
  // Lanes (can::lane_of) at prio_normal: 5 for the broadcast, 4 unicast.
  EXPECT_EQ(b.rec->frames()[0].lane, 5);
  EXPECT_EQ(b.rec->frames()[1].lane, 4);
  // The kernel filter kept the other unicast away.
  EXPECT_EQ(b.counter("rx_filtered"), 0u);
  ASSERT_FALSE(b.send(1, bytes_of("marker")));
  ASSERT_TRUE(a.rec->wait_frames(1));
  ASSERT_EQ(a.rec->frames().size(), 1u); // not its own broadcast
  EXPECT_EQ(text_of(a.rec->frames()[0].bytes), "marker");
}

TEST_F(socketcan, foreign_protocol_frames_are_counted_as_malformed) {
  raw_can raw{"vcan0"};
  ASSERT_TRUE(raw.ok()) << std::strerror(errno);
  auto b = start("can1", "vcan0", {{"node", "2"}});
  // Without the kernel filter, every frame on the bus reaches the driver.
  auto open = start("can5", "vcan0", {{"node", "5"}, {"filter", "false"}});
  ASSERT_TRUE(b.driver && open.driver);
  // Our destination bits (2) but another protocol tag; an RTR frame with a
  // HERM id; a standard frame; a HERM frame for node 3.
  canid_t foreign = CAN_EFF_FLAG | 2u << 18 | 1u << 10 | 0x3Fu << 4;
  canid_t herm_to_2 = can::to_can_id(id_format::ext29, frame_id{2, 2, 1, 0});
  canid_t herm_to_3 = can::to_can_id(id_format::ext29, frame_id{2, 3, 1, 0});
  canid_t herm_to_5 = can::to_can_id(id_format::ext29, frame_id{2, 5, 1, 0});
  ASSERT_TRUE(raw.send(foreign, bytes_of("j1939")));
  ASSERT_TRUE(raw.send(herm_to_2 | CAN_RTR_FLAG, {}));
  ASSERT_TRUE(raw.send(0x123, bytes_of("std")));
  ASSERT_TRUE(raw.send(herm_to_3, bytes_of("for 3")));
  ASSERT_TRUE(raw.send(herm_to_2, bytes_of("ok")));
  ASSERT_TRUE(raw.send(herm_to_5, bytes_of("ok")));
  ASSERT_TRUE(b.rec->wait_frames(1));
  ASSERT_TRUE(open.rec->wait_frames(1));
  // In order on one socket: everything before "ok" has been handled.
  auto bad = b.rec->malformed_frames();
  ASSERT_EQ(bad.size(), 2u); // the standard frame did not pass the filter
  EXPECT_TRUE(contains(bad[0].why, "not a HERM identifier")) << bad[0].why;
  EXPECT_TRUE(contains(bad[1].why, "remote")) << bad[1].why;
  EXPECT_EQ(b.counter("rx_malformed"), 2u);
  auto seen = open.rec->malformed_frames();
  ASSERT_EQ(seen.size(), 3u);
  EXPECT_TRUE(contains(seen[2].why, "standard 11-bit")) << seen[2].why;
  EXPECT_EQ(open.counter("rx_filtered"), 2u); // "for 3" and "ok" for 2
  EXPECT_EQ(text_of(open.rec->frames()[0].bytes), "ok");
}

TEST_F(socketcan, error_frames_become_link_events) {
  raw_can raw{"vcan0"};
  ASSERT_TRUE(raw.ok()) << std::strerror(errno);
  auto a = start("can0", "vcan0", {{"node", "1"}});
  ASSERT_TRUE(a.driver);
  byte_buffer passive(8, 0);
  passive[1] = CAN_ERR_CRTL_TX_PASSIVE;
  byte_buffer active(8, 0);
  active[1] = CAN_ERR_CRTL_ACTIVE;
  // vcan has no controller; a raw socket may put error frames on it, and
  // the kernel hands them to sockets whose error mask matches.
  ASSERT_TRUE(raw.send(CAN_ERR_FLAG | CAN_ERR_CRTL, passive));
  ASSERT_TRUE(raw.send(CAN_ERR_FLAG | CAN_ERR_BUSOFF, byte_buffer(8, 0)));
  ASSERT_TRUE(raw.send(CAN_ERR_FLAG | CAN_ERR_RESTARTED, byte_buffer(8, 0)));
  ASSERT_TRUE(raw.send(CAN_ERR_FLAG | CAN_ERR_CRTL, active));
  // Not subscribed: lost arbitration is normal on a busy bus.
  ASSERT_TRUE(raw.send(CAN_ERR_FLAG | CAN_ERR_LOSTARB, byte_buffer(8, 0)));
  ASSERT_TRUE(a.rec->wait_events(4));
  std::this_thread::sleep_for(100ms);
  auto events = a.rec->events();
  ASSERT_EQ(events.size(), 4u);
  EXPECT_EQ(events[0].kind, link_event_kind::error_frame);
  EXPECT_TRUE(contains(events[0].detail, "tx error-passive"))
    << events[0].detail;
  EXPECT_EQ(events[1].kind, link_event_kind::bus_off);
  EXPECT_EQ(events[2].kind, link_event_kind::bus_recovered);
  EXPECT_EQ(events[3].kind, link_event_kind::bus_recovered);
  EXPECT_TRUE(a.rec->malformed_frames().empty());
}

TEST_F(socketcan, fd_needs_an_fd_capable_interface_and_carries_64_bytes) {
  // An interface with the classic MTU refuses fd=true, naming the reason,
  // and works with fd=false.
  {
    scoped_vcan classic{"hermclassic0", CAN_MTU};
    if (!classic.ok())
      GTEST_SKIP() << "cannot create a vcan interface: " << classic.error();
    std::vector<link_driver_ptr> opened;
    auto refused = open_can(opened, "can0", classic.name(),
                            {{"node", "1"}, {"fd", "true"}});
    ASSERT_FALSE(refused);
    EXPECT_TRUE(is(refused.error(), ec::device_unavailable));
    EXPECT_TRUE(contains(render(refused.error()), "not CAN FD capable (MTU 16"))
      << render(refused.error());
    auto plain = open_can(opened, "can0", classic.name(), {{"node", "1"}});
    ASSERT_TRUE(plain) << render(plain.error());
    EXPECT_EQ(*(*plain)->get_param("if_mtu"), "16");
    (*plain)->stop();
  }
  scoped_vcan fd_if{"hermfd0", CANFD_MTU};
  if (!fd_if.ok())
    GTEST_SKIP() << "cannot create a CAN FD vcan: " << fd_if.error();
  raw_can sniffer{fd_if.name(), true};
  ASSERT_TRUE(sniffer.ok());
  auto a = start("fd0", fd_if.name(), {{"node", "1"}, {"fd", "true"}});
  auto b = start("fd1", fd_if.name(), {{"node", "2"}, {"fd", "true"}});
  ASSERT_TRUE(a.driver && b.driver);
  EXPECT_EQ(a.driver->profile().mtu, 64u);
  std::vector<size_t> sizes{3, 13, 64};
  for (auto n : sizes)
    ASSERT_FALSE(a.send(2, byte_buffer(n, static_cast<uint8_t>(n))));
  ASSERT_TRUE(b.rec->wait_frames(sizes.size()));
  for (size_t k = 0; k < sizes.size(); ++k) {
    EXPECT_EQ(b.rec->frames()[k].bytes,
              byte_buffer(sizes[k], static_cast<uint8_t>(sizes[k])));
    canfd_frame f{};
    ASSERT_EQ(sniffer.receive(f), size_t{CANFD_MTU});
    EXPECT_EQ(f.len, can::fd_round_up(sizes[k]));
    EXPECT_EQ(f.can_id & 0xF, can::fd_round_up(sizes[k]) - sizes[k]);
  }
  // Stop the drivers before the interface goes away.
  a.driver->stop();
  b.driver->stop();
}

TEST_F(socketcan, interface_going_down_fails_the_driver_once) {
  scoped_vcan vif{"hermdown0"};
  if (!vif.ok())
    GTEST_SKIP() << "cannot create a vcan interface: " << vif.error();
  auto a = start("can0", vif.name(), {{"node", "1"}});
  ASSERT_TRUE(a.driver);
  ASSERT_TRUE(netdev::set_up(vif.name(), false)) << std::strerror(errno);
  ASSERT_TRUE(a.rec->wait_failures(1));
  auto err = a.send(2, bytes_of("x"));
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
  std::this_thread::sleep_for(200ms);
  auto failures = a.rec->failures();
  ASSERT_EQ(failures.size(), 1u);
  EXPECT_TRUE(is(failures[0], ec::device_failed)) << render(failures[0]);
  EXPECT_TRUE(contains(render(failures[0]), "'hermdown0' went down"))
    << render(failures[0]);
  // A down interface cannot be opened.
  std::vector<link_driver_ptr> opened;
  auto again = open_can(opened, "can1", vif.name(), {{"node", "2"}});
  ASSERT_FALSE(again);
  EXPECT_TRUE(is(again.error(), ec::device_unavailable));
  EXPECT_TRUE(contains(render(again.error()), "is down"))
    << render(again.error());
  a.driver->stop();
}

TEST_F(socketcan, interface_removal_fails_the_driver_once) {
  auto vif = std::make_unique<scoped_vcan>("hermgone0");
  if (!vif->ok())
    GTEST_SKIP() << "cannot create a vcan interface: " << vif->error();
  auto a = start("can0", "hermgone0", {{"node", "1"}});
  ASSERT_TRUE(a.driver);
  vif.reset(); // deletes the interface
  ASSERT_TRUE(a.rec->wait_failures(1));
  std::this_thread::sleep_for(200ms);
  auto failures = a.rec->failures();
  ASSERT_EQ(failures.size(), 1u);
  EXPECT_TRUE(contains(render(failures[0]), "'hermgone0'"))
    << render(failures[0]);
  auto err = a.send(2, bytes_of("x"));
  EXPECT_TRUE(is(err, ec::device_failed)) << render(err);
}

TEST_F(socketcan, eleven_bit_identifiers_work_on_a_real_kernel) {
  raw_can sniffer{"vcan0"};
  ASSERT_TRUE(sniffer.ok());
  auto a = start("can0", "vcan0", {{"node", "1"}, {"id_format", "11bit"}});
  auto b = start("can1", "vcan0", {{"node", "14"}, {"id_format", "11bit"}});
  ASSERT_TRUE(a.driver && b.driver);
  ASSERT_FALSE(a.send(14, bytes_of("std"), 5));
  ASSERT_TRUE(b.rec->wait_frames(1));
  EXPECT_EQ(b.rec->frames()[0].src, 1u);
  canfd_frame f{};
  ASSERT_EQ(sniffer.receive(f), size_t{CAN_MTU});
  EXPECT_EQ(f.can_id, 0x5E1u);
}

} // namespace
