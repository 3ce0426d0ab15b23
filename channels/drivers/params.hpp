#pragma once

// Helpers the link drivers share for their options (read once, at open) and
// parameters (get_param): what every driver otherwise spells out per option
// and per counter.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include <caf/error.hpp>
#include <caf/expected.hpp>

namespace herm {

/// Stores an option value as read by option_reader (channels/options.hpp)
/// into `out`, converted to T, and returns none; or returns the read's error
/// unchanged, leaving `out` as it was. Replaces the "if (!x) return
/// x.error(); out = *x;" after each option read.
template <class T, class U>
caf::error read_into(T& out, caf::expected<U> value) {
  if (!value)
    return std::move(value.error());
  out = static_cast<T>(std::move(*value));
  return caf::none;
}

/// read_into for a run-time parameter: stores the value into the atomic
/// `out` (one store), or returns the read's error leaving `out` as it was.
template <class T, class U>
caf::error read_into(std::atomic<T>& out, caf::expected<U> value) {
  if (!value)
    return std::move(value.error());
  out.store(static_cast<T>(std::move(*value)));
  return caf::none;
}

/// One counter a driver reports through get_param: the key and the atomic
/// member of `Driver` that holds it.
template <class Driver>
struct counter_param {
  const char* key;
  std::atomic<uint64_t> Driver::*counter;
};

/// The counter `key` names in `table`, loaded from `self`, as decimal
/// text; nullopt when `table` has no such key. O(N) string compares; any
/// thread.
template <class Driver, size_t N>
std::optional<std::string>
read_counter(const Driver& self, const counter_param<Driver> (&table)[N],
             const std::string& key) {
  for (auto& entry : table)
    if (key == entry.key)
      return std::to_string((self.*entry.counter).load());
  return std::nullopt;
}

} // namespace herm
