#pragma once

// The ROS 2 services the gateway ships, with their conversions (pure, like
// ros_types.hpp). On DDS a service named S is two topics, as rmw_cyclonedds
// makes them: requests on "rq/S" + "Request" as "pkg::srv::dds_::T_Request_"
// and replies on "rr/S" + "Reply" as "pkg::srv::dds_::T_Response_", each
// sample starting with rmw_cyclonedds's request header (idl/cdds:
// the client's 64-bit id and the request's sequence number; a reply
// repeats its request's, which is how a client finds its own among all
// replies).
//
// HERM side: a request is a message to an APO and its response the APO's
// reply. example_interfaces/srv/AddTwoInts is the request (int64_t a,
// int64_t b) answered with an int64_t sum.

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "caf/actor.hpp"
#include "caf/expected.hpp"
#include "caf/fwd.hpp"
#include "caf/message.hpp"

#include "dds/dds.h"

namespace herm::dds_gateway {

/// rmw_cyclonedds's cdds_request_header_t.
struct request_header {
  uint64_t guid = 0;
  int64_t seq = 0;
};

struct ros_service {
  /// "pkg/srv/Type".
  const char* name;
  /// The HERM request and response, for logs and docs.
  const char* herm_request;
  const char* herm_response;
  const dds_topic_descriptor_t* request_descriptor;
  const dds_topic_descriptor_t* reply_descriptor;
  size_t request_size;
  size_t reply_size;
  /// A DDS request: its header and the HERM request, or an error (the
  /// sample is then dropped).
  caf::expected<caf::message> (*request_from_dds)(const void* sample,
                                                  request_header& h);
  /// A HERM request into a zeroed DDS request sample; an error for a
  /// message of another type.
  caf::error (*request_to_dds)(const caf::message& request,
                               const request_header& h, void* sample);
  /// A HERM response into a zeroed DDS reply sample.
  caf::error (*reply_to_dds)(const caf::message& response,
                             const request_header& h, void* sample);
  /// A DDS reply: its header and the HERM response.
  caf::expected<caf::message> (*reply_from_dds)(const void* sample,
                                                request_header& h);
  /// Requests `request` from `target` (on behalf of `self`) and calls
  /// `done` with the response (of this service's HERM type) or the error.
  void (*call)(caf::event_based_actor* self, const caf::actor& target,
               std::chrono::milliseconds timeout, caf::message request,
               std::function<void(caf::expected<caf::message>)> done);
};

/// Every shipped service type.
const std::vector<ros_service>& ros_services();

/// By ROS name ("example_interfaces/srv/AddTwoInts"); nullptr if not shipped.
const ros_service* find_ros_service(const std::string& name);

} // namespace herm::dds_gateway
