// herm-bench-rtt's counts per round trip (see per_round_trip.hpp).

#include "apps/bench/peers/per_round_trip.hpp"

#include <algorithm>
#include <cstdio>

namespace herm::bench {

per_rt unmeasured() {
  per_rt x;
  for (auto& row : x)
    row.fill(-1);
  return x;
}

per_rt per_round_trip(const case_counts& c, uint32_t round_trips) {
  auto x = unmeasured();
  if (round_trips == 0)
    return x;
  auto div = [&](int64_t v) { return v < 0 ? -1.0 : static_cast<double>(v) / round_trips; };
  for (size_t i = 0; i < slot_count; ++i) {
    x[i][f_wakeups] = div(c[i].wakeups);
    x[i][f_vcsw] = div(c[i].voluntary_switches);
    x[i][f_allocs] = div(c[i].allocs);
    x[i][f_syscalls] = div(c[i].syscalls);
  }
  return x;
}

per_rt median_of(const std::vector<per_rt>& runs) {
  auto x = unmeasured();
  for (size_t i = 0; i < slot_count; ++i)
    for (size_t f = 0; f < field_count; ++f) {
      std::vector<double> vs;
      for (auto& r : runs)
        if (r[i][f] >= 0)
          vs.push_back(r[i][f]);
      if (vs.empty())
        continue;
      std::sort(vs.begin(), vs.end());
      auto n = vs.size();
      x[i][f] = n % 2 == 1 ? vs[n / 2] : (vs[n / 2 - 1] + vs[n / 2]) / 2;
    }
  return x;
}

per_rt with_syscalls(per_rt a, const per_rt& b) {
  for (size_t i = 0; i < slot_count; ++i)
    a[i][f_syscalls] = b[i][f_syscalls];
  return a;
}

double total(const per_rt& x, count_field f) {
  double sum = -1;
  for (auto& row : x)
    if (row[f] >= 0)
      sum = (sum < 0 ? 0 : sum) + row[f];
  return sum;
}

double most(const per_rt& x, count_field f) {
  double m = -1;
  for (auto& row : x)
    m = std::max(m, row[f]);
  return m;
}

std::string cells(const per_rt& x, count_field f) {
  std::string out;
  for (size_t i = 0; i < slot_count; ++i) {
    if (i == slot_router && x[i][f] < 0)
      break;
    char buf[32];
    if (x[i][f] < 0)
      std::snprintf(buf, sizeof(buf), "-");
    else
      std::snprintf(buf, sizeof(buf), x[i][f] < 100 ? "%.1f" : "%.0f", x[i][f]);
    out += (i > 0 ? "/" : "") + std::string{buf};
  }
  return out;
}

nlohmann::json to_json(const per_rt& x) {
  static const char* names[field_count] = {"wakeups", "voluntary_switches", "allocs",
                                           "syscalls"};
  auto out = nlohmann::json::object();
  for (size_t i = 0; i < slot_count; ++i) {
    if (std::all_of(x[i].begin(), x[i].end(), [](double v) { return v < 0; }))
      continue;
    auto row = nlohmann::json::object();
    for (size_t f = 0; f < field_count; ++f)
      row[names[f]] = x[i][f] < 0 ? nlohmann::json() : nlohmann::json(x[i][f]);
    out[slot_name(i)] = std::move(row);
  }
  return out;
}

} // namespace herm::bench
