#pragma once

// The DDS / ROS 2 gateway (docs/gateway.md): an APO that joins HERM topics
// and DDS topics, each mapping in one direction or both, with ROS 2's names
// on the wire (topic "rt/<name>", type "pkg::msg::dds_::T_", XCDR1
// little-endian as rmw_cyclonedds writes it). hermd loads it as the APO
// kind "dds_gateway"; an embedding program calls spawn_dds_gateway and
// registers the actor in its module's application table if it wants it
// found (hermd does).
//
// Threading. HERM's actors run on one loop thread that must never block.
// DDS samples are taken by a Cyclone listener (on_data_available), on
// Cyclone's own receive thread: it takes what the reader holds with
// dds_take (never waits), converts each sample (ros_types.hpp, pure) and
// hands the HERM value to the gateway actor with anon_send. A listener
// rather than a waitset thread of our own: Cyclone already has a thread
// that knows when data is there, so there is no extra thread to stop and
// no latency of a poll period; rather than a timer poll from the loop: no
// idle wake-ups and no dds_take on the loop thread. At most `max_backlog`
// samples wait for the actor; more are dropped and counted. Writes happen
// on the loop thread: keep_last history never blocks dds_write.
//
// No loops. DDS: the gateway's readers and writers ignore entities of its
// own participant (ignorelocal), so what it writes never comes back to it.
// HERM: on a `both` mapping the gateway subscribes to the topic it also
// publishes; the application support actor hands a local publication to
// every local subscriber in order, so the gateway remembers what it
// published (bounded, 64 per mapping) and skips the first value that
// equals the oldest remembered one (counted as looped_back). A remote value
// equal to it that arrives first is taken for the echo instead; DDS then
// sees that content once either way.
//
// Bad input: a DDS sample that does not convert, or a HERM value of the
// wrong type, is dropped whole and counted (gateway_stats), never fatal.
//
// Services (ros_services.hpp): a server mapping's requests reach the HERM
// APO it names (bound by name, rebinding), and its answer goes back as the
// reply with the request's header; a client mapping's proxy APO
// (service_client.hpp) calls the DDS service. Per server mapping, at most
// 16 requests wait for the APO to be bound and 64 for its answers; more are
// counted as serve_failed.

#include "caf/actor.hpp"
#include "caf/expected.hpp"
#include "caf/fwd.hpp"

#include "actors/module.hpp"
#include "apps/dds_gateway/gateway_config.hpp"
#include "apps/dds_gateway/types.hpp"

namespace herm::dds_gateway {

/// Creates the gateway's DDS entities (one participant per domain, a topic
/// and a reader and/or writer per mapping) and its actor, which subscribes
/// to the HERM topics of its to_dds mappings on `module`. The actor
/// answers `(atom::get, atom::stats)` with gateway_stats; it deletes its
/// DDS entities when it exits (send it an exit to stop it). Errors:
/// ec::device_unavailable naming the domain or topic and Cyclone's reason.
caf::expected<caf::actor> spawn_dds_gateway(caf::actor_system& sys,
                                            const module_handles& module,
                                            gateway_config cfg);

} // namespace herm::dds_gateway
