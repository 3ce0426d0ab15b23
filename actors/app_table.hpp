#pragma once

// The application table of one module (pure core of the application support
// actor): the APOs registered here, the remote APOs learned from discovery
// answers, and which modules watch which local APO. No clock and no I/O:
// time comes in as arguments.

#include <chrono>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

#include "actors/asl_wire.hpp"
#include "routing/module_id.hpp"

namespace herm {

/// Distinct numbers that do not follow one another: a counter run through a
/// keyed permutation of T (an 8-round Feistel network over T's two halves,
/// round keys drawn from `key`). Each value comes once until the counter
/// wraps after 2^bits values, and 0 never comes. One value seen gives away
/// neither the next nor the previous ones; this is not a cryptographic
/// guarantee (a keyed network's signatures are the protection against a
/// forger who sees the traffic).
template <class T>
class scrambled_sequence {
public:
  static_assert(std::is_unsigned_v<T> && sizeof(T) >= 4);

  explicit scrambled_sequence(uint64_t key) {
    for (auto& k : keys_)
      k = mix(key += 0x9E3779B97F4A7C15ull);
  }

  T next() {
    for (;;)
      if (auto x = permute(counter_++); x != 0)
        return x;
  }

  /// The permutation itself: a bijection of T.
  T permute(T x) const {
    constexpr int half = sizeof(T) * 4;
    constexpr T mask = (T{1} << half) - 1;
    T l = x >> half;
    T r = x & mask;
    for (auto k : keys_) {
      T f = static_cast<T>(mix(k ^ r)) & mask;
      T next_r = l ^ f;
      l = r;
      r = next_r;
    }
    return static_cast<T>((l << half) | r);
  }

private:
  /// splitmix64's finalizer.
  static uint64_t mix(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }

  uint64_t keys_[8] = {};
  T counter_ = 0;
};

class app_table {
public:
  using time_point = std::chrono::steady_clock::time_point;

  struct local_entry {
    std::string name;
    std::string type;
    std::set<module_id> watchers;
  };

  struct remote_entry {
    std::string name;
    std::string type;
    time_point heard;
  };

  /// APO numbers come from a scrambled_sequence keyed with `key` (random
  /// per module start: numbers of a previous life are not taken for current
  /// ones, and one number seen gives away no other). They never repeat
  /// while the table lives (not before 2^32 registrations; never 0, never
  /// one still in use).
  explicit app_table(uint64_t key = 0);

  // -- local APOs ---------------------------------------------------------------

  /// Registers a local APO; returns its number.
  uint32_t add_local(std::string name, std::string type);

  /// Removes a local APO; returns the modules that watched it (empty if the
  /// number is unknown).
  std::set<module_id> remove_local(uint32_t apo);

  const local_entry* local(uint32_t apo) const;

  const std::map<uint32_t, local_entry>& locals() const {
    return locals_;
  }

  /// Local APOs matching a query, in number order.
  std::vector<asl_entry> match(query_by by, const std::string& pattern) const;

  // -- watchers -----------------------------------------------------------------

  /// Module `m` watches local APO `apo`; false if there is no such APO.
  /// A new watch is refused (`refused` set, true returned: the APO exists)
  /// when `max_watches` watches are held over all APOs.
  bool watch(uint32_t apo, module_id m, size_t max_watches = SIZE_MAX,
             bool* refused = nullptr);

  /// Watches held now, over all local APOs.
  size_t watches() const {
    return watches_;
  }

  void unwatch(uint32_t apo, module_id m);

  /// Forgets every watch of module `m` (it became unreachable).
  void drop_watcher(module_id m);

  // -- remote APOs ----------------------------------------------------------------

  /// Records (or refreshes) what module `m` answered. A new entry is
  /// refused (false) when `max_remotes` are held; refreshing always works.
  bool learn(module_id m, const asl_entry& e, time_point now,
             size_t max_remotes = SIZE_MAX);

  void forget(module_id m, uint32_t apo);

  void forget_module(module_id m);

  /// Drops remote entries not heard from within `ttl`.
  void expire(time_point now, std::chrono::steady_clock::duration ttl);

  const std::map<std::pair<module_id, uint32_t>, remote_entry>& remotes() const {
    return remotes_;
  }

  /// True if `e` matches a query.
  static bool matches(query_by by, const std::string& pattern,
                      const std::string& name, const std::string& type);

private:
  scrambled_sequence<uint32_t> numbers_;
  size_t watches_ = 0;
  std::map<uint32_t, local_entry> locals_;
  std::map<std::pair<module_id, uint32_t>, remote_entry> remotes_;
};

} // namespace herm
