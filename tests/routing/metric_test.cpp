// Module ids, size classes and per-class link metrics.

#include <gtest/gtest.h>

#include "routing/metric.hpp"
#include "routing/module_id.hpp"

using namespace herm;

TEST(module_id, prints_and_parses_hex_like_the_paper) {
  EXPECT_EQ(to_hex(0x42), "0x42");
  EXPECT_EQ(to_hex(0x4E), "0x4E");
  EXPECT_EQ(to_hex(0x1234), "0x1234");
  EXPECT_EQ(parse_module_id("0x4E"), module_id{0x4E});
  EXPECT_EQ(parse_module_id("0X4e"), module_id{0x4E});
  EXPECT_EQ(parse_module_id("78"), module_id{78});
  EXPECT_EQ(parse_module_id("0x10000"), std::nullopt);
  EXPECT_EQ(parse_module_id("0x"), std::nullopt);
  EXPECT_EQ(parse_module_id("4E"), std::nullopt);
  EXPECT_EQ(parse_module_id(""), std::nullopt);
  EXPECT_EQ(parse_module_id("-1"), std::nullopt);
}

TEST(module_id, static_pool_gives_the_main_controller_0x4E) {
  EXPECT_EQ(static_pool(module_category::main_controller).first, 0x4E);
  for (auto name : {"main_controller", "left_arm", "right_arm", "vision",
                    "sensor", "mobile", "manipulator", "power", "other"}) {
    SCOPED_TRACE(name);
    auto cat = parse_module_category(name);
    ASSERT_TRUE(cat);
    EXPECT_STREQ(to_string(*cat), name);
    auto r = static_pool(*cat);
    EXPECT_LE(r.first, r.last);
    EXPECT_LT(r.last, first_dynamic_module);
    EXPECT_TRUE(is_unicast(r.first));
  }
  EXPECT_FALSE(parse_module_category("tail"));
}

TEST(metric, size_classes_cover_every_size) {
  EXPECT_EQ(size_class_of(0), 0);
  EXPECT_EQ(size_class_of(8), 0);
  EXPECT_EQ(size_class_of(9), 1);
  EXPECT_EQ(size_class_of(1000), 2);
  EXPECT_EQ(size_class_of(1024), 2);
  EXPECT_EQ(size_class_of(1025), 3);
  EXPECT_EQ(size_class_of(1'000'000), 3);
}

TEST(metric, class_0_reproduces_table_1_costs) {
  const std::pair<const char*, metric> table1[] = {
    {"usb1.1", 19}, {"usb2.0", 3}, {"ieee1394a", 4}, {"ieee1394b", 1},
    {"can2.0", 30}, {"ethernet", 10}, {"rs232c", 47}};
  for (auto& [name, cost] : table1) {
    SCOPED_TRACE(name);
    EXPECT_EQ(link_metrics(*find_profile(name))[0], cost);
  }
}

TEST(metric, larger_classes_multiply_by_frames_of_the_mtu) {
  auto can = link_metrics(*find_profile("can2.0"));
  auto eth = link_metrics(*find_profile("ethernet"));
  auto rs = link_metrics(*find_profile("rs232c"));
  EXPECT_EQ(can, (metric_vector{30, 240, 3840, 245760}));
  EXPECT_EQ(eth, (metric_vector{10, 10, 10, 440}));
  EXPECT_EQ(rs, (metric_vector{47, 94, 1504, 96256}));
  // A 1,000-byte message: two Ethernet hops beat one CAN hop.
  auto k = size_class_of(1000);
  EXPECT_LT(add_metric(eth[k], eth[k]), can[k]);
  // An 8-byte one: one CAN hop (30) beats Ethernet + RS232C (57).
  EXPECT_LT(can[0], add_metric(eth[0], rs[0]));
}

TEST(metric, addition_saturates_at_infinity) {
  EXPECT_EQ(add_metric(infinite_metric, 1), infinite_metric);
  EXPECT_EQ(add_metric(1, infinite_metric), infinite_metric);
  EXPECT_EQ(add_metric(0xFFFFFFF0, 0x20), infinite_metric);
  EXPECT_EQ(add_metric(8, 10), 18u);
}

TEST(metric, link_codes_spell_the_paper_forwarding_list) {
  EXPECT_EQ(link_code_of("can2.0"), link_code::can20);
  EXPECT_STREQ(to_string(link_code::can20), "CAN2.0");
  EXPECT_STREQ(to_string(link_code::ethernet), "Ethernet");
  EXPECT_EQ(link_code_of("token-ring"), link_code::unknown);
  EXPECT_STREQ(to_string(link_code::unknown), "?");
}
