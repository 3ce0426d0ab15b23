#include "routing/flood_cache.hpp"

#include <algorithm>

namespace herm {

flood_cache::flood_cache(size_t capacity)
  : capacity_(std::max<size_t>(capacity, 1)) {
}

void flood_cache::forget(std::map<stamp, key>::iterator i) {
  expiry_.erase(i->second);
  order_.erase(i);
}

bool flood_cache::admit(const key& k, time_point now, duration lifetime) {
  // What has expired suppresses nothing: forget it, soonest first.
  while (!order_.empty() && order_.begin()->first.first <= now)
    forget(order_.begin());
  if (expiry_.count(k) > 0)
    return false;
  // Full of live ones (a flood of distinct floods): forget the one that
  // would have gone first.
  if (expiry_.size() >= capacity_) {
    ++evicted_[order_.begin()->second.kind];
    forget(order_.begin());
  }
  stamp s{now + lifetime, admitted_++};
  expiry_.emplace(k, s);
  order_.emplace(s, k);
  return true;
}

uint64_t flood_cache::evicted(uint8_t kind) const {
  auto i = evicted_.find(kind);
  return i != evicted_.end() ? i->second : 0;
}

uint64_t flood_cache::evicted() const {
  uint64_t n = 0;
  for (auto& kv : evicted_)
    n += kv.second;
  return n;
}

} // namespace herm
