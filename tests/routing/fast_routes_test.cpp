// The data path of established routes (routing/fast_routes.hpp): what the
// routing agent publishes, when, that a packet put on a published next hop
// takes the selected route, and which received packets skip the agent.
// Deterministic (test coordinator).

#include <gtest/gtest.h>

#include <functional>

#include "tests/support/actor_fixture.hpp"
#include "tests/support/topology.hpp"
#include "actors/testing/sim_network.hpp"
#include "routing/fast_routes.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

class fast_routes_test : public actor_fixture {
public:
  /// The network `t`, started after `edit` changed its configurations.
  sim_network build(const topology& t, std::function<void(sim_network&)> edit) {
    sim_network net{*this, test_prefix() + "-" + std::to_string(++nets_)};
    for (size_t i = 0; i < t.n; ++i)
      net.add_module(id_of(i));
    for (auto& [members, kind] : t.links)
      net.connect(members, kind);
    edit(net);
    net.start();
    return net;
  }

  /// Module 0 publishes into `cell` and has no observer (the others keep
  /// theirs, so paths are recorded from the first hop on).
  static std::function<void(sim_network&)>
  publishing(std::shared_ptr<route_cell> cell) {
    return [cell](sim_network& net) {
      net.at(0).cfg.observer = nullptr;
      net.at(0).cfg.fast_routes = cell;
    };
  }

  /// A ring of six Ethernet links, routes converged, module 0 publishing.
  sim_network ring6(std::shared_ptr<route_cell> cell) {
    auto net = build(ring(6, false), publishing(std::move(cell)));
    net.advance(1s);
    return net;
  }

  /// Puts a tagged protocol-0 packet for `dst` on the next hop `snap`
  /// publishes, as application support does; returns the tag.
  uint64_t send_on(sim_network& net, const route_snapshot& snap,
                   module_id dst) {
    auto* hop = snap.lookup(dst, 0);
    EXPECT_NE(hop, nullptr);
    if (hop == nullptr)
      return 0;
    auto tag = next_tag_++;
    data_header h;
    h.src = snap.self;
    h.dst = dst;
    h.protocol = 0;
    byte_buffer bytes;
    encode(h, bytes);
    for (int i = 0; i < 8; ++i)
      bytes.push_back(static_cast<uint8_t>(tag >> (8 * i)));
    caf::anon_send(hop->channel, write_packet{hop->neighbour, prio_normal,
                                              std::move(bytes)});
    net.run();
    return tag;
  }

private:
  uint64_t next_tag_ = uint64_t{1} << 40;
  int nets_ = 0;
};

} // namespace

TEST_F(fast_routes_test, no_route_is_published_before_the_module_sends) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  // Only its receiver (the network's protocol-0 log), for packets coming in.
  auto snap = cell->get();
  ASSERT_NE(snap, nullptr);
  EXPECT_TRUE(snap->routes.empty());
  EXPECT_EQ(snap->receivers.size(), 1u);
  EXPECT_EQ(snap->receivers.count(0), 1u);
}

TEST_F(fast_routes_test, a_packet_for_the_module_goes_from_its_channel_to_the_receiver) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  auto before = net.stats(0);
  // 2 -> 0 goes 2-1-0; module 0's channel hands it to the receiver.
  auto tag = net.send(2, id_of(0), 40);
  // (Module 0 has no observer: the path shows the others.)
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(2), id_of(1)}));
  ASSERT_EQ(net.at(0).received->size(), 1u);
  auto& got = net.at(0).received->back();
  EXPECT_EQ(got.src, id_of(2));
  EXPECT_EQ(got.protocol, 0);
  EXPECT_EQ(got.hops, 2);
  EXPECT_FALSE(got.authenticated);
  ASSERT_EQ(got.payload.size(), 40u); // the routing header cut off
  uint64_t seen = 0;
  for (int i = 0; i < 8; ++i)
    seen |= uint64_t{got.payload[i]} << (8 * i);
  EXPECT_EQ(seen, tag);
  auto after = net.stats(0);
  EXPECT_EQ(after.fast_delivered, before.fast_delivered + 1);
  EXPECT_EQ(after.delivered, before.delivered + 1);
}

TEST_F(fast_routes_test, a_channel_with_a_second_reader_gives_every_packet_to_its_readers) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  // A capture: a second reader on each of module 0's channels.
  auto seen = std::make_shared<size_t>(0);
  auto capture = sys().spawn(
    [seen](channel_reader_actor::pointer) -> channel_reader_actor::behavior_type {
      return {[seen](packet_received&) { ++*seen; }, [](link_event&) {}};
    });
  size_t subscribed = 0;
  for (channel_id id = 1; id <= 2; ++id)
    if (auto ch = call<channel_actor>(net.at(0).io, atom::get_v, id))
      if (call<channel_info>(std::get<0>(*ch), atom::subscribe_v, capture))
        ++subscribed;
  ASSERT_EQ(subscribed, 2u);
  auto before = net.stats(0);
  net.send(2, id_of(0));
  EXPECT_EQ(net.at(0).received->size(), 1u);
  EXPECT_GE(*seen, 1u);
  auto after = net.stats(0);
  EXPECT_EQ(after.fast_delivered, before.fast_delivered);
  EXPECT_EQ(after.delivered, before.delivered + 1);
  caf::anon_send_exit(capture, caf::exit_reason::user_shutdown);
}

TEST_F(fast_routes_test, broadcasts_unknown_protocols_and_a_first_packet_for_another_module_stay_with_the_agent) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  auto before = net.stats(0);
  // A flooded broadcast: duplicate suppression and relaying are the agent's.
  net.send(3, broadcast_module);
  EXPECT_EQ(net.at(0).received->size(), 1u);
  // 1 -> 5 is forwarded by 0 (1-0-5); no route to 5 is published before.
  auto tag = net.send(1, id_of(5));
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(1), id_of(5)}));
  // A protocol nobody receives: the agent drops and counts it.
  caf::anon_send(net.at(2).agent,
                 send_packet{id_of(0), 7, prio_normal, byte_buffer(8, 1)});
  net.run();
  auto after = net.stats(0);
  EXPECT_EQ(after.fast_delivered, before.fast_delivered);
  EXPECT_EQ(after.forwarded, before.forwarded + 1);
  EXPECT_EQ(after.fast_forwarded, before.fast_forwarded);
  EXPECT_EQ(after.dropped_no_receiver, before.dropped_no_receiver + 1);
  EXPECT_EQ(net.at(0).received->size(), 1u);
}

TEST_F(fast_routes_test, once_forwarded_a_packet_for_another_module_goes_from_channel_to_channel) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  // 1 -> 5 goes 1-0-5: the first through module 0's agent, which then
  // publishes its next hop to 5.
  net.send(1, id_of(5));
  auto snap = cell->get();
  ASSERT_NE(snap, nullptr);
  ASSERT_NE(snap->lookup(id_of(5), 0), nullptr);
  auto before = net.stats(0);
  auto tag = net.send(1, id_of(5), 40);
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(1), id_of(5)}));
  auto after = net.stats(0);
  EXPECT_EQ(after.fast_forwarded, before.fast_forwarded + 1);
  EXPECT_EQ(after.forwarded, before.forwarded + 1);
  // As the agent forwards it: one hop limit less, payload untouched.
  ASSERT_EQ(net.at(5).received->size(), 2u);
  auto& got = net.at(5).received->back();
  EXPECT_EQ(got.src, id_of(1));
  EXPECT_EQ(got.hops, 2);
  ASSERT_EQ(got.payload.size(), 40u);
  uint64_t seen = 0;
  for (int i = 0; i < 8; ++i)
    seen |= uint64_t{got.payload[i]} << (8 * i);
  EXPECT_EQ(seen, tag);
}

TEST_F(fast_routes_test, a_packet_whose_hop_limit_ends_here_or_without_a_published_hop_stays_with_the_agent) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  net.send(1, id_of(5));
  ASSERT_NE(cell->get(), nullptr);
  fast_receiver tap{cell};
  auto packet_for = [](module_id dst, uint8_t hop_limit) {
    data_header h;
    h.src = id_of(1);
    h.dst = dst;
    h.hop_limit = hop_limit;
    byte_buffer bytes;
    encode(h, bytes);
    bytes.resize(bytes.size() + 8, 7);
    return bytes;
  };
  // Left to the agent (which drops it and counts dropped_hop_limit).
  auto last_hop = packet_for(id_of(5), 1);
  auto copy = last_hop;
  EXPECT_FALSE(tap.take(1, 0, last_hop));
  EXPECT_EQ(last_hop, copy);
  // No route to 4 published: the agent looks it up.
  auto unknown = packet_for(id_of(4), 5);
  copy = unknown;
  EXPECT_FALSE(tap.take(1, 0, unknown));
  EXPECT_EQ(unknown, copy);
  EXPECT_EQ(net.stats(0).fast_forwarded, 0u);
  // With a hop limit left it is taken, one hop limit less, and arrives.
  auto taken = packet_for(id_of(5), 2);
  EXPECT_TRUE(tap.take(1, 0, taken));
  net.run();
  EXPECT_EQ(net.stats(0).fast_forwarded, 1u);
  ASSERT_EQ(net.at(5).received->size(), 2u);
  EXPECT_EQ(net.at(5).received->back().hops, default_hop_limit);
}

TEST_F(fast_routes_test, a_destination_sent_to_is_published_with_its_selected_next_hop) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  net.send(0, id_of(2));
  auto snap = cell->get();
  ASSERT_NE(snap, nullptr);
  EXPECT_EQ(snap->self, id_of(0));
  EXPECT_EQ(snap->routes.size(), 1u);
  EXPECT_EQ(snap->lookup(id_of(3), 0), nullptr);
  for (uint8_t k = 0; k < size_classes; ++k)
    EXPECT_NE(snap->lookup(id_of(2), k), nullptr) << "class " << int{k};
  // 0 -> 2 goes 0-1-2: the packet put on the published hop arrives at 1
  // and is forwarded to 2.
  auto tag = send_on(net, *snap, id_of(2));
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(1), id_of(2)}));
  EXPECT_EQ(net.at(2).received->size(), 2u);
}

TEST_F(fast_routes_test, the_snapshot_follows_a_route_change_at_once) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  net.send(0, id_of(2));
  auto before = cell->get();
  ASSERT_NE(before, nullptr);
  net.cut(0); // link 0-1
  net.advance(200ms);
  auto after = cell->get();
  ASSERT_NE(after, nullptr);
  EXPECT_NE(after, before);
  auto tag = send_on(net, *after, id_of(2));
  EXPECT_EQ(net.path(tag), (std::vector<module_id>{id_of(5), id_of(4),
                                                   id_of(3), id_of(2)}));
  // A published snapshot never changes: the old one still names link 0-1.
  EXPECT_NE(before->lookup(id_of(2), 0)->channel,
            after->lookup(id_of(2), 0)->channel);
}

TEST_F(fast_routes_test, an_unreachable_destination_leaves_the_snapshot_and_gives_its_place_back) {
  auto cell = std::make_shared<route_cell>(1);
  auto net = build(line(3, false), publishing(cell));
  net.advance(1s);
  net.send(0, id_of(2));
  ASSERT_NE(cell->get(), nullptr);
  ASSERT_NE(cell->get()->lookup(id_of(2), 0), nullptr);
  net.kill(2);
  net.advance(5s);
  ASSERT_FALSE(net.route(0, id_of(2)));
  auto snap = cell->get();
  ASSERT_NE(snap, nullptr);
  EXPECT_EQ(snap->lookup(id_of(2), 0), nullptr);
  // Room for one destination: 2's place is free again once the table
  // forgets it (its retracted routes expire).
  net.advance(60s);
  net.send(0, id_of(1));
  ASSERT_NE(cell->get(), nullptr);
  EXPECT_NE(cell->get()->lookup(id_of(1), 0), nullptr);
  EXPECT_EQ(net.stats(0).fast_routes_refused, 0u);
}

TEST_F(fast_routes_test, destinations_past_the_bound_are_refused_and_counted) {
  auto cell = std::make_shared<route_cell>(2);
  auto net = ring6(cell);
  for (size_t i = 1; i <= 4; ++i)
    net.send(0, id_of(i));
  net.send(0, id_of(4));
  auto snap = cell->get();
  ASSERT_NE(snap, nullptr);
  EXPECT_EQ(snap->routes.size(), 2u);
  EXPECT_NE(snap->lookup(id_of(1), 0), nullptr);
  EXPECT_NE(snap->lookup(id_of(2), 0), nullptr);
  // 3 once, 4 twice: every packet sent through the agent for want of room.
  EXPECT_EQ(net.stats(0).fast_routes_refused, 3u);
}

TEST_F(fast_routes_test, destinations_forwarded_to_past_the_bound_are_refused_and_counted) {
  // 0-1-2-3, module 1 publishing room for one destination: it forwards
  // 0's packets for 2 and for 3.
  auto cell = std::make_shared<route_cell>(1);
  auto net = build(line(4, false), [cell](sim_network& n) {
    n.at(1).cfg.observer = nullptr;
    n.at(1).cfg.fast_routes = cell;
  });
  net.advance(1s);
  net.send(0, id_of(2));
  net.send(0, id_of(3));
  net.send(0, id_of(3));
  auto snap = cell->get();
  ASSERT_NE(snap, nullptr);
  EXPECT_EQ(snap->routes.size(), 1u);
  EXPECT_NE(snap->lookup(id_of(2), 0), nullptr);
  EXPECT_EQ(snap->lookup(id_of(3), 0), nullptr);
  auto st = net.stats(1);
  EXPECT_EQ(st.fast_routes_refused, 2u);
  // Every packet for 3 still arrives, through the agent.
  EXPECT_EQ(st.forwarded, 3u);
  EXPECT_EQ(st.fast_forwarded, 0u);
  EXPECT_EQ(net.at(3).received->size(), 2u);
  // The module's own destinations have a place of their own.
  net.send(1, id_of(0));
  EXPECT_NE(cell->get()->lookup(id_of(0), 0), nullptr);
  EXPECT_EQ(net.stats(1).fast_routes_refused, 2u);
}

TEST_F(fast_routes_test, the_agent_counts_what_its_senders_sent_on_the_fast_path) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  net.send(0, id_of(2));
  auto before = net.stats(0);
  cell->count_sent();
  cell->count_sent();
  auto after = net.stats(0);
  EXPECT_EQ(after.fast_sent, 2u);
  EXPECT_EQ(after.originated, before.originated + 2);
}

TEST_F(fast_routes_test, nothing_is_published_with_an_observer_a_tracer_or_a_key) {
  for (int variant = 0; variant < 3; ++variant) {
    auto cell = std::make_shared<route_cell>();
    auto net = build(line(2, false), [&](sim_network& n) {
      auto& cfg = n.at(0).cfg;
      cfg.fast_routes = cell;
      if (variant == 1) {
        cfg.observer = nullptr;
        cfg.tracer = [](const packet_trace&) {};
      } else if (variant == 2) {
        // Both ends keyed: routes form, data must be signed as configured.
        for (size_t i = 0; i < n.size(); ++i) {
          n.at(i).cfg.observer = nullptr;
          n.at(i).cfg.auth.key = std::vector<uint8_t>(16, 0x5a);
        }
      }
    });
    net.advance(2s);
    ASSERT_TRUE(net.route(0, id_of(1))) << "variant " << variant;
    net.send(0, id_of(1));
    EXPECT_EQ(net.at(1).received->size(), 1u) << "variant " << variant;
    EXPECT_EQ(cell->get(), nullptr) << "variant " << variant;
  }
}

TEST_F(fast_routes_test, the_snapshot_is_withdrawn_when_the_agent_ends) {
  auto cell = std::make_shared<route_cell>();
  auto net = ring6(cell);
  net.send(0, id_of(2));
  ASSERT_NE(cell->get(), nullptr);
  net.kill(0);
  net.run();
  EXPECT_EQ(cell->get(), nullptr);
}
