// The receiver's bookkeeping of the oneway mode and the allocation counter
// every process of the benchmark carries: the global operator new is
// replaced by one that counts calls while counting is on (the oneway mode
// only, both ends, every transport alike), so the report can say how many
// heap allocations one message costs on each side.

#include <atomic>
#include <cstdlib>
#include <new>

#include "apps/bench/peers/transport.hpp"

namespace {

std::atomic<bool> counting{false};
std::atomic<uint64_t> allocs{0};

void* counted_alloc(std::size_t n) {
  if (counting.load(std::memory_order_relaxed))
    allocs.fetch_add(1, std::memory_order_relaxed);
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
  return counted_alloc(n);
}

void* operator new[](std::size_t n) {
  return counted_alloc(n);
}

void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_alloc(n);
  } catch (...) {
    return nullptr;
  }
}

void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_alloc(n);
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
  return allocs.load(std::memory_order_relaxed);
}

void alloc_counting(bool on) {
  counting.store(on, std::memory_order_relaxed);
}

bool oneway_counter::on_message(uint32_t seq, int64_t now) {
  ++seen;
  if (seq >= warmup && seq < total) {
    if (received == 0) {
      first_ns = now;
      first_allocs = alloc_count();
    }
    ++received;
    last_ns = now;
    last_allocs = alloc_count();
  }
  if (seq + 1 > next)
    next = seq + 1;
  return seen % ack_every == 0 || seq + 1 == total;
}

} // namespace herm::bench
