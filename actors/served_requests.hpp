#pragma once

// The requests of other modules one application support actor is serving
// (pure core): for each, who asked under which request id, until when the
// answer is worth sending, and how to send it. The local APO sees a local
// request number instead (sequential: it never leaves the module).
//
// No clock and no I/O: time comes in as arguments. Not thread-safe (one
// actor owns it). At most `max` requests (see full); add and take
// O(log n), expire O(n).

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>

#include "routing/module_id.hpp"

namespace herm {

/// A request a remote module made of one of our APOs.
struct served {
  module_id origin = no_module;
  uint64_t origin_id = 0;
  std::chrono::steady_clock::time_point deadline;
  /// The response goes into the duplicate-suppression cache too.
  bool reliable = false;
  /// For a signed_only APO: the response travels signed.
  bool sign = false;
};

class served_requests {
public:
  using time_point = std::chrono::steady_clock::time_point;

  explicit served_requests(size_t max = SIZE_MAX) : max_(max) {
    // nop
  }

  bool full() const {
    return requests_.size() >= max_;
  }

  size_t size() const {
    return requests_.size();
  }

  /// Adds `s` (room permitting: see full): its local request number.
  uint64_t add(served s);

  /// Removes and returns request `local`; nullopt if it is not served
  /// (any more: expired, or answered twice).
  std::optional<served> take(uint64_t local);

  /// Forgets the requests whose deadline is not after `now` (a late
  /// answer then goes nowhere).
  void expire(time_point now);

private:
  size_t max_;
  uint64_t next_ = 1;
  std::map<uint64_t, served> requests_;
};

} // namespace herm
