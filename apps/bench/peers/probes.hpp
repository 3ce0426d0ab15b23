#pragma once

// herm-bench-rtt's measurement probes: where each process of a case runs
// (vCPU pinning) and what the timed part of a round-trip case costs besides
// time, per process of the case (client, server, router):
//  - thread wake-ups: the sum over /proc/PID/task/*/schedstat's third field
//    (times a thread was scheduled in), and voluntary_ctxt_switches from
//    /proc/PID/task/*/status as a cross-check;
//  - heap allocations: this executable replaces malloc/calloc/realloc and
//    the aligned allocators (forwarding to glibc's own) and the global
//    operator new, and counts calls into a shared counter page (a memfd the
//    orchestrator creates and every child of the case inherits), one
//    cache-line slot per process, so the client reads the server's and the
//    router's counts too. C libraries' mallocs (Cyclone DDS, libzmq) are
//    counted. Under AddressSanitizer or ThreadSanitizer (their own malloc)
//    only operator new is counted: `allocations_counted()` says which;
//  - syscalls: perf_event_open counters on the raw_syscalls:sys_enter
//    tracepoint, one per thread of each process, opened only in a separate
//    counting pass (tracepoints put every syscall on the slow path, so the
//    timed runs never carry them).
// The client calls `timed_part_begins()` just before its first measured
// request and `timed_part_ends()` right after its last reply; the snapshots'
// own reads are ordered so that their allocations and syscalls fall outside
// the deltas (up to one read per counter). Threads that start or end inside
// the timed part are not seen (none do in these peers).

#include <sys/types.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace herm::bench {

/// The processes of one case, as slots of the shared counter page.
constexpr size_t slot_client = 0;
constexpr size_t slot_server = 1;
constexpr size_t slot_router = 2;
constexpr size_t slot_count = 3;

/// "client", "server", "router".
const char* slot_name(size_t slot);

/// One process's counts over the timed part (-1: not measured).
struct proc_counts {
  int64_t wakeups = -1;
  int64_t voluntary_switches = -1;
  int64_t allocs = -1;
  int64_t syscalls = -1;
};

using case_counts = std::array<proc_counts, slot_count>;

// -- the orchestrator ------------------------------------------------------------

/// A fresh, zeroed counter page: a memfd without close-on-exec, so the
/// children of the case inherit it under the same number. -1 on failure.
/// The caller closes it after the case.
int make_counter_page();

/// Empty when syscalls can be counted here; otherwise why not (no tracefs,
/// no permission for perf_event_open, ...). Checks once, on this process.
std::string syscall_counting_unavailable();

/// "malloc" (every heap allocation of the process, C libraries included) or
/// "operator new" (sanitizer builds).
const char* allocations_counted();

/// Pins the calling process (every thread it creates later) to `cpu`.
/// Returns false with errno set when the kernel refuses.
bool pin_to_cpu(int cpu);

/// True when this process may run on `cpu` (its affinity mask allows it).
bool cpu_allowed(int cpu);

// -- every child ------------------------------------------------------------------

/// Counts this process's allocations into `slot` of the page `fd` from now
/// on (and turns counting on). False when `fd` cannot be mapped; counting
/// then stays local to the process.
bool attach_counter_page(int fd, size_t slot);

// -- the client -------------------------------------------------------------------

/// The processes the client measures (0: absent); the client is this
/// process. With `count_syscalls`, the timed part also counts syscalls.
void set_case_processes(pid_t server, pid_t router, bool count_syscalls);

/// Snapshots before the first measured request and after the last reply.
/// Call each once, from the thread that runs the round trips; cheap enough
/// to sit between two round trips (a few /proc reads), never inside one.
void timed_part_begins();
void timed_part_ends();

/// The deltas between the two snapshots (all -1 when either is missing).
case_counts timed_part_counts();

// -- pure helpers (tested) ----------------------------------------------------------

/// The third field of a schedstat line ("run_ns wait_ns timeslices"), -1
/// when malformed.
int64_t parse_schedstat_timeslices(const std::string& line);

/// voluntary_ctxt_switches from the text of a /proc status file, -1 when
/// absent.
int64_t parse_voluntary_switches(const std::string& status);

} // namespace herm::bench
