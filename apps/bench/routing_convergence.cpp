// Routing convergence and repair, measured in simulated time on HERM's
// deterministic multi-module harness (actors/testing/): every module is a
// real IO manager and routing agent; links are in-process media with Table 1
// profiles. Deterministic: the same command prints the same numbers.
//
//   bench_routing_convergence [--sizes 10,100,1000] [--hello-ms 100]
//                             [--json FILE]
//
// Cold start: every module starts at t = 0; converged when every module
// has a selected class-0 route to every other module (all within the hop
// cap in these topologies). Reported: simulated time to converge, routing
// messages sent (hellos, updates, seqno requests) and update entries.
// Repair: a ring of 10 modules; the link on a converged path fails silently
// (frames vanish, no driver notices: only missed hellos reveal it); time
// until traffic takes the alternate path, for several hello intervals. A
// failure the driver notices (socket error, interface down) repairs at once.
// --json FILE also writes every row as JSON (apps/bench/report reads it).

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <sstream>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "actors/testing/sim_network.hpp"

using namespace herm;
using namespace herm::testkit;
using namespace std::chrono;

namespace {

/// Every row printed, for --json.
nlohmann::json results = {{"cold_start", nlohmann::json::array()},
                          {"repair", nlohmann::json::array()}};

struct counts {
  uint64_t hellos = 0;
  uint64_t updates = 0;
  uint64_t entries = 0;
  uint64_t requests = 0;
};

counts totals(sim_network& net) {
  counts c;
  for (size_t i = 0; i < net.size(); ++i) {
    auto st = net.stats(i);
    c.hellos += st.tx_hellos;
    c.updates += st.tx_updates;
    c.entries += st.tx_update_entries;
    c.requests += st.tx_seqno_requests;
  }
  return c;
}

bool converged(sim_network& net) {
  for (size_t i = 0; i < net.size(); ++i)
    if (net.stats(i).reachable + 1 < net.size())
      return false;
  return true;
}

/// A random mesh of n modules: a random tree (shallow) plus n/2 extra links
/// of mixed kinds, some of them 3-station CAN buses.
void build_mesh(sim_network& net, size_t n, uint64_t seed) {
  const char* kinds[] = {"ethernet", "can2.0", "ieee1394a", "usb2.0", "rs232c"};
  std::mt19937_64 rng{seed};
  auto pick = [&](size_t bound) {
    return std::uniform_int_distribution<size_t>{0, bound - 1}(rng);
  };
  for (size_t i = 0; i < n; ++i)
    net.add_module(static_cast<module_id>(0x100 + i));
  for (size_t i = 1; i < n; ++i)
    net.connect({pick(i), i}, kinds[pick(5)]);
  for (size_t extra = 0; extra < n / 2; ++extra) {
    auto a = pick(n), b = pick(n), c = pick(n);
    if (a == b || b == c || a == c)
      continue;
    if (extra % 3 == 0)
      net.connect({a, b, c}, "can2.0");
    else
      net.connect({a, b}, kinds[pick(5)]);
  }
}

void cold_start(size_t n, milliseconds hello) {
  deterministic_system sys;
  sim_network net{sys, "conv" + std::to_string(n), hello};
  build_mesh(net, n, 42);
  auto wall = steady_clock::now();
  net.start();
  // Checked every tenth of a hello interval: the figure's resolution.
  auto step = std::max(milliseconds{1}, hello / 10);
  milliseconds t{0};
  auto limit = hello * 200;
  while (t < limit) {
    net.advance(step);
    t += step;
    if (converged(net))
      break;
  }
  auto c = totals(net);
  auto secs = duration_cast<duration<double>>(steady_clock::now() - wall).count();
  std::printf("| %zu | %lld ms | %.1f | %llu | %llu | %llu | %llu | %.1f s |\n", n,
              static_cast<long long>(t.count()),
              double(t.count()) / double(hello.count()),
              static_cast<unsigned long long>(c.hellos),
              static_cast<unsigned long long>(c.updates),
              static_cast<unsigned long long>(c.entries),
              static_cast<unsigned long long>(c.requests), secs);
  std::fflush(stdout);
  results["cold_start"].push_back(
    {{"modules", n},
     {"converged", converged(net)},
     {"converged_ms", t.count()},
     {"hello_ms", hello.count()},
     {"hellos", c.hellos},
     {"updates", c.updates},
     {"update_entries", c.entries},
     {"seqno_requests", c.requests},
     {"wall_s", secs}});
}

/// Time from a silent failure of link 0-1 at `phase` after convergence
/// until a packet from 0 to 2 takes the alternate path; loops seen.
std::pair<milliseconds, size_t> repair_once(milliseconds hello, milliseconds phase) {
  deterministic_system sys;
  sim_network net{sys, "repair" + std::to_string(hello.count()) + "-"
                         + std::to_string(phase.count()),
                  hello};
  for (size_t i = 0; i < 10; ++i)
    net.add_module(static_cast<module_id>(0x100 + i));
  for (size_t i = 0; i < 10; ++i)
    net.connect({i, (i + 1) % 10}, "ethernet");
  net.start();
  net.advance(hello * 30 + phase);
  auto step = milliseconds(std::max<int64_t>(1, hello.count() / 20));
  net.silence(0);
  milliseconds t{0};
  size_t loops_before = net.loops();
  while (t < hello * 20) {
    auto tag = net.send(0, 0x102);
    auto& p = net.path(tag);
    if (p.size() == 9 && p.back() == 0x102)
      return {t, net.loops() - loops_before};
    net.advance(step);
    t += step;
  }
  return {milliseconds::max(), net.loops() - loops_before};
}

void repair(milliseconds hello) {
  // Eight failure times spread over one hello interval.
  std::vector<milliseconds> times;
  size_t loops = 0;
  for (int k = 0; k < 8; ++k) {
    auto [t, l] = repair_once(hello, hello * k / 8);
    times.push_back(t);
    loops += l;
  }
  std::sort(times.begin(), times.end());
  auto fmt = [&](milliseconds t) {
    if (t == milliseconds::max())
      return std::string{"never"};
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%lld ms (%.2f)", static_cast<long long>(t.count()),
                  double(t.count()) / double(hello.count()));
    return std::string{buf};
  };
  std::printf("| %lld ms | %s | %s | %s | %zu |\n",
              static_cast<long long>(hello.count()), fmt(times.front()).c_str(),
              fmt(times[times.size() / 2]).c_str(), fmt(times.back()).c_str(),
              loops);
  std::fflush(stdout);
  auto ms = [](milliseconds t) -> nlohmann::json {
    if (t == milliseconds::max())
      return nullptr; // never repaired
    return t.count();
  };
  results["repair"].push_back({{"hello_ms", hello.count()},
                               {"failures", times.size()},
                               {"min_ms", ms(times.front())},
                               {"median_ms", ms(times[times.size() / 2])},
                               {"max_ms", ms(times.back())},
                               {"loops", loops}});
}

} // namespace

int main(int argc, char** argv) {
  std::string sizes = "10,100";
  int hello_ms = 100;
  CLI::App app{"HERM routing convergence and repair (simulated time)"};
  app.add_option("--sizes", sizes, "module counts, comma-separated");
  app.add_option("--hello-ms", hello_ms, "hello interval for cold start");
  std::string json_file;
  app.add_option("--json", json_file, "also write the results as JSON to FILE");
  CLI11_PARSE(app, argc, argv);
  std::printf("Cold start (random mesh, hello %d ms, full update every 4 hellos)\n\n",
              hello_ms);
  std::printf("| modules | converged after | hello intervals | hellos | updates | "
              "update entries | seqno requests | wall clock |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  std::stringstream ss{sizes};
  std::string item;
  while (std::getline(ss, item, ','))
    cold_start(std::stoul(item), milliseconds(hello_ms));
  std::printf("\nRepair after a silent link failure (ring of 10, Ethernet)\n\n");
  std::printf("Time until traffic takes the alternate path, over 8 failure times "
              "spread across one hello interval (in hello intervals)\n\n");
  std::printf("| hello interval | min | median | max | loops |\n"
              "|---|---|---|---|---|\n");
  for (int h : {50, 100, 500, 1000, 4000})
    repair(milliseconds(h));
  if (!json_file.empty()) {
    results["benchmark"] = "bench_routing_convergence";
    results["sizes"] = sizes;
    std::string cmd;
    for (int i = 0; i < argc; ++i)
      cmd += (i > 0 ? " " : "") + std::string{argv[i]};
    results["command"] = cmd;
    std::FILE* f = std::fopen(json_file.c_str(), "w");
    if (f == nullptr) {
      std::perror(json_file.c_str());
      return 1;
    }
    auto text = results.dump(2) + "\n";
    auto ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    if (std::fclose(f) != 0 || !ok) {
      std::fprintf(stderr, "%s: write failed\n", json_file.c_str());
      return 1;
    }
  }
  return 0;
}
