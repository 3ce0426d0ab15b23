// A robot of 1,000 modules in one deterministic simulation: a random mesh of
// mixed link kinds (Table 1 profiles, some links 3-station CAN buses) with
// real IO managers and routing agents. Every module must reach every other,
// sampled routes must cost what Dijkstra says, and packets between random
// pairs must arrive without visiting any module twice. Takes a few minutes.

#include <queue>
#include <random>

#include "tests/support/actor_fixture.hpp"
#include "actors/testing/sim_network.hpp"
#include "tests/support/topology.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

class routing_sim_large : public actor_fixture {};

} // namespace

TEST_F(routing_sim_large, a_random_mesh_of_1000_modules_converges_without_loops) {
  constexpr size_t n = 1000;
  auto t = mesh(n, 42);
  sim_network net{*this, "large1000"};
  for (size_t i = 0; i < n; ++i)
    net.add_module(static_cast<module_id>(0x100 + i));
  for (auto& [members, kind] : t.links)
    net.connect(members, kind);
  net.start();
  // Triggered updates converge the network before the first periodic full
  // update (at 4 hello intervals, 400 ms), which would only add minutes of
  // simulation here (bench_routing_convergence measures the whole cost).
  net.advance(100ms);
  // Every module reaches every other (the mesh's diameter is far below the
  // 32-hop cap).
  size_t short_of_full = 0;
  for (size_t i = 0; i < n; ++i)
    if (net.stats(i).reachable != n - 1)
      ++short_of_full;
  EXPECT_EQ(short_of_full, 0u);
  // Sampled sources: every selected class-0 route costs the shortest path.
  std::mt19937_64 rng{7};
  std::uniform_int_distribution<size_t> pick{0, n - 1};
  size_t wrong = 0;
  for (int k = 0; k < 8; ++k) {
    auto a = pick(rng);
    auto dist = shortest(t, a);
    for (auto& r : net.routes(a)) {
      if (r.size_class != 0 || !r.selected)
        continue;
      auto b = static_cast<size_t>(r.destination - 0x100);
      ASSERT_LT(b, n);
      if (r.cost != dist[b] && ++wrong <= 5)
        ADD_FAILURE() << to_hex(static_cast<module_id>(0x100 + a)) << " -> "
                      << to_hex(r.destination) << ": cost " << r.cost
                      << ", shortest " << dist[b];
    }
  }
  EXPECT_EQ(wrong, 0u);
  // Traffic between random pairs, small and large packets.
  size_t lost = 0;
  for (int k = 0; k < 200; ++k) {
    auto a = pick(rng), b = pick(rng);
    if (a == b)
      continue;
    auto before = net.at(b).received->size();
    net.send(a, static_cast<module_id>(0x100 + b), k % 2 == 0 ? 8 : 1000);
    if (net.at(b).received->size() != before + 1)
      ++lost;
  }
  EXPECT_EQ(lost, 0u);
  EXPECT_EQ(net.loops(), 0u);
}
