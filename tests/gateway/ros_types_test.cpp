// The shipped ROS 2 types and services: their names on the wire
// (rmw_cyclonedds's), and each conversion both ways, bad input refused whole.

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <vector>

#include "apps/dds_gateway/ros_services.hpp"
#include "apps/dds_gateway/ros_types.hpp"
#include "apps/dds_gateway/types.hpp"
#include "channels/error.hpp"

#include "example_interfaces/AddTwoInts.h"
#include "geometry_msgs/Twist.h"
#include "sensor_msgs/Image.h"
#include "sensor_msgs/Range.h"
#include "std_msgs/Basic.h"

using namespace herm::dds_gateway;
using herm::hermd::srf04_reading;
using herm::hermd::vision_frame;

namespace {

const ros_type& type(const char* name) {
  auto* t = find_ros_type(name);
  EXPECT_NE(t, nullptr) << name;
  return *t;
}

template <class Sample>
caf::error to(const char* name, const caf::message& v, Sample& s,
              const conversion_options& o = {}) {
  std::memset(&s, 0, sizeof(s));
  return type(name).to_dds(v, o, 1'700'000'000'123'456'789, &s);
}

template <class T, class Sample>
caf::expected<T> from(const char* name, const Sample& s, uint64_t n = 0,
                      const conversion_options& o = {}) {
  auto m = type(name).from_dds(&s, o, n);
  if (!m)
    return m.error();
  EXPECT_TRUE(m->template match_elements<T>()) << caf::to_string(*m);
  return m->template get_as<T>(0);
}

} // namespace

TEST(ros_types, names_on_dds_are_those_rmw_cyclonedds_registers) {
  struct {
    const char* ros;
    const char* dds;
  } cases[] = {
    {"std_msgs/msg/String", "std_msgs::msg::dds_::String_"},
    {"std_msgs/msg/Float64", "std_msgs::msg::dds_::Float64_"},
    {"std_msgs/msg/Int32", "std_msgs::msg::dds_::Int32_"},
    {"sensor_msgs/msg/Range", "sensor_msgs::msg::dds_::Range_"},
    {"sensor_msgs/msg/Image", "sensor_msgs::msg::dds_::Image_"},
    {"geometry_msgs/msg/Twist", "geometry_msgs::msg::dds_::Twist_"},
  };
  ASSERT_EQ(ros_types().size(), std::size(cases));
  for (auto& c : cases) {
    auto& t = type(c.ros);
    EXPECT_EQ(dds_type_name(c.ros), c.dds);
    // What idlc generated from our IDL says the same.
    EXPECT_STREQ(t.descriptor->m_typename, c.dds);
    EXPECT_EQ(t.sample_size, t.descriptor->m_size);
  }
  EXPECT_EQ(find_ros_type("std_msgs/String"), nullptr);
}

TEST(ros_types, a_sonar_reading_becomes_a_range_in_metres_stamped_now) {
  sensor_msgs_msg_dds__Range_ s;
  conversion_options o;
  o.frame_id = "sonar_front";
  o.field_of_view = 0.5f;
  o.min_range = 0.02f;
  o.max_range = 3.0f;
  auto v = caf::make_message(srf04_reading{7, 1234, 7195});
  ASSERT_FALSE(to("sensor_msgs/msg/Range", v, s, o));
  EXPECT_FLOAT_EQ(s.range, 1.234f);
  EXPECT_EQ(s.radiation_type, 0); // ULTRASOUND
  EXPECT_FLOAT_EQ(s.field_of_view, 0.5f);
  EXPECT_FLOAT_EQ(s.min_range, 0.02f);
  EXPECT_FLOAT_EQ(s.max_range, 3.0f);
  EXPECT_STREQ(s.header.frame_id, "sonar_front");
  EXPECT_EQ(s.header.stamp.sec, 1'700'000'000);
  EXPECT_EQ(s.header.stamp.nanosec, 123'456'789u);
}

TEST(ros_types, nothing_in_range_is_plus_infinity_both_ways) {
  sensor_msgs_msg_dds__Range_ s;
  auto v = caf::make_message(
    srf04_reading{1, herm::hermd::srf04_out_of_range, 30000});
  // The sample borrows its frame_id from the options: they outlive it.
  conversion_options o;
  ASSERT_FALSE(to("sensor_msgs/msg/Range", v, s, o));
  EXPECT_TRUE(std::isinf(s.range) && s.range > 0);
  auto back = from<srf04_reading>("sensor_msgs/msg/Range", s, 0, o);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->distance_mm, herm::hermd::srf04_out_of_range);
}

TEST(ros_types, a_range_from_dds_becomes_a_reading_in_mm_numbered_by_count) {
  sensor_msgs_msg_dds__Range_ s{};
  s.range = 0.5f;
  auto r = from<srf04_reading>("sensor_msgs/msg/Range", s, 70000);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->distance_mm, 500);
  EXPECT_EQ(r->echo_us, 500u * 2000 / 343);
  EXPECT_EQ(r->seq, 70000 % 65536);
}

TEST(ros_types, a_range_that_is_no_distance_is_refused_whole) {
  const float bad[] = {std::numeric_limits<float>::quiet_NaN(),
                       -std::numeric_limits<float>::infinity(), -0.01f,
                       65.535f, 1e9f};
  for (auto x : bad) {
    sensor_msgs_msg_dds__Range_ s{};
    s.range = x;
    auto r = from<srf04_reading>("sensor_msgs/msg/Range", s);
    ASSERT_FALSE(r) << x;
    EXPECT_EQ(r.error(), herm::ec::invalid_parameter) << x;
  }
}

TEST(ros_types, strings_over_the_bound_are_refused_both_ways) {
  conversion_options o;
  o.max_string = 8;
  std_msgs_msg_dds__String_ s;
  // The sample borrows the string from the value: it outlives the sample.
  auto eight = caf::make_message(std::string{"12345678"});
  ASSERT_FALSE(to("std_msgs/msg/String", eight, s, o));
  EXPECT_STREQ(s.data, "12345678");
  EXPECT_TRUE(to("std_msgs/msg/String",
                 caf::make_message(std::string{"123456789"}), s, o));
  EXPECT_TRUE(to("std_msgs/msg/String",
                 caf::make_message(std::string{"a\0b", 3}), s, o));
  std::string nine = "123456789";
  std_msgs_msg_dds__String_ in{nine.data()};
  EXPECT_FALSE((from<std::string>("std_msgs/msg/String", in, 0, o)));
  nine.pop_back();
  auto ok = from<std::string>("std_msgs/msg/String", in, 0, o);
  ASSERT_TRUE(ok);
  EXPECT_EQ(*ok, "12345678");
  // A range's frame id is bounded the same way.
  sensor_msgs_msg_dds__Range_ r{};
  r.header.frame_id = const_cast<char*>("a_long_frame");
  EXPECT_FALSE((from<srf04_reading>("sensor_msgs/msg/Range", r, 0, o)));
}

TEST(ros_types, numbers_and_twists_round_trip) {
  std_msgs_msg_dds__Float64_ f;
  ASSERT_FALSE(to("std_msgs/msg/Float64", caf::make_message(2.5), f));
  EXPECT_EQ(*from<double>("std_msgs/msg/Float64", f), 2.5);
  std_msgs_msg_dds__Int32_ i;
  ASSERT_FALSE(to("std_msgs/msg/Int32", caf::make_message(int32_t{-42}), i));
  EXPECT_EQ(*from<int32_t>("std_msgs/msg/Int32", i), -42);
  geometry_msgs_msg_dds__Twist_ t;
  twist cmd{{0.5, 0, 0}, {0, 0, -0.25}};
  ASSERT_FALSE(to("geometry_msgs/msg/Twist", caf::make_message(cmd), t));
  EXPECT_EQ(t.linear.x, 0.5);
  EXPECT_EQ(t.angular.z, -0.25);
  auto back = from<twist>("geometry_msgs/msg/Twist", t);
  ASSERT_TRUE(back);
  EXPECT_EQ(*back, cmd);
}

TEST(ros_types, a_twist_with_nan_or_inf_is_refused) {
  geometry_msgs_msg_dds__Twist_ t{};
  t.angular.z = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE((from<twist>("geometry_msgs/msg/Twist", t)));
  t.angular.z = 0;
  t.linear.y = std::numeric_limits<double>::infinity();
  EXPECT_FALSE((from<twist>("geometry_msgs/msg/Twist", t)));
}

TEST(ros_types, a_vision_frame_is_one_mono8_row_of_its_bytes_borrowed) {
  sensor_msgs_msg_dds__Image_ s;
  conversion_options o;
  o.frame_id = "camera";
  auto v = caf::make_message(vision_frame{"cam0", 9, {1, 2, 3, 250}});
  ASSERT_FALSE(to("sensor_msgs/msg/Image", v, s, o));
  EXPECT_EQ(s.height, 1u);
  EXPECT_EQ(s.width, 4u);
  EXPECT_EQ(s.step, 4u);
  EXPECT_STREQ(s.encoding, "mono8");
  EXPECT_EQ(s.is_bigendian, 0);
  EXPECT_STREQ(s.header.frame_id, "camera");
  EXPECT_EQ(s.header.stamp.sec, 1'700'000'000);
  ASSERT_EQ(s.data._length, 4u);
  EXPECT_FALSE(s.data._release);
  // Borrowed: the sample points into the value.
  EXPECT_EQ(s.data._buffer, v.get_as<vision_frame>(0).data.data());
  auto back = from<vision_frame>("sensor_msgs/msg/Image", s, 12);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->source, "camera");
  EXPECT_EQ(back->seq, 12u);
  EXPECT_EQ(back->data, (std::vector<uint8_t>{1, 2, 3, 250}));
}

TEST(ros_types, an_image_from_dds_loses_its_row_padding) {
  // 2 rows of 3 pixels, 4 bytes a row.
  std::vector<uint8_t> px{1, 2, 3, 0, 4, 5, 6, 0};
  sensor_msgs_msg_dds__Image_ s{};
  s.height = 2;
  s.width = 3;
  s.step = 4;
  s.encoding = const_cast<char*>("8UC1");
  s.data = {static_cast<uint32_t>(px.size()), static_cast<uint32_t>(px.size()),
            px.data(), false};
  auto f = from<vision_frame>("sensor_msgs/msg/Image", s);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->data, (std::vector<uint8_t>{1, 2, 3, 4, 5, 6}));
}

TEST(ros_types, an_image_that_is_no_frame_is_refused_whole) {
  std::vector<uint8_t> px(12, 7);
  auto image = [&](const char* enc, uint32_t h, uint32_t w, uint32_t step,
                   uint32_t len) {
    sensor_msgs_msg_dds__Image_ s{};
    s.height = h;
    s.width = w;
    s.step = step;
    s.encoding = const_cast<char*>(enc);
    s.data = {len, len, px.data(), false};
    return s;
  };
  conversion_options o;
  o.max_bytes = 8;
  struct {
    sensor_msgs_msg_dds__Image_ s;
    const char* why;
  } cases[] = {
    {image("rgb8", 1, 4, 12, 12), "encoding 'rgb8'"},
    {image("mono8", 2, 4, 3, 6), "step (3) is below its width (4)"},
    {image("mono8", 2, 4, 4, 12), "2 rows of 4 bytes with 12 bytes"},
    {image("mono8", 3, 4, 4, 12), "12 pixels, over 8"},
  };
  for (auto& c : cases) {
    auto f = from<vision_frame>("sensor_msgs/msg/Image", c.s, 0, o);
    ASSERT_FALSE(f) << c.why;
    EXPECT_NE(herm::render(f.error()).find(c.why), std::string::npos)
      << herm::render(f.error());
  }
  // A frame over the bound is not sent either.
  sensor_msgs_msg_dds__Image_ out;
  EXPECT_TRUE(to("sensor_msgs/msg/Image",
                 caf::make_message(vision_frame{"c", 1, std::vector<uint8_t>(9)}),
                 out, o));
}

TEST(ros_types, a_herm_value_of_another_type_is_refused) {
  std_msgs_msg_dds__Int32_ i;
  auto err = to("std_msgs/msg/Int32", caf::make_message(2.5), i);
  EXPECT_EQ(err, herm::ec::invalid_parameter);
  sensor_msgs_msg_dds__Range_ r;
  EXPECT_TRUE(to("sensor_msgs/msg/Range", caf::make_message(std::string{"x"}), r));
  geometry_msgs_msg_dds__Twist_ t;
  EXPECT_TRUE(to("geometry_msgs/msg/Twist",
                 caf::make_message(twist{}, twist{}), t));
}

// -- services --------------------------------------------------------------------

TEST(ros_services, add_two_ints_travels_as_rmw_cyclonedds_lays_it_out) {
  auto* s = find_ros_service("example_interfaces/srv/AddTwoInts");
  ASSERT_NE(s, nullptr);
  EXPECT_STREQ(s->request_descriptor->m_typename,
               "example_interfaces::srv::dds_::AddTwoInts_Request_");
  EXPECT_STREQ(s->reply_descriptor->m_typename,
               "example_interfaces::srv::dds_::AddTwoInts_Response_");
  // The request header (two 64-bit words) comes first.
  example_interfaces_srv_dds__AddTwoInts_Request_ rq{};
  EXPECT_EQ(offsetof(example_interfaces_srv_dds__AddTwoInts_Request_, a), 16u);
  ASSERT_FALSE(s->request_to_dds(caf::make_message(int64_t{2}, int64_t{3}),
                                 request_header{0xABCD, 7}, &rq));
  EXPECT_EQ(rq.header.guid, 0xABCDu);
  EXPECT_EQ(rq.header.seq, 7);
  request_header h;
  auto req = s->request_from_dds(&rq, h);
  ASSERT_TRUE(req);
  EXPECT_EQ(h.guid, 0xABCDu);
  EXPECT_EQ(h.seq, 7);
  EXPECT_TRUE((req->match_elements<int64_t, int64_t>()));
  example_interfaces_srv_dds__AddTwoInts_Response_ rr{};
  ASSERT_FALSE(s->reply_to_dds(caf::make_message(int64_t{5}), h, &rr));
  EXPECT_EQ(rr.sum, 5);
  EXPECT_EQ(rr.header.seq, 7); // the reply repeats its request's header
  request_header back;
  auto resp = s->reply_from_dds(&rr, back);
  ASSERT_TRUE(resp);
  EXPECT_EQ(back.guid, 0xABCDu);
  EXPECT_EQ(resp->get_as<int64_t>(0), 5);
}

TEST(ros_services, herm_messages_of_other_types_are_refused) {
  auto* s = find_ros_service("example_interfaces/srv/AddTwoInts");
  ASSERT_NE(s, nullptr);
  example_interfaces_srv_dds__AddTwoInts_Request_ rq{};
  EXPECT_EQ(s->request_to_dds(caf::make_message(int32_t{2}, int32_t{3}), {}, &rq),
            herm::ec::invalid_parameter);
  example_interfaces_srv_dds__AddTwoInts_Response_ rr{};
  EXPECT_EQ(s->reply_to_dds(caf::make_message(std::string{"5"}), {}, &rr),
            herm::ec::invalid_parameter);
  EXPECT_EQ(find_ros_service("example_interfaces/srv/AddThreeInts"), nullptr);
}
