#pragma once

// The proxy APO of a client service mapping: HERM modules bind it by name
// and request it like any APO; it calls the DDS service (a ROS 2 service
// server on the mapping's domain) and answers with the reply.
//
// A request of the service's HERM type is written on rq/<S>Request with
// the request header {guid, next sequence number}; the reply reader's
// listener hands replies carrying this client's guid to the proxy
// (svc_reply_atom), which answers the request with the same sequence
// number. Errors, as HERM's typed errors: app_ec::not_found when no DDS
// service server is matched (nobody to call), ec::timeout when none
// answered within the mapping's timeout_ms, ec::queue_full past
// max_calls outstanding calls, ec::invalid_parameter for a request of
// another type, ec::device_failed when dds_write fails. A reply to no
// outstanding call (late, or another client's) is dropped.
//
// Runs on HERM's loop thread like every actor; dds_write never blocks
// (keep-last history).

#include <atomic>
#include <cstdint>
#include <memory>

#include "caf/actor.hpp"
#include "caf/fwd.hpp"

#include "apps/dds_gateway/gateway_config.hpp"

namespace herm::dds_gateway {

/// A DDS reply for the proxy: guid, sequence number, HERM response.
using svc_reply_atom = caf::atom_constant<caf::atom("gw_svc_rr")>;

/// Most calls one proxy has outstanding.
constexpr size_t max_calls = 64;

/// Spawns the proxy for mapping `m` (a client service mapping) writing
/// requests with `writer` under id `guid`. Each reply message it handles
/// decrements `backlog` (the listener's count of samples in flight).
caf::actor spawn_service_client(caf::actor_system& sys, mapping m,
                                dds_entity_t writer, uint64_t guid,
                                std::shared_ptr<std::atomic<uint32_t>> backlog);

} // namespace herm::dds_gateway
