// A robot of 1,000 modules in one deterministic simulation: a random mesh of
// mixed link kinds (Table 1 profiles, some links 3-station CAN buses) with
// real IO managers and routing agents. Every module must reach every other,
// sampled routes must cost what Dijkstra says, and packets between random
// pairs must arrive without visiting any module twice. Takes a few minutes.

#include <queue>
#include <random>

#include "tests/support/actor_fixture.hpp"
#include "actors/testing/sim_network.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

struct edge_list {
  size_t n = 0;
  std::vector<std::pair<std::vector<size_t>, std::string>> links;
};

edge_list random_mesh(size_t n, uint64_t seed) {
  const char* kinds[] = {"ethernet", "can2.0", "ieee1394a", "usb2.0", "rs232c"};
  std::mt19937_64 rng{seed};
  auto pick = [&](size_t bound) {
    return std::uniform_int_distribution<size_t>{0, bound - 1}(rng);
  };
  edge_list t{n, {}};
  for (size_t i = 1; i < n; ++i)
    t.links.push_back({{pick(i), i}, kinds[pick(5)]});
  for (size_t extra = 0; extra < n / 2; ++extra) {
    auto a = pick(n), b = pick(n), c = pick(n);
    if (a == b || b == c || a == c)
      continue;
    if (extra % 3 == 0)
      t.links.push_back({{a, b, c}, "can2.0"});
    else
      t.links.push_back({{a, b}, kinds[pick(5)]});
  }
  return t;
}

/// Class-0 shortest-path costs and hop counts from `src`.
std::vector<std::pair<uint64_t, uint64_t>> dijkstra(const edge_list& t, size_t src) {
  std::vector<std::vector<std::pair<size_t, uint64_t>>> adj(t.n);
  for (auto& [members, kind] : t.links) {
    auto cost = link_metrics(*find_profile(kind))[0];
    for (auto a : members)
      for (auto b : members)
        if (a != b)
          adj[a].push_back({b, cost});
  }
  std::vector<std::pair<uint64_t, uint64_t>> dist(t.n, {UINT64_MAX, 0});
  using item = std::pair<std::pair<uint64_t, uint64_t>, size_t>;
  std::priority_queue<item, std::vector<item>, std::greater<>> q;
  dist[src] = {0, 0};
  q.push({dist[src], src});
  while (!q.empty()) {
    auto [d, u] = q.top();
    q.pop();
    if (d > dist[u])
      continue;
    for (auto [v, c] : adj[u]) {
      std::pair<uint64_t, uint64_t> nd{d.first + c, d.second + 1};
      if (nd < dist[v]) {
        dist[v] = nd;
        q.push({nd, v});
      }
    }
  }
  return dist;
}

class routing_sim_large : public actor_fixture {};

} // namespace

TEST_F(routing_sim_large, a_random_mesh_of_1000_modules_converges_without_loops) {
  constexpr size_t n = 1000;
  auto t = random_mesh(n, 42);
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
    auto dist = dijkstra(t, a);
    for (auto& r : net.routes(a)) {
      if (r.size_class != 0 || !r.selected)
        continue;
      auto b = static_cast<size_t>(r.destination - 0x100);
      ASSERT_LT(b, n);
      EXPECT_LE(dist[b].second, max_route_hops);
      if (r.cost != dist[b].first && ++wrong <= 5)
        ADD_FAILURE() << to_hex(static_cast<module_id>(0x100 + a)) << " -> "
                      << to_hex(r.destination) << ": cost " << r.cost
                      << ", shortest " << dist[b].first;
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
