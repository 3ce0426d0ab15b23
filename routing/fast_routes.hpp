#pragma once

// The data path of established routes (docs/architecture.md, "Threads"):
// the routing agent publishes the next hops of the destinations its module
// sends or forwards to as an immutable snapshot, and the application
// support layer puts a unicast data packet for one of them straight on the next hop's
// channel, without a turn through the agent. On the way in, a unicast data
// packet for the module goes from the channel that received it straight to
// the receiver of its protocol, and one for another module straight to the
// channel of its next hop (fast_receiver, below). Hellos, updates, claims,
// broadcasts, authentication and tracing stay with the agent; so does every
// packet the snapshot does not cover.
//
// Who publishes what (agent_fast_routes.cpp, publish_fast_routes): only while
// the module has an address, no network key, no tracer or observer, and
// has not said goodbye; its receivers, and routes only for destinations
// this module originated a unicast packet to and for others it forwarded
// one to (at most `route_cell::max_destinations()` of each, so transit
// traffic never takes the places of the module's own destinations;
// counted in routing_stats::fast_routes_refused beyond; a destination
// the routing table forgot gives its place back); republished whenever a
// selected route to one of them changes (a channel that ends takes its
// routes with it, so that is such a change), a receiver subscribes or the
// module's address changes; withdrawn when the agent ends.
//
// Order: a packet sent through the snapshot may overtake one sent through
// the agent just before the snapshot appeared or changed (as a route change
// may reorder packets anyway): a flow may be reordered once, when it moves
// to the fast path; packets sent through one path keep their order.
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

#include "caf/meta/type_name.hpp"
#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "channels/channel_actor.hpp"
#include "channels/messages.hpp"
#include "channels/packet_tap.hpp"
#include "routing/metric.hpp"
#include "routing/module_id.hpp"

namespace herm {

/// A data packet for this module, handed to the receiver of its protocol.
struct packet_delivered {
  module_id src = no_module;
  uint8_t protocol = 0;
  uint8_t priority = prio_normal;
  /// Hops the packet took.
  uint8_t hops = 0;
  byte_buffer payload;
  /// The packet arrived signed and its signature verified (a keyed module;
  /// always false without a key, and for packets this module sent itself).
  bool authenticated = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, packet_delivered& x) {
  return f(caf::meta::type_name("packet_delivered"), x.src, x.protocol,
           x.priority, x.hops, x.payload, x.authenticated);
}

/// Receives this module's data packets of one protocol (the application
/// layer).
using network_receiver_actor = caf::typed_actor<caf::reacts_to<packet_delivered>>;

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
  /// The module's receivers, per protocol: a unicast data packet for this
  /// module goes from its channel straight to one (fast_receiver).
  std::unordered_map<uint8_t, network_receiver_actor> receivers;

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
  /// `max_destinations`: how many destinations the module sends to, and
  /// how many others it forwards to, a snapshot covers at most. A module
  /// sends to tens of others, and the snapshot is rebuilt whole when a
  /// route to one of them changes.
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

  /// Counts one packet delivered through the snapshot (the agent adds
  /// these to routing_stats::delivered).
  void count_delivered() noexcept {
    delivered_.fetch_add(1, std::memory_order_relaxed);
  }

  uint64_t delivered() const noexcept {
    return delivered_.load(std::memory_order_relaxed);
  }

  /// Counts one packet forwarded through the snapshot (the agent adds
  /// these to routing_stats::forwarded).
  void count_forwarded() noexcept {
    forwarded_.fetch_add(1, std::memory_order_relaxed);
  }

  uint64_t forwarded() const noexcept {
    return forwarded_.load(std::memory_order_relaxed);
  }

private:
  const size_t max_destinations_;
  mutable std::mutex mtx_;
  std::shared_ptr<const route_snapshot> snapshot_;
  std::atomic<uint64_t> sent_{0};
  std::atomic<uint64_t> delivered_{0};
  std::atomic<uint64_t> forwarded_{0};
};

/// The receive half: the IO manager's packet tap (channels/packet_tap.hpp).
/// It hands an unsigned unicast data packet
/// - for this module, of a protocol with a receiver, from the channel
///   straight to that receiver, its routing header cut off in place (no
///   copy);
/// - for another module with a published next hop in its size class and a
///   hop limit above 1, one hop limit less, straight to that hop's channel
///   (the same buffer), as the agent's forward would.
///
/// Everything else (a packet the snapshot does not cover, none published,
/// a hop limit that ends here, or one that does not decode) is left to the
/// channel's reader, the routing agent, which counts what it drops. Order:
/// as for sending (above).
class fast_receiver : public packet_tap {
public:
  explicit fast_receiver(std::shared_ptr<route_cell> cell)
    : cell_(std::move(cell)) {
    // nop
  }

  bool take(channel_id ch, link_addr src, byte_buffer& packet) override;

private:
  std::shared_ptr<route_cell> cell_;
};

} // namespace herm
