#pragma once

// Test topologies for routing simulations and their shortest paths,
// computed independently of HERM (Dijkstra over class-0 link costs).

#include <queue>
#include <random>
#include <string>
#include <vector>

#include "routing/metric.hpp"
#include "routing/module_id.hpp"
#include "routing/route_table.hpp"

namespace herm::test {

/// A topology: modules 0..n-1 with static ids 0x100 + i, and links.
struct topology {
  size_t n = 0;
  std::vector<std::pair<std::vector<size_t>, std::string>> links;
};

inline const char* kinds[] = {"ethernet", "can2.0", "ieee1394a", "usb2.0", "rs232c",
                       "usb1.1"};

inline topology line(size_t n, bool mixed) {
  topology t{n, {}};
  for (size_t i = 0; i + 1 < n; ++i)
    t.links.push_back({{i, i + 1}, mixed ? kinds[i % 6] : "ethernet"});
  return t;
}

inline topology ring(size_t n, bool mixed) {
  auto t = line(n, mixed);
  t.links.push_back({{n - 1, 0}, mixed ? "can2.0" : "ethernet"});
  return t;
}

inline topology star(size_t n, bool mixed) {
  topology t{n, {}};
  for (size_t i = 1; i < n; ++i)
    t.links.push_back({{0, i}, mixed ? kinds[i % 6] : "ethernet"});
  return t;
}

inline topology grid(size_t w, size_t h, bool mixed) {
  topology t{w * h, {}};
  for (size_t y = 0; y < h; ++y)
    for (size_t x = 0; x < w; ++x) {
      auto i = y * w + x;
      if (x + 1 < w)
        t.links.push_back({{i, i + 1}, mixed ? kinds[(x + y) % 6] : "ethernet"});
      if (y + 1 < h)
        t.links.push_back({{i, i + w}, mixed ? kinds[(x * y) % 6] : "ethernet"});
    }
  return t;
}

/// A connected random mesh: a random spanning tree plus extra links, some
/// of them buses of three stations.
inline topology mesh(size_t n, uint64_t seed) {
  std::mt19937_64 rng{seed};
  topology t{n, {}};
  auto pick = [&](size_t bound) {
    return std::uniform_int_distribution<size_t>{0, bound - 1}(rng);
  };
  for (size_t i = 1; i < n; ++i)
    t.links.push_back({{pick(i), i}, kinds[pick(6)]});
  for (size_t extra = 0; extra < n / 2; ++extra) {
    auto a = pick(n), b = pick(n), c = pick(n);
    if (a == b || b == c || a == c)
      continue;
    if (extra % 3 == 0)
      t.links.push_back({{a, b, c}, "can2.0"});
    else
      t.links.push_back({{a, b}, kinds[pick(6)]});
  }
  return t;
}

inline module_id id_of(size_t i) {
  return static_cast<module_id>(0x100 + i);
}

/// Class-0 shortest path costs from `src` (Dijkstra over link costs).
inline std::vector<uint64_t> shortest(const topology& t, size_t src,
                                      const std::vector<bool>& link_up = {}) {
  std::vector<std::vector<std::pair<size_t, uint64_t>>> adj(t.n);
  for (size_t li = 0; li < t.links.size(); ++li) {
    if (!link_up.empty() && !link_up[li])
      continue;
    auto& [members, kind] = t.links[li];
    auto cost = link_metrics(*find_profile(kind))[0];
    for (auto a : members)
      for (auto b : members)
        if (a != b)
          adj[a].push_back({b, cost});
  }
  // Dijkstra on (cost, hops): among shortest paths, the fewest hops.
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
  // Routes are capped at max_route_hops: farther modules are unreachable.
  // (Exact for the topologies here: uniform costs, or diameters below the
  // cap.)
  std::vector<uint64_t> result(t.n);
  for (size_t i = 0; i < t.n; ++i)
    result[i] = dist[i].second > max_route_hops ? UINT64_MAX : dist[i].first;
  return result;
}

} // namespace herm::test
