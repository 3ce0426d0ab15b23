// A gateway's options as hermd reads them: ROS 2's defaults, every field,
// and errors that name the option.

#include <gtest/gtest.h>

#include <chrono>

#include "actors/runtime/error.hpp"
#include "apps/dds_gateway/gateway_config.hpp"

using namespace herm::dds_gateway;
using options = std::map<std::string, std::string>;

namespace {

/// The error's text ("" when it parsed).
std::string error_of(const options& o) {
  auto cfg = parse_gateway_options(o);
  if (cfg)
    return "";
  EXPECT_EQ(cfg.error(), herm::ec::invalid_config);
  return herm::render(cfg.error());
}

} // namespace

TEST(gateway_config, a_mapping_needs_only_its_type_and_gets_ros2_defaults) {
  auto cfg = parse_gateway_options({{"sonar.type", "sensor_msgs/msg/Range"}});
  ASSERT_TRUE(cfg) << herm::render(cfg.error());
  ASSERT_EQ(cfg->mappings.size(), 1u);
  auto& m = cfg->mappings[0];
  EXPECT_EQ(m.herm_topic, "sonar");
  EXPECT_EQ(m.dds_topic, "rt/sonar");
  EXPECT_STREQ(m.type->name, "sensor_msgs/msg/Range");
  EXPECT_EQ(m.dir, direction::to_dds);
  EXPECT_EQ(m.domain, 0u);
  EXPECT_TRUE(m.reliable);
  EXPECT_EQ(m.depth, 10);
  EXPECT_FALSE(m.transient_local);
  EXPECT_EQ(m.conv.frame_id, "sonar");
  EXPECT_EQ(m.conv.max_string, 4096u);
  EXPECT_EQ(cfg->max_backlog, 1024u);
}

TEST(gateway_config, every_field_is_read_and_the_gateway_domain_is_the_default) {
  auto cfg = parse_gateway_options({
    {"domain", "42"},
    {"max_string", "100"},
    {"max_backlog", "8"},
    {"robot.cmd_vel.type", "geometry_msgs/msg/Twist"},
    {"robot.cmd_vel.direction", "from_dds"},
    {"robot.cmd_vel.dds_topic", "rt/robot1/cmd_vel"},
    {"robot.cmd_vel.reliability", "best_effort"},
    {"robot.cmd_vel.depth", "1"},
    {"robot.cmd_vel.durability", "transient_local"},
    {"chat.type", "std_msgs/msg/String"},
    {"chat.direction", "both"},
    {"chat.domain", "7"},
    {"sonar.type", "sensor_msgs/msg/Range"},
    {"sonar.frame_id", "front"},
    {"sonar.field_of_view", "0.3"},
    {"sonar.min_range", "0.05"},
    {"sonar.max_range", "2.5"},
  });
  ASSERT_TRUE(cfg) << herm::render(cfg.error());
  ASSERT_EQ(cfg->mappings.size(), 3u);
  EXPECT_EQ(cfg->max_backlog, 8u);
  // In topic order.
  auto& chat = cfg->mappings[0];
  EXPECT_EQ(chat.herm_topic, "chat");
  EXPECT_EQ(chat.dir, direction::both);
  EXPECT_TRUE(chat.to_dds() && chat.from_dds());
  EXPECT_EQ(chat.domain, 7u);
  EXPECT_EQ(chat.conv.max_string, 100u);
  auto& cmd = cfg->mappings[1];
  EXPECT_EQ(cmd.herm_topic, "robot.cmd_vel");
  EXPECT_EQ(cmd.dds_topic, "rt/robot1/cmd_vel");
  EXPECT_EQ(cmd.dir, direction::from_dds);
  EXPECT_FALSE(cmd.to_dds());
  EXPECT_EQ(cmd.domain, 42u);
  EXPECT_FALSE(cmd.reliable);
  EXPECT_EQ(cmd.depth, 1);
  EXPECT_TRUE(cmd.transient_local);
  auto& sonar = cfg->mappings[2];
  EXPECT_EQ(sonar.conv.frame_id, "front");
  EXPECT_FLOAT_EQ(sonar.conv.field_of_view, 0.3f);
  EXPECT_FLOAT_EQ(sonar.conv.min_range, 0.05f);
  EXPECT_FLOAT_EQ(sonar.conv.max_range, 2.5f);
}

TEST(gateway_config, errors_name_the_option_and_what_was_expected) {
  struct {
    options opts;
    const char* text;
  } cases[] = {
    {{{"sonar.direction", "to_dds"}},
     "options.sonar.type: missing: every mapping needs its ROS type"},
    {{{"sonar.type", "sensor_msgs/Range"}},
     "options.sonar.type: expected a shipped ROS type (std_msgs/msg/String"},
    {{{"sonar.type", "sensor_msgs/msg/Range"}, {"sonar.direction", "up"}},
     "options.sonar.direction: expected to_dds, from_dds or both, got 'up'"},
    {{{"sonar.type", "sensor_msgs/msg/Range"}, {"sonar.depth", "0"}},
     "options.sonar.depth: expected an integer in [1, 10000], got '0'"},
    {{{"sonar.type", "sensor_msgs/msg/Range"}, {"sonar.reliability", "maybe"}},
     "options.sonar.reliability: expected reliable or best_effort"},
    {{{"sonar.type", "sensor_msgs/msg/Range"}, {"sonar.durability", "forever"}},
     "options.sonar.durability: expected volatile or transient_local"},
    {{{"sonar.type", "sensor_msgs/msg/Range"}, {"sonar.colour", "red"}},
     "options.sonar.colour: unknown field 'colour'"},
    {{{"domain", "233"}},
     "options.domain: expected an integer in [0, 232], got '233'"},
    {{{"speed", "1"}}, "options.speed: unknown option"},
    {{{"x.type", "std_msgs/msg/Int32"}, {"x.frame_id", "f"}},
     "options.x.frame_id: only a sensor_msgs/msg/Range or Image mapping takes "
     "this field"},
    {{{"v.type", "sensor_msgs/msg/Image"}, {"v.min_range", "1"}},
     "options.v.min_range: only a sensor_msgs/msg/Range mapping takes this field"},
    {{{"max_bytes", "60001"}},
     "options.max_bytes: expected an integer in [1, 60000], got '60001'"},
    {{{"s.type", "sensor_msgs/msg/Range"}, {"s.min_range", "NaN"}},
     "options.s.min_range: expected a number"},
    {{{"s.type", "sensor_msgs/msg/Range"}, {"s.min_range", "3"},
      {"s.max_range", "2"}},
     "options.s.min_range: is above max_range"},
    {{{".type", "std_msgs/msg/Int32"}}, "options..type: expected a HERM topic"},
  };
  for (auto& c : cases) {
    auto text = error_of(c.opts);
    EXPECT_NE(text.find(c.text), std::string::npos)
      << "expected '" << c.text << "' in '" << text << "'";
  }
}

TEST(gateway_config, an_image_mapping_takes_a_frame_id_and_the_byte_bound) {
  auto cfg = parse_gateway_options({{"max_bytes", "4096"},
                                    {"vision.type", "sensor_msgs/msg/Image"},
                                    {"vision.frame_id", "camera_front"}});
  ASSERT_TRUE(cfg) << herm::render(cfg.error());
  ASSERT_EQ(cfg->mappings.size(), 1u);
  auto& m = cfg->mappings[0];
  EXPECT_STREQ(m.type->name, "sensor_msgs/msg/Image");
  EXPECT_EQ(m.dds_topic, "rt/vision");
  EXPECT_EQ(m.conv.frame_id, "camera_front");
  EXPECT_EQ(m.conv.max_bytes, 4096u);
  // Without them: the topic's name and HERM's largest message.
  auto plain = parse_gateway_options({{"vision.type", "sensor_msgs/msg/Image"}});
  ASSERT_TRUE(plain);
  EXPECT_EQ(plain->mappings[0].conv.frame_id, "vision");
  EXPECT_EQ(plain->mappings[0].conv.max_bytes, 60000u);
}

// A fleet on one domain: each robot's gateway names its DDS topics and
// services under its own namespace, as a ROS 2 node in that namespace does.
TEST(gateway_config, a_namespace_prefixes_the_default_dds_names) {
  auto cfg = parse_gateway_options({{"namespace", "/fleet/robot_1"},
                                    {"sonar.type", "sensor_msgs/msg/Range"},
                                    {"cmd.type", "geometry_msgs/msg/Twist"},
                                    {"cmd.dds_topic", "rt/cmd_vel"},
                                    {"add.service", "example_interfaces/srv/AddTwoInts"}});
  ASSERT_TRUE(cfg) << herm::render(cfg.error());
  ASSERT_EQ(cfg->mappings.size(), 3u);
  // In topic order: add, cmd, sonar.
  EXPECT_EQ(cfg->mappings[0].request_topic(), "rq/fleet/robot_1/addRequest");
  EXPECT_EQ(cfg->mappings[0].reply_topic(), "rr/fleet/robot_1/addReply");
  EXPECT_EQ(cfg->mappings[1].dds_topic, "rt/cmd_vel"); // named: as it is
  EXPECT_EQ(cfg->mappings[2].dds_topic, "rt/fleet/robot_1/sonar");
  // The root namespace is no prefix.
  auto root = parse_gateway_options({{"namespace", "/"}, {"s.type", "std_msgs/msg/Int32"}});
  ASSERT_TRUE(root);
  EXPECT_EQ(root->mappings[0].dds_topic, "rt/s");
  for (auto bad : {"1robot", "robot 1", "a//b", "robot-1", "a/2b"})
    EXPECT_NE(error_of({{"namespace", bad}}).find("options.namespace: expected a ROS 2 "
                                                  "namespace"),
              std::string::npos)
      << bad;
}

TEST(gateway_config, mappings_are_bounded) {
  options o;
  for (size_t i = 0; i <= max_mappings; ++i)
    o["t" + std::to_string(i) + ".type"] = "std_msgs/msg/Int32";
  EXPECT_NE(error_of(o).find("more than 256 mappings"), std::string::npos);
  o.erase("t0.type");
  EXPECT_EQ(error_of(o), "");
}

TEST(gateway_config, a_service_mapping_serves_its_namesake_apo_by_default) {
  auto cfg = parse_gateway_options({
    {"add_two_ints.service", "example_interfaces/srv/AddTwoInts"},
    {"calc.service", "example_interfaces/srv/AddTwoInts"},
    {"calc.role", "client"},
    {"calc.dds_service", "robot1/calc"},
    {"calc.timeout_ms", "250"},
    {"sum.service", "example_interfaces/srv/AddTwoInts"},
    {"sum.apo", "adder"},
  });
  ASSERT_TRUE(cfg) << herm::render(cfg.error());
  ASSERT_EQ(cfg->mappings.size(), 3u);
  auto& add = cfg->mappings[0];
  EXPECT_STREQ(add.service->name, "example_interfaces/srv/AddTwoInts");
  EXPECT_EQ(add.type, nullptr);
  EXPECT_TRUE(add.server);
  EXPECT_EQ(add.apo, "add_two_ints");
  EXPECT_EQ(add.request_topic(), "rq/add_two_intsRequest");
  EXPECT_EQ(add.reply_topic(), "rr/add_two_intsReply");
  EXPECT_EQ(add.timeout, std::chrono::milliseconds(5000));
  EXPECT_FALSE(add.to_dds() || add.from_dds()); // no topic of its own
  auto& calc = cfg->mappings[1];
  EXPECT_FALSE(calc.server);
  EXPECT_EQ(calc.request_topic(), "rq/robot1/calcRequest");
  EXPECT_EQ(calc.timeout, std::chrono::milliseconds(250));
  EXPECT_EQ(cfg->mappings[2].apo, "adder");
}

TEST(gateway_config, service_and_topic_fields_do_not_mix) {
  struct {
    options opts;
    const char* text;
  } cases[] = {
    {{{"s.service", "std_srvs/srv/Trigger"}},
     "options.s.service: expected a shipped ROS service type "
     "(example_interfaces/srv/AddTwoInts), got 'std_srvs/srv/Trigger'"},
    {{{"s.service", "example_interfaces/srv/AddTwoInts"}, {"s.role", "both"}},
     "options.s.role: expected server or client, got 'both'"},
    {{{"s.service", "example_interfaces/srv/AddTwoInts"},
      {"s.direction", "both"}},
     "options.s.direction: a service mapping (s.service) takes no topic "
     "fields"},
    {{{"s.service", "example_interfaces/srv/AddTwoInts"}, {"s.role", "client"},
      {"s.apo", "x"}},
     "options.s.apo: only a server mapping serves an APO"},
    {{{"s.type", "std_msgs/msg/Int32"}, {"s.timeout_ms", "5"}},
     "options.s.timeout_ms: only a service mapping (s.service) takes this "
     "field"},
    {{{"s.service", "example_interfaces/srv/AddTwoInts"},
      {"s.timeout_ms", "0"}},
     "options.s.timeout_ms: expected an integer in [1, 3600000], got '0'"},
  };
  for (auto& c : cases) {
    auto text = error_of(c.opts);
    EXPECT_NE(text.find(c.text), std::string::npos)
      << "expected '" << c.text << "' in '" << text << "'";
  }
}
