// The receiver's bookkeeping of the oneway mode. The allocation counter it
// reads (alloc_count) is in probes.cpp.

#include "apps/bench/peers/transport.hpp"

namespace herm::bench {

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
