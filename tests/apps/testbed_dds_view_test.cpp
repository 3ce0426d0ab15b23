// herm-testbed --dds-gateway as pure code: the main controller's gateway
// entry and the judgement of what the DDS reader printed
// (apps/testbed/dds_view.hpp).

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "apps/testbed/dds_view.hpp"

using herm::testbed::dds_gateway_apo;
using herm::testbed::view_dds_reader;

TEST(testbed_dds_view, the_gateway_entry_maps_sonar_and_vision_on_the_domain) {
  EXPECT_EQ(dds_gateway_apo(42), "  - name: gateway      # the DDS / ROS 2 gateway (--dds-gateway)\n"
                                 "    kind: dds_gateway\n"
                                 "    options:\n"
                                 "      domain: 42\n"
                                 "      sonar.type: sensor_msgs/msg/Range\n"
                                 "      sonar.frame_id: srf04\n"
                                 "      vision.type: sensor_msgs/msg/Image\n"
                                 "      vision.frame_id: camera\n");
  EXPECT_NE(dds_gateway_apo(232).find("domain: 232\n"), std::string::npos);
}

TEST(testbed_dds_view, counts_readings_of_the_board_with_the_gateways_frame) {
  std::vector<std::string> lines{
    "subscribed rt/sonar",
    "encoding 00 01",
    "range 0.300 frame srf04 radiation 0 fov 0.262",  // lo, to the millimetre
    "range 2.500 frame srf04 radiation 0 fov 0.262",  // hi
    "range 1.234 frame srf04 radiation 0 fov 0.262",
    "range 2.501 frame srf04 radiation 0 fov 0.262",  // past the obstacle
    "range 1.000 frame other radiation 0 fov 0.262",  // another writer's
    "done ranges 5",
  };
  auto v = view_dds_reader(lines, 300, 2500, 100);
  EXPECT_EQ(v.ranges, 5);
  EXPECT_EQ(v.from_sensor, 3);
  EXPECT_TRUE(v.xcdr1);
  EXPECT_EQ(v.first, lines[2]);
  EXPECT_EQ(v.images, 0);
}

TEST(testbed_dds_view, counts_images_that_are_the_cameras_frames) {
  std::vector<std::string> lines{
    "image 100x1 mono8 frame camera bytes 100 first 1",
    "image 100x1 mono8 frame camera bytes 100 first 2",
    "image 99x1 mono8 frame camera bytes 99 first 3",     // another size
    "image 100x1 rgb8 frame camera bytes 100 first 4",    // another encoding
    "image 100x1 mono8 frame other bytes 100 first 5",    // another writer's
    "image 50x2 mono8 frame camera bytes 100 first 6",    // two rows
  };
  auto v = view_dds_reader(lines, 0, 10000, 100);
  EXPECT_EQ(v.images, 6);
  EXPECT_EQ(v.frames, 2);
  EXPECT_EQ(v.first_image, lines[0]);
  EXPECT_EQ(v.ranges, 0);
}

TEST(testbed_dds_view, another_encoding_or_no_range_is_seen_as_such) {
  auto v = view_dds_reader({"encoding 01 01", "range x frame srf04", "image x",
                            "error reader: x"},
                           0, 10000, 100);
  EXPECT_FALSE(v.xcdr1);
  EXPECT_EQ(v.ranges, 0);
  EXPECT_EQ(v.from_sensor, 0);
  EXPECT_TRUE(v.first.empty());
  EXPECT_EQ(v.images, 0);
}
