// Deterministic actor tests of the Network Interface Layer: the IO manager,
// devices and channels over the in-process link, driven by CAF's
// test_coordinator.

#include <numeric>

#include "tests/support/actor_fixture.hpp"
#include "tests/support/null_frame_handler.hpp"

#include "channels/channel.hpp"
#include "channels/drivers/inproc.hpp"
#include "channels/fragmentation.hpp"
#include "channels/io_manager.hpp"
#include "channels/link_driver.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

/// A unique segment name per test so that tests never share a medium.
std::string segment_name() {
  auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::string{"seg-"} + info->name();
}

byte_buffer pattern(size_t n, uint8_t seed = 0) {
  byte_buffer buf(n);
  for (size_t i = 0; i < n; ++i)
    buf[i] = static_cast<uint8_t>(seed + i * 7 + i / 251);
  return buf;
}

class nil_test : public test::actor_fixture {
public:
  /// One module: an IO manager with one inproc device on the test's segment.
  struct module {
    io_manager_actor io;
    channel_actor ch;
    channel_info info;
  };

  module make_module(uint16_t station, std::string profile = "ethernet",
                     bool persistent = false) {
    module m;
    m.io = track(spawn_io_manager(sys()));
    device_config cfg{"lan", "inproc", segment_name(),
                      {{"station", std::to_string(station)},
                       {"profile", profile}}};
    auto added = call<device_info>(m.io, atom::add_v, cfg);
    EXPECT_TRUE(added) << render(added.error());
    channel_request req{"lan", "*", persistent};
    auto opened = call<channel_actor, channel_info>(m.io, atom::open_v, req);
    EXPECT_TRUE(opened) << render(opened.error());
    if (opened) {
      m.ch = std::get<0>(*opened);
      m.info = std::get<1>(*opened);
    }
    return m;
  }

  void subscribe(const channel_actor& ch, const test::probe_actor& probe) {
    auto res = call<channel_info>(ch, atom::subscribe_v,
                                  caf::actor_cast<channel_reader_actor>(probe));
    ASSERT_TRUE(res) << render(res.error());
  }

  channel_stats stats(const channel_actor& ch) {
    auto res = call<channel_stats>(ch, atom::get_v, atom::stats_v);
    EXPECT_TRUE(res);
    return res ? std::get<0>(*res) : channel_stats{};
  }

  /// A raw station on the segment that bypasses channels, to inject frames.
  link_driver_ptr raw_station(uint16_t station, std::string profile) {
    device_config cfg{"raw", "inproc", segment_name(),
                      {{"station", std::to_string(station)},
                       {"profile", profile}}};
    auto drv = find_link_kind("inproc")->open(cfg);
    EXPECT_TRUE(drv);
    (*drv)->start(std::make_shared<test::null_frame_handler>());
    return *drv;
  }
};

} // namespace

TEST_F(nil_test, delivers_a_packet_between_two_modules) {
  auto a = make_module(1);
  auto b = make_module(2);
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  caf::anon_send(a.ch, write_packet{2, prio_normal, pattern(100)});
  run();
  ASSERT_EQ(log->packets.size(), 1u);
  EXPECT_EQ(log->packets[0].bytes, pattern(100));
  EXPECT_EQ(log->packets[0].src, 1u);
  EXPECT_EQ(log->packets[0].channel, b.info.id);
  auto st = stats(a.ch);
  EXPECT_EQ(st.tx_packets, 1u);
  EXPECT_EQ(st.tx_bytes, 100u);
  EXPECT_EQ(st.tx_frames, 1u);
}

TEST_F(nil_test, broadcast_reaches_every_other_station_but_not_the_sender) {
  auto a = make_module(1);
  auto b = make_module(2);
  auto c = make_module(3);
  auto [pa, la] = spawn_probe();
  auto [pb, lb] = spawn_probe();
  auto [pc, lc] = spawn_probe();
  subscribe(a.ch, pa);
  subscribe(b.ch, pb);
  subscribe(c.ch, pc);
  caf::anon_send(a.ch, write_packet{broadcast_addr, prio_normal, pattern(10)});
  run();
  EXPECT_EQ(la->packets.size(), 0u);
  EXPECT_EQ(lb->packets.size(), 1u);
  EXPECT_EQ(lc->packets.size(), 1u);
}

TEST_F(nil_test, fragments_and_reassembles_large_packets_on_an_8_byte_link) {
  auto a = make_module(1, "can2.0");
  auto b = make_module(2, "can2.0");
  EXPECT_EQ(a.info.profile.mtu, 8u);
  EXPECT_GT(a.info.max_packet, 60'000u);
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  for (size_t size : {0, 1, 7, 8, 100, 5000, 65536})
    caf::anon_send(a.ch, write_packet{2, prio_normal, pattern(size, 3)});
  run();
  ASSERT_EQ(log->packets.size(), 7u);
  size_t i = 0;
  for (size_t size : {0, 1, 7, 8, 100, 5000, 65536})
    EXPECT_EQ(log->packets[i++].bytes, pattern(size, 3)) << "size " << size;
  fragmenter f{8};
  size_t frames = 0;
  for (size_t size : {0, 1, 7, 8, 100, 5000, 65536})
    frames += f.frames_for(size);
  EXPECT_EQ(stats(a.ch).tx_frames, frames);
  EXPECT_EQ(stats(b.ch).rx_frames, frames);
}

TEST_F(nil_test, reports_the_link_profile_and_the_peers_it_heard) {
  auto a = make_module(1, "ieee1394a");
  auto b = make_module(2, "ieee1394a");
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  caf::anon_send(a.ch, write_packet{2, prio_normal, pattern(5)});
  run();
  auto info = call<channel_info>(b.ch, atom::get_v, atom::info_v);
  ASSERT_TRUE(info);
  auto& ci = std::get<0>(*info);
  EXPECT_EQ(ci.profile.name, "ieee1394a");
  EXPECT_EQ(ci.profile.bandwidth_bps, 400'000'000u);
  EXPECT_EQ(link_cost(ci.profile), 4u);
  EXPECT_TRUE(ci.profile.multi_access);
  EXPECT_EQ(ci.local, "2");
  EXPECT_EQ(ci.peers, std::vector<std::string>{"1"});
  ASSERT_EQ(log->events.size(), 1u);
  EXPECT_EQ(log->events[0].kind, uint8_t(link_event_kind::peer_heard));
  EXPECT_EQ(log->events[0].peer, 1u);
}

TEST_F(nil_test, control_reads_parameters_and_refuses_impossible_ones) {
  auto a = make_module(1, "can2.0");
  auto bw = call<std::string>(a.ch, atom::get_v, std::string{"bandwidth"});
  ASSERT_TRUE(bw);
  EXPECT_EQ(std::get<0>(*bw), "1000000");
  auto bad = call<std::string>(a.ch, atom::get_v, std::string{"colour"});
  ASSERT_FALSE(bad);
  EXPECT_TRUE(is(bad.error(), ec::invalid_parameter));
  EXPECT_NE(render(bad.error()).find("colour"), std::string::npos);
  auto mtu = call<channel_info>(a.ch, atom::set_v, std::string{"mtu"},
                                std::string{"4"});
  ASSERT_FALSE(mtu);
  EXPECT_TRUE(is(mtu.error(), ec::invalid_parameter));
}

TEST_F(nil_test, unknown_device_kind_address_and_option_are_typed_errors) {
  auto io = track(spawn_io_manager(sys()));
  auto r1 = call<channel_actor, channel_info>(io, atom::open_v,
                                              channel_request{"nope", "*"});
  ASSERT_FALSE(r1);
  EXPECT_TRUE(is(r1.error(), ec::unknown_device));
  EXPECT_NE(render(r1.error()).find("nope"), std::string::npos);
  auto r2 = call<device_info>(io, atom::add_v,
                              device_config{"x", "token-ring", "", {}});
  ASSERT_FALSE(r2);
  EXPECT_TRUE(is(r2.error(), ec::unknown_link_kind));
  EXPECT_NE(render(r2.error()).find("token-ring"), std::string::npos);
  auto r3 = call<device_info>(io, atom::add_v,
                              device_config{"y", "inproc", segment_name(),
                                            {{"statoin", "3"}}});
  ASSERT_FALSE(r3);
  EXPECT_TRUE(is(r3.error(), ec::invalid_parameter));
  EXPECT_NE(render(r3.error()).find("statoin"), std::string::npos);
  auto r4 = call<device_info>(io, atom::add_v,
                              device_config{"z", "inproc", segment_name(), {}});
  ASSERT_TRUE(r4);
  auto r5 = call<channel_actor, channel_info>(io, atom::open_v,
                                              channel_request{"z", "not-a-station"});
  ASSERT_FALSE(r5);
  EXPECT_TRUE(is(r5.error(), ec::invalid_address));
  EXPECT_NE(render(r5.error()).find("not-a-station"), std::string::npos);
  auto r6 = call<device_info>(io, atom::add_v,
                              device_config{"z", "inproc", segment_name(), {}});
  ASSERT_FALSE(r6);
  EXPECT_TRUE(is(r6.error(), ec::already_exists));
}

TEST_F(nil_test, point_to_point_channels_hear_only_their_peer) {
  auto a = make_module(1);
  auto c = make_module(3);
  // Module b: one channel for peer 1, one for everybody else.
  auto io = track(spawn_io_manager(sys()));
  ASSERT_TRUE((call<device_info>(io, atom::add_v,
                                 device_config{"lan", "inproc", segment_name(),
                                               {{"station", "2"}}})));
  auto p2p = call<channel_actor, channel_info>(io, atom::open_v,
                                               channel_request{"lan", "1"});
  auto rest = call<channel_actor, channel_info>(io, atom::open_v,
                                                channel_request{"lan", "*"});
  ASSERT_TRUE(p2p && rest);
  auto dup = call<channel_actor, channel_info>(io, atom::open_v,
                                               channel_request{"lan", "1"});
  ASSERT_FALSE(dup);
  EXPECT_TRUE(is(dup.error(), ec::already_exists));
  auto [pp, lp] = spawn_probe();
  auto [pr, lr] = spawn_probe();
  subscribe(std::get<0>(*p2p), pp);
  subscribe(std::get<0>(*rest), pr);
  caf::anon_send(a.ch, write_packet{2, prio_normal, pattern(3, 1)});
  caf::anon_send(c.ch, write_packet{2, prio_normal, pattern(3, 9)});
  run();
  ASSERT_EQ(lp->packets.size(), 1u);
  EXPECT_EQ(lp->packets[0].src, 1u);
  ASSERT_EQ(lr->packets.size(), 1u);
  EXPECT_EQ(lr->packets[0].src, 3u);
  // Writes on a point-to-point channel go to its peer whatever dst says.
  auto [pa, la] = spawn_probe();
  subscribe(a.ch, pa);
  caf::anon_send(std::get<0>(*p2p), write_packet{broadcast_addr, prio_normal, pattern(4)});
  run();
  EXPECT_EQ(la->packets.size(), 1u);
}

TEST_F(nil_test, malformed_frames_are_counted_and_the_channel_keeps_working) {
  auto b = make_module(2, "can2.0");
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  auto raw = raw_station(7, "can2.0");
  // A "single" header with reserved bits set, an empty frame, and a first
  // fragment announcing far more than the maximum packet.
  const uint8_t reserved[] = {0x0F, 1, 2};
  const uint8_t huge[] = {0x40, 0xFF, 0xFF, 0x7F, 1, 2, 3, 4};
  raw->send(2, reserved, sizeof(reserved), prio_normal);
  raw->send(2, nullptr, 0, prio_normal);
  raw->send(2, huge, sizeof(huge), prio_normal);
  run();
  EXPECT_EQ(log->packets.size(), 0u);
  auto st = stats(b.ch);
  EXPECT_EQ(st.rx_frames, 3u);
  EXPECT_GE(st.rx_malformed + st.rx_reassembly_dropped, 3u);
  // A valid single frame still gets through.
  const uint8_t good[] = {0x00, 'o', 'k'};
  raw->send(2, good, sizeof(good), prio_normal);
  run();
  ASSERT_EQ(log->packets.size(), 1u);
  EXPECT_EQ(log->packets[0].bytes, (byte_buffer{'o', 'k'}));
}

TEST_F(nil_test, an_incomplete_packet_is_dropped_after_the_reassembly_timeout) {
  auto b = make_module(2, "can2.0");
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  auto raw = raw_station(7, "can2.0");
  // The first two frames of a 100-byte packet, then nothing.
  fragmenter f{8};
  auto payload = pattern(100);
  std::vector<byte_buffer> frames;
  f.split(payload.data(), payload.size(), [&](const uint8_t* p, size_t n) {
    frames.emplace_back(p, p + n);
  });
  ASSERT_GT(frames.size(), 2u);
  raw->send(2, frames[0].data(), frames[0].size(), prio_normal);
  raw->send(2, frames[1].data(), frames[1].size(), prio_normal);
  run();
  EXPECT_EQ(stats(b.ch).rx_reassembly_dropped, 0u);
  advance(reassembly_limits{}.timeout + 100ms);
  EXPECT_EQ(stats(b.ch).rx_reassembly_dropped, 1u);
  EXPECT_EQ(log->packets.size(), 0u);
}

TEST_F(nil_test, oversized_writes_are_dropped_and_counted) {
  auto a = make_module(1, "can2.0");
  caf::anon_send(a.ch, write_packet{2, prio_normal, byte_buffer(a.info.max_packet + 1)});
  run();
  auto st = stats(a.ch);
  EXPECT_EQ(st.tx_dropped, 1u);
  EXPECT_EQ(st.tx_packets, 0u);
}

TEST_F(nil_test, device_failure_ends_the_channel_and_tells_subscribers_and_listeners) {
  auto a = make_module(1);
  auto [probe, log] = spawn_probe();
  subscribe(a.ch, probe);
  caf::anon_send(a.io, atom::subscribe_v, caf::actor_cast<io_listener_actor>(probe));
  run();
  ASSERT_EQ(log->ups.size(), 1u);
  inproc::unplug(segment_name(), make_error(ec::device_failed, "cable pulled"));
  run();
  // The subscriber got a down message without monitoring the channel itself.
  ASSERT_EQ(log->monitor_downs.size(), 1u);
  EXPECT_TRUE(is(log->monitor_downs[0].reason, ec::device_failed));
  EXPECT_NE(render(log->monitor_downs[0].reason).find("cable pulled"),
            std::string::npos);
  ASSERT_EQ(log->downs.size(), 1u);
  EXPECT_EQ(log->downs[0].id, a.info.id);
  EXPECT_FALSE(log->downs[0].will_retry);
  auto table = call<std::vector<channel_entry>>(a.io, atom::get_v, atom::channels_v);
  ASSERT_TRUE(table);
  EXPECT_TRUE(std::get<0>(*table).empty());
  inproc::replug(segment_name());
}

TEST_F(nil_test, persistent_channels_come_back_with_backoff_when_the_device_returns) {
  auto a = make_module(1, "ethernet", true);
  auto b = make_module(2);
  auto [probe, log] = spawn_probe();
  caf::anon_send(a.io, atom::subscribe_v, caf::actor_cast<io_listener_actor>(probe));
  run();
  inproc::unplug(segment_name(), make_error(ec::device_failed, "cable pulled"));
  run();
  ASSERT_EQ(log->downs.size(), 1u);
  EXPECT_TRUE(log->downs[0].will_retry);
  auto table = call<std::vector<channel_entry>>(a.io, atom::get_v, atom::channels_v);
  ASSERT_TRUE(table);
  ASSERT_EQ(std::get<0>(*table).size(), 1u);
  EXPECT_EQ(std::get<0>(*table)[0].state, "retrying");
  EXPECT_NE(std::get<0>(*table)[0].last_error.find("cable pulled"), std::string::npos);
  // Still unplugged: the first retries fail, each waiting twice as long.
  advance(100ms);
  advance(200ms);
  EXPECT_EQ(log->ups.size(), 1u);
  inproc::replug(segment_name());
  // Module b's station also went down with the segment; bring b back too.
  auto b2 = make_module(2);
  // Next retry after 400 ms.
  advance(399ms);
  EXPECT_EQ(log->ups.size(), 1u);
  advance(2ms);
  ASSERT_EQ(log->ups.size(), 2u);
  EXPECT_EQ(log->ups[1].info.id, a.info.id);
  auto fresh = log->ups[1].handle;
  auto [pb, lb] = spawn_probe();
  subscribe(b2.ch, pb);
  caf::anon_send(fresh, write_packet{2, prio_normal, pattern(42)});
  run();
  ASSERT_EQ(lb->packets.size(), 1u);
  table = call<std::vector<channel_entry>>(a.io, atom::get_v, atom::channels_v);
  ASSERT_TRUE(table);
  EXPECT_EQ(std::get<0>(*table)[0].state, "up");
  EXPECT_EQ(std::get<0>(*table)[0].restarts, 1u);
}

TEST_F(nil_test, closing_a_channel_ends_it_and_removes_it_from_the_table) {
  auto a = make_module(1);
  auto [probe, log] = spawn_probe();
  subscribe(a.ch, probe);
  auto res = call<>(a.io, atom::close_v, a.info.id);
  ASSERT_TRUE(res) << render(res.error());
  ASSERT_EQ(log->monitor_downs.size(), 1u);
  EXPECT_TRUE(is(log->monitor_downs[0].reason, ec::channel_closed));
  auto table = call<std::vector<channel_entry>>(a.io, atom::get_v, atom::channels_v);
  ASSERT_TRUE(table);
  EXPECT_TRUE(std::get<0>(*table).empty());
  auto again = call<>(a.io, atom::close_v, a.info.id);
  ASSERT_FALSE(again);
  EXPECT_TRUE(is(again.error(), ec::unknown_channel));
}

TEST_F(nil_test, a_subscriber_that_exits_is_forgotten) {
  auto a = make_module(1);
  auto b = make_module(2);
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  caf::anon_send_exit(probe, caf::exit_reason::user_shutdown);
  run();
  caf::anon_send(a.ch, write_packet{2, prio_normal, pattern(8)});
  run();
  auto st = stats(b.ch);
  EXPECT_EQ(st.rx_packets, 1u);
}

TEST_F(nil_test, removing_a_device_closes_its_channels_and_frees_its_name) {
  auto a = make_module(1, "ethernet", true);
  auto [probe, log] = spawn_probe();
  subscribe(a.ch, probe);
  auto res = call<>(a.io, atom::close_v, std::string{"lan"});
  ASSERT_TRUE(res) << render(res.error());
  ASSERT_EQ(log->monitor_downs.size(), 1u);
  EXPECT_TRUE(is(log->monitor_downs[0].reason, ec::channel_closed));
  auto table = call<std::vector<channel_entry>>(a.io, atom::get_v, atom::channels_v);
  ASSERT_TRUE(table);
  EXPECT_TRUE(std::get<0>(*table).empty()) << "a persistent channel came back";
  auto devices = call<std::vector<device_info>>(a.io, atom::get_v, atom::devices_v);
  ASSERT_TRUE(devices);
  EXPECT_TRUE(std::get<0>(*devices).empty());
  // The name is free: the same device can be added again, with new options.
  device_config cfg{"lan", "inproc", segment_name(),
                    {{"station", "1"}, {"profile", "can2.0"}}};
  auto added = call<device_info>(a.io, atom::add_v, cfg);
  ASSERT_TRUE(added) << render(added.error());
  auto opened = call<channel_actor, channel_info>(a.io, atom::open_v,
                                                  channel_request{"lan", "*", true});
  ASSERT_TRUE(opened) << render(opened.error());
  EXPECT_EQ(std::get<1>(*opened).profile.mtu, 8u);
  auto again = call<>(a.io, atom::close_v, std::string{"nope"});
  ASSERT_FALSE(again);
  EXPECT_TRUE(is(again.error(), ec::unknown_device));
}

// An APO's own channel (a sensor line) works like any other, but listeners
// (the routing agent) never hear of it.
TEST_F(nil_test, a_local_channel_is_not_announced_to_listeners) {
  auto a = make_module(1);
  auto b = make_module(2);
  auto [probe, log] = spawn_probe();
  caf::anon_send(a.io, atom::subscribe_v, caf::actor_cast<io_listener_actor>(probe));
  run();
  ASSERT_EQ(log->ups.size(), 1u); // the ordinary channel
  device_config sensor{"sensor", "inproc", segment_name(),
                       {{"station", "3"}, {"profile", "rs232c"}}};
  ASSERT_TRUE(call<device_info>(a.io, atom::add_v, sensor));
  auto opened = call<channel_actor, channel_info>(
    a.io, atom::open_v, channel_request{"sensor", "*", false, true});
  ASSERT_TRUE(opened) << render(opened.error());
  run();
  EXPECT_EQ(log->ups.size(), 1u);
  auto [reader, rlog] = spawn_probe();
  subscribe(std::get<0>(*opened), reader);
  caf::anon_send(b.ch, write_packet{broadcast_addr, prio_normal, {1, 2, 3}});
  run();
  EXPECT_FALSE(rlog->packets.empty()) << "the local channel hears the link";
  auto closed = call<>(a.io, atom::close_v, std::get<1>(*opened).id);
  ASSERT_TRUE(closed);
  run();
  EXPECT_TRUE(log->downs.empty());
}

// -- bounds on what the network can make a channel hold ----------------------------

// The driver hands frames to the channel from its own thread; a flood faster
// than the channel (here: the channel does not run at all until run())
// meets the inbound queue's bound, and the excess is dropped and counted.
TEST_F(nil_test, a_flood_faster_than_the_channel_stops_at_its_inbound_queue_bound_and_is_counted) {
  auto b = make_module(2);
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  auto raw = raw_station(7, "ethernet");
  byte_buffer frame{0x00}; // a single-frame packet
  auto body = pattern(1399);
  frame.insert(frame.end(), body.begin(), body.end());
  auto fits = default_rx_queue_bytes / (frame.size() + rx_queue_frame_overhead);
  const size_t excess = 100;
  for (size_t i = 0; i < fits + excess; ++i)
    ASSERT_FALSE(raw->send(2, frame.data(), frame.size(), prio_normal));
  run();
  auto st = stats(b.ch);
  EXPECT_EQ(st.rx_frames, fits);
  EXPECT_EQ(st.rx_queue_dropped, excess);
  EXPECT_EQ(log->packets.size(), fits);
  // Processed frames are credited back: the queue takes frames again.
  ASSERT_FALSE(raw->send(2, frame.data(), frame.size(), prio_normal));
  run();
  st = stats(b.ch);
  EXPECT_EQ(st.rx_frames, fits + 1);
  EXPECT_EQ(st.rx_queue_dropped, excess);
  EXPECT_EQ(log->packets.size(), fits + 1);
}

// A channel remembers at most 1024 peers (channel_info::peers, peer_heard
// events); frames of further peers are still delivered, and counted.
TEST_F(nil_test, frames_from_more_peers_than_a_channel_remembers_are_delivered_and_counted) {
  auto b = make_module(2);
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  const size_t remembered = 1024;
  const size_t extra = 6;
  const uint8_t single[] = {0x00, 'h', 'i'};
  for (size_t i = 0; i < remembered + extra; ++i) {
    auto raw = raw_station(static_cast<uint16_t>(10 + i), "ethernet");
    ASSERT_FALSE(raw->send(2, single, sizeof(single), prio_normal));
    raw->stop();
    run();
  }
  auto st = stats(b.ch);
  EXPECT_EQ(st.rx_packets, remembered + extra);
  EXPECT_EQ(st.rx_peers_unrecorded, extra);
  size_t heard = 0;
  for (auto& ev : log->events)
    heard += ev.kind == static_cast<uint8_t>(link_event_kind::peer_heard);
  EXPECT_EQ(heard, remembered);
  auto info = call<channel_info>(b.ch, atom::get_v, atom::info_v);
  ASSERT_TRUE(info);
  EXPECT_EQ(std::get<0>(*info).peers.size(), remembered);
}

// Orphans (a consecutive fragment whose first never came) and duplicates
// (a fragment the packet already has) are counted each under its own name.
TEST_F(nil_test, orphan_and_duplicate_fragments_are_counted_apart) {
  auto b = make_module(2, "can2.0");
  auto [probe, log] = spawn_probe();
  subscribe(b.ch, probe);
  auto raw = raw_station(7, "can2.0");
  fragmenter f{8};
  auto payload = pattern(40);
  std::vector<byte_buffer> frames;
  f.split(payload.data(), payload.size(), [&](const uint8_t* p, size_t n) {
    frames.emplace_back(p, p + n);
  });
  ASSERT_GT(frames.size(), 3u);
  // An orphan: the second fragment alone, held until the timeout.
  raw->send(2, frames[1].data(), frames[1].size(), prio_normal);
  run();
  advance(reassembly_limits{}.timeout + 100ms);
  auto st = stats(b.ch);
  EXPECT_EQ(st.rx_orphans, 1u);
  EXPECT_EQ(st.rx_duplicates, 0u);
  // A duplicate: the next packet's first fragment twice.
  f.split(payload.data(), payload.size(), [&](const uint8_t* p, size_t n) {
    frames.emplace_back(p, p + n);
  });
  auto second = frames.size() / 2;
  raw->send(2, frames[second].data(), frames[second].size(), prio_normal);
  raw->send(2, frames[second].data(), frames[second].size(), prio_normal);
  for (auto i = second + 1; i < frames.size(); ++i)
    raw->send(2, frames[i].data(), frames[i].size(), prio_normal);
  run();
  st = stats(b.ch);
  EXPECT_EQ(st.rx_duplicates, 1u);
  EXPECT_EQ(st.rx_orphans, 1u);
  ASSERT_EQ(log->packets.size(), 1u);
  EXPECT_EQ(log->packets[0].bytes, payload);
}
