#pragma once

// The data path of established routes (docs/architecture.md, "Threads"):
// the routing agent publishes the next hops of the destinations its module
// sends to as an immutable snapshot, and the application support layer
// puts a unicast data packet for one of them straight on the next hop's
// channel, without a turn through the agent. Hellos, updates, claims,
// broadcasts, authentication, tracing and forwarding stay with the agent;
// so does every packet the snapshot has no route for.
//
// Who publishes what (agent_fast_routes.cpp, publish_fast_routes): only while
// the module has an address, no network key, no tracer or observer, and
// has not said goodbye; only for destinations this module originated a
// unicast packet to (at most `route_cell::max_destinations()`, counted in
// routing_stats::fast_routes_refused beyond); republished whenever a
// selected route to one of them changes (a channel that ends takes its
// routes with it, so that is such a change) or the module's address
// changes; withdrawn when the agent ends.
//
// Order: a packet sent through the snapshot may overtake one sent through
// the agent just before the snapshot appeared or changed (as a route change
// may reorder packets anyway); packets sent through one path keep their
// order.
//
// Thread-safety: a snapshot never changes once published; the cell is
// read and written under a mutex, from any thread.

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <unordered_map>

#include "channels/channel_actor.hpp"
#include "channels/messages.hpp"
#include "routing/metric.hpp"
#include "routing/module_id.hpp"

namespace herm {

/// Where a packet for one destination and size class leaves.
struct fast_hop {
  channel_actor channel;
  link_addr neighbour = 0;
};

/// The next hops one agent published. Immutable once published.
struct route_snapshot {
  /// The module's own address (the source of every packet sent).
  module_id self = no_module;
  /// Per destination, per size class (absent: no route in that class).
  std::unordered_map<module_id, std::array<std::optional<fast_hop>, size_classes>>
    routes;

  /// The next hop for a packet of class `k` to `dst`, or null.
  const fast_hop* lookup(module_id dst, uint8_t k) const {
    auto i = routes.find(dst);
    if (i == routes.end() || k >= size_classes || !i->second[k])
      return nullptr;
    return &*i->second[k];
  }
};

/// Shared by one routing agent (the only publisher) and the senders of its
/// module.
class route_cell {
public:
  /// `max_destinations`: how many destinations a snapshot covers at most.
  /// A module sends to tens of others, and the snapshot is rebuilt whole
  /// when a route to one of them changes.
  explicit route_cell(size_t max_destinations = 256)
    : max_destinations_(max_destinations) {
    // nop
  }

  size_t max_destinations() const noexcept {
    return max_destinations_;
  }

  /// The current snapshot, or null (then every packet goes to the agent).
  std::shared_ptr<const route_snapshot> get() const {
    std::lock_guard<std::mutex> guard{mtx_};
    return snapshot_;
  }

  void publish(std::shared_ptr<const route_snapshot> x) {
    std::lock_guard<std::mutex> guard{mtx_};
    snapshot_ = std::move(x);
  }

  /// Counts one packet sent through the snapshot (the agent adds these to
  /// routing_stats::originated).
  void count_sent() noexcept {
    sent_.fetch_add(1, std::memory_order_relaxed);
  }

  uint64_t sent() const noexcept {
    return sent_.load(std::memory_order_relaxed);
  }

private:
  const size_t max_destinations_;
  mutable std::mutex mtx_;
  std::shared_ptr<const route_snapshot> snapshot_;
  std::atomic<uint64_t> sent_{0};
};

} // namespace herm
