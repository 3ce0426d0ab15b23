// herm-bench-rtt's probes (see probes.hpp): the allocation counter (this
// executable's malloc and operator new), the shared counter page, /proc
// snapshots, perf syscall counters and vCPU pinning.

#include "apps/bench/peers/probes.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <linux/perf_event.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <new>
#include <sstream>
#include <tuple>
#include <vector>

#include "apps/bench/peers/transport.hpp"

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#  define HERM_BENCH_SANITIZED 1
#elif defined(__has_feature)
#  if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) \
    || __has_feature(memory_sanitizer)
#    define HERM_BENCH_SANITIZED 1
#  endif
#endif

// -- the allocation counter ------------------------------------------------------------
// Constant-initialised (no constructor runs), so the allocator works before
// main and during static initialisation.

namespace {

static_assert(std::atomic<uint64_t>::is_always_lock_free,
              "the shared counter page needs lock-free 64-bit atomics");

std::atomic<bool> counting{false};
std::atomic<uint64_t> local_count{0};
std::atomic<std::atomic<uint64_t>*> count_slot{&local_count};

inline void count_one() {
  if (counting.load(std::memory_order_relaxed))
    count_slot.load(std::memory_order_relaxed)->fetch_add(1, std::memory_order_relaxed);
}

} // namespace

#ifndef HERM_BENCH_SANITIZED
// glibc's own allocator under its internal names: the replacements below
// count and forward, so memory from either side may be freed by the other.
extern "C" {
void* __libc_malloc(size_t);
void* __libc_calloc(size_t, size_t);
void* __libc_realloc(void*, size_t);
void* __libc_memalign(size_t, size_t);
void __libc_free(void*);

void* malloc(size_t n) noexcept {
  count_one();
  return __libc_malloc(n);
}

void* calloc(size_t n, size_t size) noexcept {
  count_one();
  return __libc_calloc(n, size);
}

void* realloc(void* p, size_t n) noexcept {
  count_one();
  return __libc_realloc(p, n);
}

void free(void* p) noexcept {
  __libc_free(p);
}

void* memalign(size_t align, size_t n) noexcept {
  count_one();
  return __libc_memalign(align, n);
}

void* aligned_alloc(size_t align, size_t n) noexcept {
  count_one();
  return __libc_memalign(align, n);
}

int posix_memalign(void** out, size_t align, size_t n) noexcept {
  if (align < sizeof(void*) || (align & (align - 1)) != 0)
    return EINVAL;
  count_one();
  void* p = __libc_memalign(align, n);
  if (p == nullptr)
    return ENOMEM;
  *out = p;
  return 0;
}
} // extern "C"
#endif

namespace {

void* counted_new(std::size_t n) {
#ifdef HERM_BENCH_SANITIZED
  count_one(); // malloc is the sanitizer's: count here instead
#endif
  if (n == 0)
    n = 1;
  for (;;) {
    if (void* p = std::malloc(n))
      return p;
    auto handler = std::get_new_handler();
    if (handler == nullptr)
      throw std::bad_alloc{};
    handler();
  }
}

} // namespace

void* operator new(std::size_t n) {
  return counted_new(n);
}

void* operator new[](std::size_t n) {
  return counted_new(n);
}

void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}

void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}

void operator delete(void* p) noexcept {
  std::free(p);
}

void operator delete[](void* p) noexcept {
  std::free(p);
}

void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}

void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}

namespace herm::bench {

uint64_t alloc_count() {
  return count_slot.load(std::memory_order_relaxed)->load(std::memory_order_relaxed);
}

void alloc_counting(bool on) {
  counting.store(on, std::memory_order_relaxed);
}

const char* allocations_counted() {
#ifdef HERM_BENCH_SANITIZED
  return "operator new";
#else
  return "malloc";
#endif
}

const char* slot_name(size_t slot) {
  static const char* names[] = {"client", "server", "router"};
  return slot < slot_count ? names[slot] : "?";
}

// -- the shared counter page -----------------------------------------------------------

namespace {

struct alignas(64) page_slot {
  std::atomic<uint64_t> allocs;
};

constexpr size_t page_size = 4096;
static_assert(sizeof(page_slot) * slot_count <= page_size);

page_slot* page = nullptr; // this process's mapping, if any

} // namespace

int make_counter_page() {
  int fd = static_cast<int>(::syscall(SYS_memfd_create, "herm-bench-counters", 0));
  if (fd < 0)
    return -1;
  if (::ftruncate(fd, page_size) != 0) { // zero-filled
    ::close(fd);
    return -1;
  }
  return fd;
}

bool attach_counter_page(int fd, size_t slot) {
  if (fd < 0 || slot >= slot_count)
    return false;
  void* p = ::mmap(nullptr, page_size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED)
    return false;
  page = static_cast<page_slot*>(p);
  count_slot.store(&page[slot].allocs, std::memory_order_relaxed);
  alloc_counting(true);
  return true;
}

// -- pinning ------------------------------------------------------------------------------

bool pin_to_cpu(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return ::sched_setaffinity(0, sizeof(set), &set) == 0;
}

bool cpu_allowed(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  return cpu >= 0 && cpu < CPU_SETSIZE && ::sched_getaffinity(0, sizeof(set), &set) == 0
         && CPU_ISSET(cpu, &set);
}

// -- /proc ------------------------------------------------------------------------------

int64_t parse_schedstat_timeslices(const std::string& line) {
  std::istringstream in{line};
  int64_t run = 0, wait = 0, slices = -1;
  if (!(in >> run >> wait >> slices) || slices < 0)
    return -1;
  return slices;
}

int64_t parse_voluntary_switches(const std::string& status) {
  static const char key[] = "voluntary_ctxt_switches:";
  auto at = status.find(key);
  // "nonvoluntary_ctxt_switches:" contains the key too: it must start a line.
  while (at != std::string::npos && at > 0 && status[at - 1] != '\n')
    at = status.find(key, at + 1);
  if (at == std::string::npos)
    return -1;
  std::istringstream in{status.substr(at + sizeof(key) - 1)};
  int64_t n = -1;
  in >> n;
  return in ? n : -1;
}

namespace {

std::string read_small_file(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    return {};
  char buf[4096];
  std::string out;
  ssize_t n;
  while ((n = ::read(fd, buf, sizeof(buf))) > 0 && out.size() < 65536)
    out.append(buf, static_cast<size_t>(n));
  ::close(fd);
  return out;
}

std::vector<pid_t> threads_of(pid_t pid) {
  std::vector<pid_t> out;
  auto dir = "/proc/" + std::to_string(pid) + "/task";
  if (DIR* d = ::opendir(dir.c_str())) {
    while (auto* e = ::readdir(d))
      if (e->d_name[0] != '.')
        out.push_back(static_cast<pid_t>(std::atoi(e->d_name)));
    ::closedir(d);
  }
  return out;
}

/// Sums of the threads' timeslices and voluntary switches (-1: no threads).
std::pair<int64_t, int64_t> sched_counts(pid_t pid) {
  int64_t slices = -1, vcsw = -1;
  for (auto tid : threads_of(pid)) {
    auto base = "/proc/" + std::to_string(pid) + "/task/" + std::to_string(tid);
    auto s = parse_schedstat_timeslices(read_small_file(base + "/schedstat"));
    auto v = parse_voluntary_switches(read_small_file(base + "/status"));
    if (s >= 0)
      slices = (slices < 0 ? 0 : slices) + s;
    if (v >= 0)
      vcsw = (vcsw < 0 ? 0 : vcsw) + v;
  }
  return {slices, vcsw};
}

// -- perf syscall counters -------------------------------------------------------------------

long sys_enter_id() {
  for (auto* path : {"/sys/kernel/tracing/events/raw_syscalls/sys_enter/id",
                     "/sys/kernel/debug/tracing/events/raw_syscalls/sys_enter/id"}) {
    auto text = read_small_file(path);
    if (!text.empty())
      return std::atol(text.c_str());
  }
  return -1;
}

int open_syscall_counter(long id, pid_t tid) {
  perf_event_attr a;
  std::memset(&a, 0, sizeof(a));
  a.type = PERF_TYPE_TRACEPOINT;
  a.size = sizeof(a);
  a.config = static_cast<uint64_t>(id);
  return static_cast<int>(::syscall(SYS_perf_event_open, &a, tid, -1, -1, PERF_FLAG_FD_CLOEXEC));
}

int64_t read_counter(int fd) {
  uint64_t v = 0;
  return ::read(fd, &v, sizeof(v)) == sizeof(v) ? static_cast<int64_t>(v) : -1;
}

// -- the client's snapshots ------------------------------------------------------------------

struct snapshot {
  std::array<int64_t, slot_count> wakeups{-1, -1, -1}, vcsw{-1, -1, -1};
  std::array<int64_t, slot_count> allocs{-1, -1, -1}, syscalls{-1, -1, -1};
  bool taken = false;
};

std::array<pid_t, slot_count> pids{0, 0, 0};
bool syscalls_wanted = false;
std::array<std::vector<int>, slot_count> counters; // perf fds per thread
snapshot before, after;

void read_sched(snapshot& s) {
  for (size_t i = 0; i < slot_count; ++i)
    if (pids[i] > 0)
      std::tie(s.wakeups[i], s.vcsw[i]) = sched_counts(pids[i]);
}

void read_allocs(snapshot& s) {
  for (size_t i = 0; i < slot_count; ++i)
    if (pids[i] > 0 && page != nullptr)
      s.allocs[i] = static_cast<int64_t>(page[i].allocs.load(std::memory_order_relaxed));
}

void read_syscalls(snapshot& s) {
  for (size_t i = 0; i < slot_count; ++i) {
    if (counters[i].empty())
      continue;
    int64_t sum = 0;
    for (int fd : counters[i]) {
      auto v = read_counter(fd);
      if (v < 0) {
        sum = -1;
        break;
      }
      sum += v;
    }
    s.syscalls[i] = sum;
  }
}

} // namespace

std::string syscall_counting_unavailable() {
  static const std::string why = [] {
    auto id = sys_enter_id();
    if (id < 0)
      return std::string{"no tracefs with raw_syscalls/sys_enter (mount tracefs on "
                         "/sys/kernel/tracing)"};
    int fd = open_syscall_counter(id, 0);
    if (fd < 0)
      return "perf_event_open on raw_syscalls:sys_enter: " + std::string{std::strerror(errno)}
             + " (needs CAP_PERFMON or kernel.perf_event_paranoid=-1)";
    ::close(fd);
    return std::string{};
  }();
  return why;
}

void set_case_processes(pid_t server, pid_t router, bool count_syscalls) {
  pids = {::getpid(), server, router};
  syscalls_wanted = count_syscalls;
}

void timed_part_begins() {
  before = after = snapshot{};
  if (pids[slot_client] == 0)
    pids[slot_client] = ::getpid();
  if (syscalls_wanted) {
    if (auto id = sys_enter_id(); id >= 0)
      for (size_t i = 0; i < slot_count; ++i) {
        if (pids[i] <= 0)
          continue;
        for (auto tid : threads_of(pids[i])) {
          int fd = open_syscall_counter(id, tid);
          if (fd < 0) { // counts of a part of the threads would mislead
            for (int x : counters[i])
              ::close(x);
            counters[i].clear();
            break;
          }
          counters[i].push_back(fd);
        }
      }
  }
  // Most expensive first: the reads' own allocations and syscalls fall
  // before the allocation and syscall baselines.
  read_sched(before);
  read_allocs(before);
  read_syscalls(before);
  before.taken = true;
}

void timed_part_ends() {
  read_syscalls(after);
  read_allocs(after);
  read_sched(after);
  after.taken = true;
  for (auto& fds : counters) {
    for (int fd : fds)
      ::close(fd);
    fds.clear();
  }
}

case_counts timed_part_counts() {
  case_counts out;
  if (!before.taken || !after.taken)
    return out;
  auto delta = [](int64_t a, int64_t b) { return a >= 0 && b >= a ? b - a : -1; };
  for (size_t i = 0; i < slot_count; ++i) {
    out[i].wakeups = delta(before.wakeups[i], after.wakeups[i]);
    out[i].voluntary_switches = delta(before.vcsw[i], after.vcsw[i]);
    out[i].allocs = delta(before.allocs[i], after.allocs[i]);
    out[i].syscalls = delta(before.syscalls[i], after.syscalls[i]);
  }
  return out;
}

} // namespace herm::bench
