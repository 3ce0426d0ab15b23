#include "apps/dds_gateway/gateway_config.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "actors/runtime/error.hpp"

namespace herm::dds_gateway {

namespace {

caf::error fail(const std::string& key, const std::string& what) {
  return make_error(ec::invalid_config, "options." + key + ": " + what);
}

caf::error integer(const std::string& key, const std::string& text,
                   uint64_t min, uint64_t max, uint64_t& out) {
  char* end = nullptr;
  errno = 0;
  auto v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || *end != '\0' || errno != 0 || v < min
      || v > max)
    return fail(key, "expected an integer in [" + std::to_string(min) + ", "
                       + std::to_string(max) + "], got '" + text + "'");
  out = v;
  return caf::none;
}

caf::error number(const std::string& key, const std::string& text, float min,
                  float max, float& out) {
  char* end = nullptr;
  auto v = std::strtof(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(v) || v < min || v > max)
    return fail(key, "expected a number in [" + std::to_string(min) + ", "
                       + std::to_string(max) + "], got '" + text + "'");
  out = v;
  return caf::none;
}

std::string known_types() {
  std::string out;
  for (auto& t : ros_types())
    out += (out.empty() ? "" : ", ") + std::string{t.name};
  return out;
}

constexpr uint64_t max_domain = 232; // DDSI's port mapping allows 0..232

/// A ROS 2 namespace ("robot1", "/fleet/robot1") as the prefix of DDS
/// names ("fleet/robot1/"): tokens of letters, digits and '_', not starting
/// with a digit, joined by '/'; "" and "/" are the root (no prefix).
caf::error parse_namespace(const std::string& key, const std::string& v,
                           std::string& prefix) {
  auto ns = v;
  if (!ns.empty() && ns.front() == '/')
    ns.erase(0, 1);
  if (!ns.empty() && ns.back() == '/')
    ns.pop_back();
  if (ns.size() > 200)
    return fail(key, "expected a namespace of at most 200 bytes");
  bool start = true;
  for (auto c : ns) {
    bool letter = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_';
    bool digit = c >= '0' && c <= '9';
    if (c == '/' && !start) {
      start = true;
      continue;
    }
    if (!letter && !(digit && !start))
      return fail(key, "expected a ROS 2 namespace (tokens of letters, digits "
                       "and '_', not starting with a digit, joined by '/'), "
                       "got '" + v + "'");
    start = false;
  }
  if (start && !ns.empty())
    return fail(key, "expected a ROS 2 namespace, got '" + v
                       + "' (an empty token)");
  prefix = ns.empty() ? "" : ns + "/";
  return caf::none;
}

/// One `<topic>.<field>` option into `m`.
caf::error field(mapping& m, const std::string& key, const std::string& f,
                 const std::string& v) {
  if (f == "type") {
    m.type = find_ros_type(v);
    if (m.type == nullptr)
      return fail(key, "expected a shipped ROS type (" + known_types()
                         + "), got '" + v + "'");
  } else if (f == "direction") {
    if (v == "to_dds")
      m.dir = direction::to_dds;
    else if (v == "from_dds")
      m.dir = direction::from_dds;
    else if (v == "both")
      m.dir = direction::both;
    else
      return fail(key, "expected to_dds, from_dds or both, got '" + v + "'");
  } else if (f == "dds_topic") {
    if (v.empty() || v.size() > 255)
      return fail(key, "expected a DDS topic name of 1 to 255 bytes");
    m.dds_topic = v;
  } else if (f == "domain") {
    uint64_t d = 0;
    if (auto err = integer(key, v, 0, max_domain, d))
      return err;
    m.domain = static_cast<uint32_t>(d);
  } else if (f == "reliability") {
    if (v != "reliable" && v != "best_effort")
      return fail(key, "expected reliable or best_effort, got '" + v + "'");
    m.reliable = v == "reliable";
  } else if (f == "depth") {
    uint64_t d = 0;
    if (auto err = integer(key, v, 1, 10000, d))
      return err;
    m.depth = static_cast<int32_t>(d);
  } else if (f == "durability") {
    if (v != "volatile" && v != "transient_local")
      return fail(key, "expected volatile or transient_local, got '" + v + "'");
    m.transient_local = v == "transient_local";
  } else if (f == "service") {
    m.service = find_ros_service(v);
    if (m.service == nullptr) {
      std::string known;
      for (auto& x : ros_services())
        known += (known.empty() ? "" : ", ") + std::string{x.name};
      return fail(key, "expected a shipped ROS service type (" + known
                         + "), got '" + v + "'");
    }
  } else if (f == "role") {
    if (v != "server" && v != "client")
      return fail(key, "expected server or client, got '" + v + "'");
    m.server = v == "server";
  } else if (f == "apo") {
    if (v.empty() || v.size() > 255)
      return fail(key, "expected an APO name of 1 to 255 bytes");
    m.apo = v;
  } else if (f == "dds_service") {
    if (v.empty() || v.size() > 240)
      return fail(key, "expected a DDS service name of 1 to 240 bytes");
    m.dds_topic = v;
  } else if (f == "timeout_ms") {
    uint64_t ms = 0;
    if (auto err = integer(key, v, 1, 3'600'000, ms))
      return err;
    m.timeout = std::chrono::milliseconds(ms);
  } else if (f == "frame_id") {
    if (v.size() > 255)
      return fail(key, "expected a frame id of at most 255 bytes");
    m.conv.frame_id = v;
  } else if (f == "field_of_view") {
    return number(key, v, 0, 6.2832f, m.conv.field_of_view);
  } else if (f == "min_range") {
    return number(key, v, 0, 65.534f, m.conv.min_range);
  } else if (f == "max_range") {
    return number(key, v, 0, 65.534f, m.conv.max_range);
  } else {
    return fail(key, "unknown field '" + f
                       + "' (expected type, direction, dds_topic, domain, "
                         "reliability, depth, durability, frame_id, "
                         "field_of_view, min_range, max_range; for a service: "
                         "service, role, apo, dds_service, timeout_ms)");
  }
  return caf::none;
}

bool is_type(const mapping& m, const char* ros_name) {
  return m.type != nullptr && std::string{m.type->name} == ros_name;
}

} // namespace

caf::expected<gateway_config>
parse_gateway_options(const std::map<std::string, std::string>& options) {
  gateway_config cfg;
  uint64_t domain = 0;
  uint64_t max_string = 4096;
  uint64_t max_bytes = 60000;
  uint64_t backlog = cfg.max_backlog;
  std::string ns; // "robot1/": the prefix of default DDS names
  // Gateway-wide options first: every mapping starts from them.
  for (auto& [key, v] : options) {
    if (key.find('.') != std::string::npos)
      continue;
    caf::error err;
    if (key == "domain")
      err = integer(key, v, 0, max_domain, domain);
    else if (key == "max_string")
      err = integer(key, v, 1, 60000, max_string);
    else if (key == "max_bytes")
      err = integer(key, v, 1, 60000, max_bytes);
    else if (key == "max_backlog")
      err = integer(key, v, 1, 1000000, backlog);
    else if (key == "namespace")
      err = parse_namespace(key, v, ns);
    else
      err = fail(key, "unknown option (expected domain, namespace, "
                      "max_string, max_bytes, max_backlog or "
                      "<topic>.<field>)");
    if (err)
      return err;
  }
  cfg.max_backlog = static_cast<uint32_t>(backlog);
  // Then one mapping per topic, fields in key order (std::map).
  std::map<std::string, mapping> by_topic;
  // Which option keys each mapping used, to refuse mixed kinds.
  std::map<std::string, std::vector<std::string>> header_fields;
  std::map<std::string, std::vector<std::string>> range_fields;
  std::map<std::string, std::vector<std::string>> topic_fields;
  std::map<std::string, std::vector<std::string>> service_fields;
  for (auto& [key, v] : options) {
    auto dot = key.rfind('.');
    if (dot == std::string::npos)
      continue;
    auto topic = key.substr(0, dot);
    auto f = key.substr(dot + 1);
    if (topic.empty() || topic.size() > 255)
      return fail(key, "expected a HERM topic of 1 to 255 bytes before '."
                         + f + "'");
    auto i = by_topic.find(topic);
    if (i == by_topic.end()) {
      if (by_topic.size() >= max_mappings)
        return fail(key, "more than " + std::to_string(max_mappings)
                           + " mappings");
      mapping m;
      m.herm_topic = topic;
      m.dds_topic = "rt/" + ns + topic;
      m.domain = static_cast<uint32_t>(domain);
      m.conv.max_string = max_string;
      m.conv.max_bytes = max_bytes;
      m.conv.frame_id = topic;
      i = by_topic.emplace(topic, std::move(m)).first;
    }
    if (auto err = field(i->second, key, f, v))
      return err;
    if (f == "frame_id")
      header_fields[topic].push_back(key);
    else if (f == "field_of_view" || f == "min_range" || f == "max_range")
      range_fields[topic].push_back(key);
    else if (f == "type" || f == "direction" || f == "dds_topic")
      topic_fields[topic].push_back(key);
    else if (f == "role" || f == "apo" || f == "dds_service"
             || f == "timeout_ms")
      service_fields[topic].push_back(key);
  }
  for (auto& [topic, m] : by_topic) {
    if (m.service != nullptr) {
      if (topic_fields.count(topic) > 0)
        return fail(topic_fields[topic].front(),
                    "a service mapping (" + topic + ".service) takes no topic "
                    "fields (type, direction, dds_topic)");
      if (header_fields.count(topic) > 0)
        return fail(header_fields[topic].front(),
                    "only a sensor_msgs/msg/Range or Image mapping takes "
                    "this field");
      if (range_fields.count(topic) > 0)
        return fail(range_fields[topic].front(),
                    "only a sensor_msgs/msg/Range mapping takes this field");
      if (!m.server && !m.apo.empty())
        return fail(topic + ".apo", "only a server mapping serves an APO");
      if (m.dds_topic == "rt/" + ns + topic)
        m.dds_topic = ns + topic;
      if (m.apo.empty())
        m.apo = topic;
      cfg.mappings.push_back(std::move(m));
      continue;
    }
    if (service_fields.count(topic) > 0)
      return fail(service_fields[topic].front(),
                  "only a service mapping (" + topic + ".service) takes this "
                  "field");
    if (m.type == nullptr)
      return fail(topic + ".type", "missing: every mapping needs its ROS type ("
                                     + known_types() + ") or service");
    bool range = is_type(m, "sensor_msgs/msg/Range");
    if (!range && !is_type(m, "sensor_msgs/msg/Image")
        && header_fields.count(topic) > 0)
      return fail(header_fields[topic].front(),
                  "only a sensor_msgs/msg/Range or Image mapping takes this "
                  "field");
    if (!range && range_fields.count(topic) > 0)
      return fail(range_fields[topic].front(),
                  "only a sensor_msgs/msg/Range mapping takes this field");
    if (m.conv.min_range > m.conv.max_range)
      return fail(topic + ".min_range", "is above max_range");
    cfg.mappings.push_back(std::move(m));
  }
  return cfg;
}

} // namespace herm::dds_gateway
