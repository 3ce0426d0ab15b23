#pragma once

// herm-bench-rtt's counts per round trip: a process's wake-ups, voluntary
// context switches, allocations and syscalls over a case's timed part
// (probes.hpp) divided by its round trips, the median over runs, and how
// they are shown in the table and the JSON. Pure: no I/O but the strings
// returned.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "apps/bench/peers/probes.hpp"

namespace herm::bench {

/// The figures per process, in this order.
enum count_field : size_t { f_wakeups, f_vcsw, f_allocs, f_syscalls, field_count };

/// Per round trip, by slot (client, server, router) and count_field; -1:
/// not measured (no such process, or no probe).
using per_rt = std::array<std::array<double, field_count>, slot_count>;

/// An all -1 table.
per_rt unmeasured();

/// `c` divided by `round_trips` (all -1 when 0).
per_rt per_round_trip(const case_counts& c, uint32_t round_trips);

/// The median of each figure over the runs that measured it (-1: none did).
per_rt median_of(const std::vector<per_rt>& runs);

/// `a` with the syscall figures of `b` (those come from the counting pass).
per_rt with_syscalls(per_rt a, const per_rt& b);

/// Sum of one figure over the processes that measured it (-1: none).
double total(const per_rt& x, count_field f);

/// Largest of one figure over the processes (-1: none measured it).
double most(const per_rt& x, count_field f);

/// One figure per process, "c/s" or "c/s/r" ('-' where not measured, the
/// router's only when it measured), e.g. "2.0/2.0".
std::string cells(const per_rt& x, count_field f);

/// {"client": {"wakeups": .., "voluntary_switches": .., "allocs": ..,
/// "syscalls": ..}, "server": {..}, "router": {..}} with null for -1 and
/// processes without any figure left out.
nlohmann::json to_json(const per_rt& x);

} // namespace herm::bench
