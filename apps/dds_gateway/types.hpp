#pragma once

// The DDS gateway's HERM-side message types and its type-ID block, which
// follows hermd's (apps/hermd/testbed_types.hpp: herm_apos, whose
// srf04_reading the sonar mapping carries). Every module that publishes or
// subscribes a Twist topic, or asks a gateway for its counters, registers
// the block (herm::dds_gateway::add_gateway_types).

#include <cstdint>

#include "caf/fwd.hpp"
#include "caf/meta/type_name.hpp"
#include "caf/type_id.hpp"

#include "apps/hermd/testbed_types.hpp"

namespace herm::dds_gateway {

/// A 3-vector; units are the user's (m/s in a twist's linear part, rad/s
/// in its angular part, as in geometry_msgs).
struct vector3 {
  double x = 0;
  double y = 0;
  double z = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, vector3& v) {
  return f(caf::meta::type_name("herm.vector3"), v.x, v.y, v.z);
}

inline bool operator==(const vector3& a, const vector3& b) {
  return a.x == b.x && a.y == b.y && a.z == b.z;
}

// [twist-type]
/// A motion command: geometry_msgs/msg/Twist on the DDS side.
struct twist {
  vector3 linear;
  vector3 angular;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, twist& t) {
  return f(caf::meta::type_name("herm.twist"), t.linear, t.angular);
}

inline bool operator==(const twist& a, const twist& b) {
  return a.linear == b.linear && a.angular == b.angular;
}
// [twist-type-end]

/// What a gateway did since it started (answer to `get, stats`).
struct gateway_stats {
  /// HERM values written to DDS.
  uint64_t to_dds = 0;
  /// DDS samples published on HERM topics.
  uint64_t from_dds = 0;
  /// DDS samples that did not convert (NaN range, string over the bound,
  /// ...): dropped, never forwarded.
  uint64_t dds_rejected = 0;
  /// HERM values of the wrong type for their mapping, or that do not fit
  /// the DDS type: dropped.
  uint64_t herm_rejected = 0;
  /// The gateway's own publications coming back from HERM on a `both`
  /// mapping: not sent to DDS again.
  uint64_t looped_back = 0;
  /// DDS samples dropped because the gateway had `max_backlog` samples not
  /// yet handled (the HERM side too slow).
  uint64_t backlog_dropped = 0;
  /// dds_write failures.
  uint64_t write_failed = 0;
  /// DDS service requests answered by a HERM APO (server mappings).
  uint64_t served = 0;
  /// DDS service requests the HERM APO did not answer (not found, error,
  /// timeout) or whose answer did not convert: no reply is written, the
  /// DDS client times out, as with a ROS 2 server that fails.
  uint64_t serve_failed = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, gateway_stats& s) {
  return f(caf::meta::type_name("herm.gateway_stats"), s.to_dds, s.from_dds,
           s.dds_rejected, s.herm_rejected, s.looped_back, s.backlog_dropped,
           s.write_failed, s.served, s.serve_failed);
}

/// Registers the block below (twist, vector3, gateway_stats) and describes
/// the types' fields (actors/type_description.hpp) for hermctl.
void add_gateway_types(caf::actor_system_config& cfg);

} // namespace herm::dds_gateway

CAF_BEGIN_TYPE_ID_BLOCK(herm_gateway, caf::id_block::herm_apos::end)
  CAF_ADD_TYPE_ID(herm_gateway, (herm::dds_gateway::vector3))
  CAF_ADD_TYPE_ID(herm_gateway, (herm::dds_gateway::twist))
  CAF_ADD_TYPE_ID(herm_gateway, (herm::dds_gateway::gateway_stats))
CAF_END_TYPE_ID_BLOCK(herm_gateway)
