// The channel's transmit backlog (channels/tx_backlog.hpp) drains through
// link_driver::send_batch (channels/channel.cpp, flush): completely, in
// order, and past partial takes and a frame refused for good.
//
// The "gate" link kind, added here, is a point-to-point link inside the
// process (delivery on the sender's thread, like inproc) whose sending end
// the test controls: closed, it answers queue_full; it can take only a few
// frames per send_batch call; it can refuse one frame for good. It records
// how many frames each send_batch call took.
//
// Every wait is bounded; no test asserts speed.

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

#include "channels/error.hpp"
#include "channels/io_manager.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"
#include "channels/type_ids.hpp"

namespace herm {
namespace {

using namespace std::chrono_literals;

// -- the "gate" kind ---------------------------------------------------------------

class gate_driver;

/// Both ends of every cable, by interface name: station 1 opened first.
std::mutex cables_mtx;
std::map<std::string, std::vector<gate_driver*>> cables;

class gate_driver : public link_driver {
public:
  gate_driver(std::string cable, link_addr self, link_profile profile)
    : cable_(std::move(cable)), self_(self), profile_(std::move(profile)) {
  }

  ~gate_driver() override {
    stop();
    std::lock_guard<std::mutex> guard{cables_mtx};
    auto& ends = cables[cable_];
    ends.erase(std::find(ends.begin(), ends.end(), this));
  }

  // -- what the test controls (any thread) --

  /// Closed: every send answers queue_full.
  std::atomic<bool> closed{false};
  /// Frames one send_batch call takes at most before answering queue_full.
  std::atomic<size_t> per_call{SIZE_MAX};
  /// The frame with this index (counting every frame taken or refused,
  /// from 0) is refused with packet_too_large; SIZE_MAX: none.
  std::atomic<size_t> refuse_nth{SIZE_MAX};

  /// How many frames each send_batch call took, in order.
  std::vector<size_t> takes() {
    std::lock_guard<std::mutex> guard{mtx_};
    return takes_;
  }

  // -- link_driver --

  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop&) override {
    std::lock_guard<std::mutex> guard{mtx_};
    handler_ = std::move(handler);
    return caf::none;
  }

  void stop() override {
    std::lock_guard<std::mutex> guard{mtx_};
    handler_.reset();
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > profile_.mtu)
      return make_error(ec::packet_too_large, "above the MTU");
    if (dst != broadcast_addr && dst != 3 - self_)
      return make_error(ec::invalid_address, "no such station");
    if (closed)
      return make_error(ec::queue_full, "the gate is closed");
    if (sent_++ == refuse_nth)
      return make_error(ec::packet_too_large, "refused by the test");
    std::shared_ptr<frame_handler> peer;
    {
      std::lock_guard<std::mutex> guard{cables_mtx};
      for (auto* end : cables[cable_])
        if (end != this) {
          std::lock_guard<std::mutex> guard2{end->mtx_};
          peer = end->handler_;
        }
    }
    if (peer)
      peer->on_frame(self_, data, size);
    return caf::none;
  }

  /// Takes at most per_call frames through the default; records how many.
  size_t send_batch(const tx_frame* frames, size_t n,
                    caf::error& err) override {
    auto limit = std::min(n, per_call.load());
    auto taken = link_driver::send_batch(frames, limit, err);
    if (taken == limit && limit < n)
      err = make_error(ec::queue_full, "the gate takes no more this call");
    std::lock_guard<std::mutex> guard{mtx_};
    takes_.push_back(taken);
    return taken;
  }

  const link_profile& profile() const override {
    return profile_;
  }

  link_addr local_addr() const override {
    return self_;
  }

  std::string format_addr(link_addr addr) const override {
    return std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    if (str == "1" || str == "2")
      return link_addr{str == "1" ? 1u : 2u};
    return make_error(ec::invalid_address, str);
  }

private:
  std::string cable_;
  link_addr self_;
  link_profile profile_;
  std::atomic<size_t> sent_{0};
  std::mutex mtx_;
  std::shared_ptr<frame_handler> handler_;
  std::vector<size_t> takes_;
};

caf::expected<link_driver_ptr> open_gate(const device_config& cfg) {
  option_reader opts{cfg};
  auto profile = opts.profile("ethernet");
  if (!profile)
    return profile.error();
  if (auto err = opts.finish())
    return err;
  std::lock_guard<std::mutex> guard{cables_mtx};
  auto& ends = cables[cfg.interface];
  if (ends.size() >= 2)
    return opts.fail(ec::device_unavailable, "the cable has two ends");
  auto drv = std::make_shared<gate_driver>(cfg.interface, ends.size() + 1,
                                           *profile);
  ends.push_back(drv.get());
  return link_driver_ptr{std::move(drv)};
}

const caf::error gate_added = add_link_kind(
  {"gate", "a cable whose sending end the test controls", open_gate});

// -- the fixture ---------------------------------------------------------------------

/// Packet `seq`: its number in the first two bytes, then a pattern.
byte_buffer packet(uint16_t seq, size_t size) {
  byte_buffer p(size);
  for (size_t i = 0; i < size; ++i)
    p[i] = static_cast<uint8_t>(seq * 5 + i);
  p[0] = static_cast<uint8_t>(seq >> 8);
  p[1] = static_cast<uint8_t>(seq);
  return p;
}

uint16_t seq_of(const byte_buffer& p) {
  return static_cast<uint16_t>((p[0] << 8) | p[1]);
}

class channel_backlog : public ::testing::Test {
protected:
  channel_backlog() : sys(init(cfg)), self(sys) {
    io = spawn_io_manager(sys);
  }

  ~channel_backlog() override {
    self->send_exit(io, caf::exit_reason::user_shutdown);
  }

  static caf::actor_system_config& init(caf::actor_system_config& c) {
    c.add_message_types<caf::id_block::herm_channels>();
    return c;
  }

  void SetUp() override {
    ASSERT_FALSE(gate_added) << render(gate_added);
    auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    auto cable = std::string{"cable-"} + info->name();
    tx = open("tx", cable);
    rx = open("rx", cable);
    ASSERT_TRUE(tx && rx);
    {
      std::lock_guard<std::mutex> guard{cables_mtx};
      gate = cables[cable].at(0);
    }
    self->request(rx, 5s, atom::subscribe_v,
                  caf::actor_cast<channel_reader_actor>(self))
      .receive([](channel_info&) {},
               [](caf::error& e) { FAIL() << render(e); });
  }

  channel_actor open(const std::string& name, const std::string& cable) {
    caf::error err;
    self->request(io, 5s, atom::add_v, device_config{name, "gate", cable, {}})
      .receive([](device_info&) {}, [&](caf::error& e) { err = e; });
    EXPECT_FALSE(err) << render(err);
    channel_actor result;
    self->request(io, 5s, atom::open_v, channel_request{name, "*", false})
      .receive([&](channel_actor& ch, channel_info&) { result = ch; },
               [&](caf::error& e) { err = e; });
    EXPECT_FALSE(err) << render(err);
    return result;
  }

  channel_stats stats(const channel_actor& ch) {
    channel_stats result;
    self->request(ch, 5s, atom::get_v, atom::stats_v)
      .receive([&](channel_stats& x) { result = x; },
               [](caf::error& e) { FAIL() << render(e); });
    return result;
  }

  /// With the gate closed, writes `n` packets of mixed sizes (some above
  /// the MTU: several frames each) into the backlog; returns them.
  std::vector<byte_buffer> fill_backlog(uint16_t n) {
    gate->closed = true;
    std::vector<byte_buffer> sent;
    for (uint16_t i = 0; i < n; ++i) {
      sent.push_back(packet(i, i % 10 == 9 ? 3000 : 40 + i % 50));
      self->send(tx, write_packet{2, prio_normal, sent.back()});
    }
    // After every write was handled: all wait in the backlog.
    EXPECT_GT(stats(tx).backlog_bytes, 0u);
    auto takes = gate->takes();
    EXPECT_EQ(std::count(takes.begin(), takes.end(), size_t{0}),
              static_cast<std::ptrdiff_t>(takes.size()))
      << "a closed gate took a frame";
    return sent;
  }

  /// Packets rx delivers until packet `n - 1` (the last one sent) arrived
  /// or none came for 5 s.
  std::vector<byte_buffer> received(size_t n) {
    std::vector<byte_buffer> result;
    bool idle = false;
    while (!idle && (result.empty() || seq_of(result.back()) + 1u < n))
      self->receive(
        [&](packet_received& x) { result.push_back(std::move(x.bytes)); },
        [](link_event&) {}, caf::after(5s) >> [&] { idle = true; });
    return result;
  }

  caf::actor_system_config cfg;
  caf::actor_system sys;
  caf::scoped_actor self;
  io_manager_actor io;
  channel_actor tx;
  channel_actor rx;
  gate_driver* gate = nullptr;
};

// -- the tests ---------------------------------------------------------------------------

TEST_F(channel_backlog, drains_completely_and_in_order_in_batches) {
  auto sent = fill_backlog(200);
  gate->closed = false;
  EXPECT_EQ(received(sent.size()), sent);
  auto st = stats(tx);
  EXPECT_EQ(st.tx_dropped, 0u);
  EXPECT_EQ(st.backlog_bytes, 0u);
  // The flush handed the driver more than one frame per call.
  auto b = gate->takes();
  ASSERT_FALSE(b.empty());
  EXPECT_GT(*std::max_element(b.begin(), b.end()), 1u);
  EXPECT_LE(*std::max_element(b.begin(), b.end()), 64u);
}

TEST_F(channel_backlog, drains_completely_and_in_order_past_partial_takes) {
  auto sent = fill_backlog(120);
  gate->per_call = 3;
  gate->closed = false;
  EXPECT_EQ(received(sent.size()), sent);
  EXPECT_EQ(stats(tx).backlog_bytes, 0u);
  EXPECT_EQ(stats(tx).tx_dropped, 0u);
}

TEST_F(channel_backlog, a_frame_refused_for_good_is_dropped_and_the_rest_still_leave) {
  auto sent = fill_backlog(60);
  gate->refuse_nth = 10;
  gate->closed = false;
  auto got = received(sent.size());
  // One frame is lost (and with it one packet, or the packets of one
  // bundle); everything else arrives intact and in order.
  ASSERT_GE(got.size(), sent.size() - 8);
  ASSERT_LT(got.size(), sent.size());
  uint16_t last = 0;
  for (size_t i = 0; i < got.size(); ++i) {
    auto seq = seq_of(got[i]);
    ASSERT_LT(seq, sent.size());
    EXPECT_EQ(got[i], sent[seq]);
    if (i > 0) {
      EXPECT_GT(seq, last);
    }
    last = seq;
  }
  EXPECT_EQ(seq_of(got.back()), sent.size() - 1) << "the frames after it left";
  auto st = stats(tx);
  EXPECT_EQ(st.tx_dropped, 1u);
  EXPECT_EQ(st.backlog_bytes, 0u);
}

} // namespace
} // namespace herm
