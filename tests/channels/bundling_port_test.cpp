// Bundling as a port decorator (channels/bundling_port.hpp): which packets
// wait for a bundle, when bundles leave, their wire layout, the MTU bound
// and the counters. No actors: a fake inner port records what comes down.

#include "channels/bundling_port.hpp"

#include <gtest/gtest.h>

#include "caf/sec.hpp"

#include <memory>
#include <string>
#include <vector>

using namespace herm;

namespace {

constexpr uint32_t udp_mtu = 1472;

/// What reached the wrapped port: a packet (send) or a prepared frame
/// (send_frame).
struct sent {
  bool frame;
  link_addr dst;
  uint8_t priority;
  byte_buffer bytes;
};

/// The wrapped port: records everything, can be congested and can refuse
/// frames; receive() copies the frame out as one packet.
class fake_port : public packet_port {
public:
  std::vector<sent> log;
  bool busy = false;
  bool refuse = false;
  size_t flushes = 0;
  size_t received = 0;
  uint32_t largest = 128 * 1024;

  uint32_t max_packet() const override {
    return largest;
  }

  caf::expected<size_t> send(link_addr dst, uint8_t priority,
                             const uint8_t* data, size_t size) override {
    log.push_back(sent{false, dst, priority, byte_buffer(data, data + size)});
    return size_t{1};
  }

  caf::expected<size_t> send_frame(link_addr dst, uint8_t priority,
                                   const uint8_t* data, size_t size) override {
    if (refuse)
      return caf::make_error(caf::sec::runtime_error, "refused");
    log.push_back(sent{true, dst, priority, byte_buffer(data, data + size)});
    return size_t{1};
  }

  rx receive(link_addr, uint8_t, const uint8_t* data, size_t size,
             time_point, byte_buffer& out) override {
    ++received;
    out.assign(data, data + size);
    return rx::packet;
  }

  void flush() override {
    ++flushes;
  }

  bool congested() const override {
    return busy;
  }
};

/// A bundling port over a fake port it lets the test inspect.
struct stack {
  fake_port* inner;
  bundling_port port;

  explicit stack(uint32_t mtu = udp_mtu)
    : stack(std::make_unique<fake_port>(), mtu) {
  }

  stack(std::unique_ptr<fake_port> p, uint32_t mtu)
    : inner(p.get()), port(std::move(p), mtu) {
  }

  caf::expected<size_t> send(const byte_buffer& b, link_addr dst = 7,
                             uint8_t prio = 2) {
    return port.send(dst, prio, b.data(), b.size());
  }
};

/// Packet `i` of `size` bytes, its bytes telling it from the others.
byte_buffer packet(size_t i, size_t size) {
  byte_buffer b(size);
  for (size_t k = 0; k < size; ++k)
    b[k] = static_cast<uint8_t>(i * 31 + k);
  return b;
}

/// The packets a bundle frame holds, in order (empty when malformed).
std::vector<byte_buffer> unbundle(const byte_buffer& frame) {
  std::vector<byte_buffer> out;
  bundle_decode(frame.data(), frame.size(), SIZE_MAX,
                [&](const uint8_t* p, size_t n) { out.emplace_back(p, p + n); });
  return out;
}

/// Every packet that went down, bundled or not, in the order sent.
std::vector<byte_buffer> packets_sent(const fake_port& p) {
  std::vector<byte_buffer> out;
  for (auto& s : p.log) {
    if (!s.frame) {
      out.push_back(s.bytes);
      continue;
    }
    auto inside = unbundle(s.bytes);
    out.insert(out.end(), inside.begin(), inside.end());
  }
  return out;
}

} // namespace

TEST(bundling_port, forms_bundles_for_n_small_packets_written_before_a_flush) {
  struct row {
    const char* what;
    size_t n;
    size_t size;
    std::vector<size_t> expected; // per unit sent: packets (0: alone)
  };
  // At MTU 1472 a 20-byte packet costs 21 bytes after the 1-byte header:
  // 70 fit one bundle frame.
  std::vector<row> rows{
    {"nothing written", 0, 20, {}},
    {"one packet leaves as an ordinary packet", 1, 20, {0}},
    {"two make a bundle", 2, 20, {2}},
    {"ten make one bundle", 10, 20, {10}},
    {"seventy fill one frame exactly", 70, 20, {70}},
    {"the 71st starts the next bundle", 71, 20, {70, 0}},
    {"a hundred make two bundles", 100, 20, {70, 30}},
    {"two of 700 bytes share a frame", 2, 700, {2}},
    {"three of 700 bytes need two frames", 3, 700, {2, 0}},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    stack s;
    std::vector<byte_buffer> written;
    for (size_t i = 0; i < r.n; ++i) {
      written.push_back(packet(i, r.size));
      auto res = s.send(written.back());
      ASSERT_TRUE(res);
      EXPECT_EQ(*res, 0u) << "held until the flush";
    }
    s.port.flush();
    std::vector<size_t> got;
    for (auto& u : s.inner->log) {
      got.push_back(u.frame ? unbundle(u.bytes).size() : 0);
      EXPECT_LE(u.bytes.size(), udp_mtu);
      EXPECT_EQ(u.dst, 7u);
      EXPECT_EQ(u.priority, 2u);
    }
    EXPECT_EQ(got, r.expected);
    EXPECT_EQ(packets_sent(*s.inner), written) << "every packet, in order";
    EXPECT_EQ(s.port.held(), 0u);
  }
}

TEST(bundling_port, a_bundle_frame_is_the_header_then_each_length_and_packet) {
  stack s(256);
  s.send(byte_buffer{'h', 'i'});
  s.send(byte_buffer{'a', 'b', 'c'});
  s.port.flush();
  ASSERT_EQ(s.inner->log.size(), 1u);
  EXPECT_TRUE(s.inner->log[0].frame);
  EXPECT_EQ(s.inner->log[0].bytes,
            (byte_buffer{0x01, 0x02, 'h', 'i', 0x03, 'a', 'b', 'c'}));
}

TEST(bundling_port, bundles_break_where_destination_priority_or_a_large_packet_change) {
  struct step {
    link_addr dst;
    uint8_t prio;
    size_t size;
    bool flush_after = false;
  };
  struct row {
    const char* what;
    std::vector<step> steps;
    std::vector<size_t> expected; // per unit sent: packets (0: alone)
  };
  std::vector<row> rows{
    {"same destination and priority: one bundle",
     {{1, 2, 10}, {1, 2, 10}, {1, 2, 10}}, {3}},
    {"another destination starts a new bundle",
     {{1, 2, 10}, {1, 2, 10}, {5, 2, 10}, {5, 2, 10}}, {2, 2}},
    {"another priority starts a new bundle",
     {{1, 2, 10}, {1, 2, 10}, {1, 0, 10}, {1, 0, 10}}, {2, 2}},
    {"a lone packet between two bundles leaves alone",
     {{1, 2, 10}, {1, 2, 10}, {5, 2, 10}, {1, 2, 10}, {1, 2, 10}},
     {2, 0, 2}},
    {"a large packet sends the held ones first, keeping the order",
     {{1, 2, 10}, {1, 2, 10}, {1, 2, 1000}, {1, 2, 10}}, {2, 0, 0}},
    {"each flush ends a bundle",
     {{1, 2, 10}, {1, 2, 10, true}, {1, 2, 10}, {1, 2, 10, true}, {1, 2, 10}},
     {2, 2, 0}},
    {"a flush with nothing held sends nothing",
     {{1, 2, 1000, true}, {1, 2, 1000, true}}, {0, 0}},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    stack s;
    std::vector<byte_buffer> written;
    for (size_t i = 0; i < r.steps.size(); ++i) {
      auto& st = r.steps[i];
      written.push_back(packet(i, st.size));
      s.port.send(st.dst, st.prio, written.back().data(), written.back().size());
      if (st.flush_after)
        s.port.flush();
    }
    s.port.flush();
    std::vector<size_t> got;
    for (auto& u : s.inner->log)
      got.push_back(u.frame ? unbundle(u.bytes).size() : 0);
    EXPECT_EQ(got, r.expected);
    EXPECT_EQ(packets_sent(*s.inner), written);
  }
}

TEST(bundling_port, only_packets_below_half_the_mtu_wait_for_a_bundle) {
  struct row {
    uint32_t mtu;
    size_t size;
    bool held;
  };
  // Small means bundle_cost(size) + 1 < mtu / 2.
  std::vector<row> rows{
    {1472, 1, true},    {1472, 732, true},  {1472, 733, false},
    {1472, 1400, false}, {256, 124, true},  {256, 125, true},
    {256, 126, false},
  };
  for (auto& r : rows) {
    SCOPED_TRACE("mtu " + std::to_string(r.mtu) + ", size "
                 + std::to_string(r.size));
    EXPECT_EQ(bundling_port::is_small(r.size, r.mtu), r.held);
    stack s(r.mtu);
    auto res = s.send(packet(0, r.size));
    ASSERT_TRUE(res);
    EXPECT_EQ(s.port.held(), r.held ? 1u : 0u);
    EXPECT_EQ(s.inner->log.size(), r.held ? 0u : 1u)
      << "a packet too big to bundle passes at once, alone";
  }
}

TEST(bundling_port, bundles_never_exceed_the_mtu) {
  // Mixed sizes, including 2-byte length fields: every frame stays within
  // the MTU and every packet arrives in order.
  for (uint32_t mtu : {256u, 300u, 1472u}) {
    SCOPED_TRACE("mtu " + std::to_string(mtu));
    stack s(mtu);
    std::vector<byte_buffer> written;
    for (size_t i = 0; i < 200; ++i) {
      written.push_back(packet(i, 1 + (i * 37) % (mtu / 2 - 4)));
      s.send(written.back());
    }
    s.port.flush();
    for (auto& u : s.inner->log)
      EXPECT_LE(u.bytes.size(), mtu);
    EXPECT_EQ(packets_sent(*s.inner), written);
  }
}

TEST(bundling_port, holds_nothing_while_the_wrapped_port_is_congested) {
  stack s;
  s.inner->busy = true;
  s.send(packet(0, 20));
  s.send(packet(1, 20));
  EXPECT_EQ(s.port.held(), 0u);
  ASSERT_EQ(s.inner->log.size(), 2u);
  EXPECT_FALSE(s.inner->log[0].frame);
  EXPECT_FALSE(s.inner->log[1].frame);
}

TEST(bundling_port, flush_reaches_the_wrapped_port) {
  stack s;
  s.port.flush();
  s.port.flush();
  EXPECT_EQ(s.inner->flushes, 2u);
}

TEST(bundling_port, counts_the_packets_and_frames_of_bundles_and_refusals) {
  stack s;
  for (size_t i = 0; i < 5; ++i)
    s.send(packet(i, 30));
  s.port.flush();
  s.send(packet(9, 30)); // alone: the wrapped port counts it
  s.port.flush();
  s.inner->refuse = true;
  for (size_t i = 0; i < 3; ++i)
    s.send(packet(i, 40));
  s.port.flush();
  channel_stats st;
  s.port.add_stats(st);
  EXPECT_EQ(st.tx_bundles, 1u);
  EXPECT_EQ(st.tx_frames, 1u);
  EXPECT_EQ(st.tx_packets, 5u);
  EXPECT_EQ(st.tx_bytes, 150u);
  EXPECT_EQ(st.tx_dropped, 3u) << "a refused bundle drops its packets";
  EXPECT_EQ(s.port.stats().tx_bundles, 1u);
  EXPECT_EQ(s.port.held(), 0u) << "a refused bundle is not kept";
}

TEST(bundling_port, unpacks_a_received_bundle_into_its_packets_in_order) {
  byte_buffer frame;
  std::vector<byte_buffer> packets{packet(0, 3), packet(1, 200), packet(2, 1)};
  for (auto& p : packets)
    ASSERT_TRUE(bundle_append(frame, udp_mtu, p.data(), p.size()));
  stack s;
  byte_buffer out;
  ASSERT_EQ(s.port.receive(3, frame.data(), frame.size(), {}, out),
            packet_port::rx::packet);
  std::vector<byte_buffer> got{out};
  while (s.port.next_packet(out))
    got.push_back(out);
  EXPECT_EQ(got, packets);
  EXPECT_EQ(s.inner->received, 0u);
  channel_stats st;
  s.port.add_stats(st);
  EXPECT_EQ(st.rx_bundles, 1u);
  EXPECT_EQ(st.rx_malformed, 0u);
}

TEST(bundling_port, drops_a_malformed_bundle_whole_and_passes_other_frames_on) {
  struct row {
    const char* what;
    byte_buffer frame;
    packet_port::rx expected;
    size_t to_inner;
    uint64_t malformed;
  };
  std::vector<row> rows{
    {"one packet only", {0x01, 0x02, 'h', 'i'}, packet_port::rx::dropped, 0, 1},
    {"length past the end", {0x01, 0x02, 'h', 'i', 0x05, 'x'},
     packet_port::rx::dropped, 0, 1},
    {"empty packet", {0x01, 0x00, 0x01, 'x'}, packet_port::rx::dropped, 0, 1},
    {"a single frame is not a bundle", {0x00, 'h', 'i'},
     packet_port::rx::packet, 1, 0},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    stack s;
    byte_buffer out;
    EXPECT_EQ(s.port.receive(3, r.frame.data(), r.frame.size(), {}, out),
              r.expected);
    EXPECT_FALSE(s.port.next_packet(out));
    EXPECT_EQ(s.inner->received, r.to_inner);
    channel_stats st;
    s.port.add_stats(st);
    EXPECT_EQ(st.rx_malformed, r.malformed);
    EXPECT_EQ(st.rx_bundles, 0u);
  }
}

TEST(bundling_port, decorates_only_fragmenting_stacks_on_links_of_256_bytes_or_more) {
  struct row {
    uint32_t mtu;
    uint32_t max_packet;
    bool bundles;
  };
  std::vector<row> rows{
    {1472, 128 * 1024, true}, {256, 128 * 1024, true},
    {255, 128 * 1024, false}, {64, 128 * 1024, false},
    {8, 128 * 1024, false},   {1472, 1472, false},
  };
  for (auto& r : rows) {
    SCOPED_TRACE("mtu " + std::to_string(r.mtu) + ", max packet "
                 + std::to_string(r.max_packet));
    auto inner = std::make_unique<fake_port>();
    inner->largest = r.max_packet;
    auto port = with_bundling(std::move(inner), r.mtu);
    EXPECT_EQ(dynamic_cast<bundling_port*>(port.get()) != nullptr, r.bundles);
    EXPECT_EQ(bundling_port::applies(r.mtu, r.max_packet), r.bundles);
  }
}
