#pragma once

// What a DDS gateway joins: its mappings, each a HERM topic and a DDS
// topic with a ROS type, a direction, a domain and QoS. Read from an APO's
// flat options (hermd's `apos` section; docs/gateway.md, "Configuration"):
//
//   domain: 0                 default domain of every mapping (0..232)
//   namespace: robot1         ROS 2 namespace of the default DDS names:
//                             rt/robot1/<topic>, rq/robot1/<name>Request
//   max_string: 4096          longest string either way, bytes
//   max_bytes: 60000          longest byte sequence either way (Image data)
//   max_backlog: 1024         DDS samples waiting for the HERM side at most
//   <topic>.type: sensor_msgs/msg/Range      required: makes a mapping
//   <topic>.direction: to_dds | from_dds | both          (to_dds)
//   <topic>.dds_topic: rt/[<namespace>/]<topic>
//   <topic>.domain: <domain>
//   <topic>.reliability: reliable | best_effort          (reliable)
//   <topic>.depth: 10                        keep_last history depth
//   <topic>.durability: volatile | transient_local       (volatile)
//   <topic>.frame_id                          (Range and Image; the topic)
//   <topic>.field_of_view / min_range / max_range            (Range only)
//
// A service instead (docs/gateway.md, "Services"), `<name>` its ROS name:
//   <name>.service: example_interfaces/srv/AddTwoInts   required
//   <name>.role: server | client                         (server)
//     server: the HERM APO `<name>.apo` (default <name>) is offered as the
//             DDS service; client: a proxy APO named <name> calls the DDS
//             service
//   <name>.dds_service: [<namespace>/]<name>   the DDS service (rq/<..>Request, rr/<..>Reply)
//   <name>.timeout_ms: 5000       a call's deadline, either way
//   <name>.domain / reliability / depth / durability as for topics
//
// The defaults are ROS 2's (rclcpp's default QoS profile). <topic> is the
// HERM topic: everything before the option's last dot. Pure; errors are
// ec::invalid_config whose text names the option ("options.sonar.depth:
// expected an integer in [1, 10000], got 'x'"); hermd prefixes file and
// line.

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "caf/expected.hpp"

#include "apps/dds_gateway/ros_services.hpp"
#include "apps/dds_gateway/ros_types.hpp"

namespace herm::dds_gateway {

enum class direction : uint8_t { to_dds, from_dds, both };

struct mapping {
  std::string herm_topic;
  std::string dds_topic;
  const ros_type* type = nullptr;
  direction dir = direction::to_dds;
  uint32_t domain = 0;
  bool reliable = true;
  int32_t depth = 10;
  bool transient_local = false;
  conversion_options conv;
  // -- a service mapping (type is then nullptr) --
  const ros_service* service = nullptr;
  /// Server: HERM APO `apo` offered on DDS; client: DDS service offered to
  /// HERM as the APO `herm_topic`.
  bool server = true;
  std::string apo;
  std::chrono::milliseconds timeout{5000};

  bool to_dds() const {
    return service == nullptr && dir != direction::from_dds;
  }
  bool from_dds() const {
    return service == nullptr && dir != direction::to_dds;
  }
  /// Service topics: dds_topic holds the service's DDS name.
  std::string request_topic() const {
    return "rq/" + dds_topic + "Request";
  }
  std::string reply_topic() const {
    return "rr/" + dds_topic + "Reply";
  }
};

struct gateway_config {
  std::vector<mapping> mappings;
  /// Most DDS samples handed to the gateway actor and not yet handled;
  /// more are dropped and counted (gateway_stats::backlog_dropped).
  uint32_t max_backlog = 1024;
};

/// Most mappings in one gateway.
constexpr size_t max_mappings = 256;

/// Reads `options` (an apo_config's) into a configuration.
caf::expected<gateway_config>
parse_gateway_options(const std::map<std::string, std::string>& options);

} // namespace herm::dds_gateway
