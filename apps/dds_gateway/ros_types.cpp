#include "apps/dds_gateway/ros_types.hpp"

#include <cmath>
#include <cstring>
#include <limits>

#include "actors/runtime/error.hpp"
#include "apps/dds_gateway/types.hpp"
#include "apps/hermd/srf04.hpp"
#include "apps/hermd/testbed_types.hpp"

#include "geometry_msgs/Twist.h"
#include "sensor_msgs/Image.h"
#include "sensor_msgs/Range.h"
#include "std_msgs/Basic.h"

namespace herm::dds_gateway {

namespace {

caf::error bad(std::string what) {
  return make_error(ec::invalid_parameter, std::move(what));
}

template <class T>
caf::error expect_type(const caf::message& value, const char* herm_type) {
  if (value.match_elements<T>())
    return caf::none;
  return bad(std::string{"expected a "} + herm_type + ", got "
             + caf::to_string(value));
}

/// A string from DDS: refused over the bound (a null is an empty one).
caf::expected<std::string> take_string(const char* s, size_t max) {
  if (s == nullptr)
    return std::string{};
  auto n = ::strnlen(s, max + 1);
  if (n > max)
    return bad("a string over " + std::to_string(max) + " bytes");
  return std::string{s, n};
}

/// A header stamped `now` (ns since the epoch) with the mapping's frame_id
/// (borrowed).
void stamp(std_msgs_msg_dds__Header_& h, const conversion_options& o,
           dds_time_t now) {
  h.stamp.sec = static_cast<int32_t>(now / DDS_NSECS_IN_SEC);
  h.stamp.nanosec = static_cast<uint32_t>(now % DDS_NSECS_IN_SEC);
  h.frame_id = const_cast<char*>(o.frame_id.c_str());
}

// -- std_msgs/String <-> std::string -------------------------------------------

caf::error string_to(const caf::message& v, const conversion_options& o,
                     dds_time_t, void* sample) {
  if (auto err = expect_type<std::string>(v, "std::string"))
    return err;
  auto& s = v.get_as<std::string>(0);
  if (s.size() > o.max_string)
    return bad("a string of " + std::to_string(s.size()) + " bytes, over "
               + std::to_string(o.max_string));
  if (std::memchr(s.data(), '\0', s.size()) != nullptr)
    return bad("a string with a NUL byte (a DDS string ends at the first)");
  static_cast<std_msgs_msg_dds__String_*>(sample)->data
    = const_cast<char*>(s.c_str());
  return caf::none;
}

caf::expected<caf::message> string_from(const void* sample,
                                        const conversion_options& o,
                                        uint64_t) {
  auto s = take_string(
    static_cast<const std_msgs_msg_dds__String_*>(sample)->data, o.max_string);
  if (!s)
    return s.error();
  return caf::make_message(std::move(*s));
}

// -- std_msgs/Float64 <-> double, Int32 <-> int32_t --------------------------------

caf::error float64_to(const caf::message& v, const conversion_options&,
                      dds_time_t, void* sample) {
  if (auto err = expect_type<double>(v, "double"))
    return err;
  static_cast<std_msgs_msg_dds__Float64_*>(sample)->data = v.get_as<double>(0);
  return caf::none;
}

caf::expected<caf::message> float64_from(const void* sample,
                                         const conversion_options&, uint64_t) {
  // Any double is a Float64, NaN included (std_msgs gives it no meaning).
  return caf::make_message(
    static_cast<const std_msgs_msg_dds__Float64_*>(sample)->data);
}

caf::error int32_to(const caf::message& v, const conversion_options&,
                    dds_time_t, void* sample) {
  if (auto err = expect_type<int32_t>(v, "int32_t"))
    return err;
  static_cast<std_msgs_msg_dds__Int32_*>(sample)->data = v.get_as<int32_t>(0);
  return caf::none;
}

caf::expected<caf::message> int32_from(const void* sample,
                                       const conversion_options&, uint64_t) {
  return caf::make_message(
    static_cast<const std_msgs_msg_dds__Int32_*>(sample)->data);
}

// -- sensor_msgs/Range <-> srf04_reading ---------------------------------------------

constexpr uint8_t ultrasound = 0; // sensor_msgs/Range ULTRASOUND

/// REP 117: +Inf is "nothing detected within range", which is what an
/// SRF04 says with srf04_out_of_range.
caf::error range_to(const caf::message& v, const conversion_options& o,
                    dds_time_t now, void* sample) {
  if (auto err = expect_type<hermd::srf04_reading>(v, "herm.srf04_reading"))
    return err;
  auto& r = v.get_as<hermd::srf04_reading>(0);
  auto* s = static_cast<sensor_msgs_msg_dds__Range_*>(sample);
  stamp(s->header, o, now);
  s->radiation_type = ultrasound;
  s->field_of_view = o.field_of_view;
  s->min_range = o.min_range;
  s->max_range = o.max_range;
  s->range = r.distance_mm == hermd::srf04_out_of_range
               ? std::numeric_limits<float>::infinity()
               : static_cast<float>(r.distance_mm) / 1000.0f;
  return caf::none;
}

/// A distance in metres to whole mm, +Inf to srf04_out_of_range; NaN,
/// -Inf ("too close", no distance to give), negative distances and ones an
/// srf04_reading cannot hold (65.535 m and over) are refused.
caf::expected<caf::message> range_from(const void* sample,
                                       const conversion_options& o,
                                       uint64_t count) {
  auto* s = static_cast<const sensor_msgs_msg_dds__Range_*>(sample);
  if (auto frame = take_string(s->header.frame_id, o.max_string); !frame)
    return frame.error();
  hermd::srf04_reading r;
  r.seq = static_cast<uint16_t>(count);
  if (std::isnan(s->range))
    return bad("a range that is NaN");
  if (std::isinf(s->range)) {
    if (s->range < 0)
      return bad("a range of -Inf (too close to measure)");
    r.distance_mm = hermd::srf04_out_of_range;
    return caf::make_message(r);
  }
  auto mm = std::lround(static_cast<double>(s->range) * 1000.0);
  if (mm < 0 || mm >= hermd::srf04_out_of_range)
    return bad("a range of " + std::to_string(s->range)
               + " m, outside [0, 65.534] m");
  r.distance_mm = static_cast<uint16_t>(mm);
  r.echo_us = static_cast<uint32_t>(mm * 2000 / 343);
  return caf::make_message(r);
}

// -- sensor_msgs/Image <-> vision_frame ----------------------------------------------

/// The encoding of a vision frame's bytes: one row of 8-bit grey values.
constexpr const char* mono8 = "mono8";

/// A frame's bytes as one mono8 row (height 1, width = step = its size);
/// the data is borrowed, not copied.
caf::error image_to(const caf::message& v, const conversion_options& o,
                    dds_time_t now, void* sample) {
  if (auto err = expect_type<hermd::vision_frame>(v, "herm.vision_frame"))
    return err;
  auto& f = v.get_as<hermd::vision_frame>(0);
  if (f.data.size() > o.max_bytes)
    return bad("a frame of " + std::to_string(f.data.size()) + " bytes, over "
               + std::to_string(o.max_bytes));
  auto* s = static_cast<sensor_msgs_msg_dds__Image_*>(sample);
  stamp(s->header, o, now);
  auto n = static_cast<uint32_t>(f.data.size());
  s->height = n > 0 ? 1 : 0;
  s->width = n;
  s->step = n;
  s->encoding = const_cast<char*>(mono8);
  s->is_bigendian = 0;
  s->data._maximum = n;
  s->data._length = n;
  s->data._buffer = const_cast<uint8_t*>(f.data.data());
  s->data._release = false;
  return caf::none;
}

/// An 8-bit single-channel image (mono8 or 8UC1) to a frame of its pixels,
/// row after row without the rows' padding (step - width), `source` its
/// frame_id, `seq` the count. Other encodings, a step below the width, data
/// that is not height x step bytes and more than max_bytes of pixels are
/// refused.
caf::expected<caf::message> image_from(const void* sample,
                                       const conversion_options& o,
                                       uint64_t count) {
  auto* s = static_cast<const sensor_msgs_msg_dds__Image_*>(sample);
  auto frame = take_string(s->header.frame_id, o.max_string);
  if (!frame)
    return frame.error();
  auto enc = take_string(s->encoding, 64);
  if (!enc)
    return enc.error();
  if (*enc != mono8 && *enc != "8UC1")
    return bad("an image of encoding '" + *enc
               + "' (only mono8 and 8UC1 map to a vision frame)");
  if (s->step < s->width)
    return bad("an image whose step (" + std::to_string(s->step)
               + ") is below its width (" + std::to_string(s->width) + ")");
  auto rows = uint64_t{s->height};
  if (rows * s->step != s->data._length
      || (s->data._length > 0 && s->data._buffer == nullptr))
    return bad("an image of " + std::to_string(s->height) + " rows of "
               + std::to_string(s->step) + " bytes with "
               + std::to_string(s->data._length) + " bytes of data");
  if (rows * s->width > o.max_bytes)
    return bad("an image of " + std::to_string(rows * s->width)
               + " pixels, over " + std::to_string(o.max_bytes));
  hermd::vision_frame f;
  f.source = std::move(*frame);
  f.seq = static_cast<uint32_t>(count);
  f.data.reserve(rows * s->width);
  for (uint64_t r = 0; r < rows; ++r) {
    auto* row = s->data._buffer + r * s->step;
    f.data.insert(f.data.end(), row, row + s->width);
  }
  return caf::make_message(std::move(f));
}

// -- geometry_msgs/Twist <-> twist -----------------------------------------------------

// [twist-conversion]
vector3 from_wire(const geometry_msgs_msg_dds__Vector3_& v) {
  return {v.x, v.y, v.z};
}

geometry_msgs_msg_dds__Vector3_ to_wire(const vector3& v) {
  return {v.x, v.y, v.z};
}

bool finite(const vector3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

caf::error twist_to(const caf::message& v, const conversion_options&,
                    dds_time_t, void* sample) {
  if (auto err = expect_type<twist>(v, "herm.twist"))
    return err;
  auto& t = v.get_as<twist>(0);
  auto* s = static_cast<geometry_msgs_msg_dds__Twist_*>(sample);
  s->linear = to_wire(t.linear);
  s->angular = to_wire(t.angular);
  return caf::none;
}

/// A motion command with NaN or Inf in it is refused: no robot can follow it.
caf::expected<caf::message> twist_from(const void* sample,
                                       const conversion_options&, uint64_t) {
  auto* s = static_cast<const geometry_msgs_msg_dds__Twist_*>(sample);
  twist t{from_wire(s->linear), from_wire(s->angular)};
  if (!finite(t.linear) || !finite(t.angular))
    return bad("a twist with a NaN or infinite component");
  return caf::make_message(t);
}
// [twist-conversion-end]

template <class Sample>
ros_type row(const char* name, const char* herm_type,
             const dds_topic_descriptor_t& desc,
             caf::error (*to)(const caf::message&, const conversion_options&,
                              dds_time_t, void*),
             caf::expected<caf::message> (*from)(const void*,
                                                 const conversion_options&,
                                                 uint64_t)) {
  return {name, herm_type, &desc, sizeof(Sample), to, from};
}

} // namespace

const std::vector<ros_type>& ros_types() {
  static const std::vector<ros_type> types{
    row<std_msgs_msg_dds__String_>("std_msgs/msg/String", "std::string",
                                   std_msgs_msg_dds__String__desc, string_to,
                                   string_from),
    row<std_msgs_msg_dds__Float64_>("std_msgs/msg/Float64", "double",
                                    std_msgs_msg_dds__Float64__desc,
                                    float64_to, float64_from),
    row<std_msgs_msg_dds__Int32_>("std_msgs/msg/Int32", "int32_t",
                                  std_msgs_msg_dds__Int32__desc, int32_to,
                                  int32_from),
    row<sensor_msgs_msg_dds__Range_>("sensor_msgs/msg/Range",
                                     "herm.srf04_reading",
                                     sensor_msgs_msg_dds__Range__desc, range_to,
                                     range_from),
    row<sensor_msgs_msg_dds__Image_>("sensor_msgs/msg/Image",
                                     "herm.vision_frame",
                                     sensor_msgs_msg_dds__Image__desc, image_to,
                                     image_from),
    // [twist-row]
    row<geometry_msgs_msg_dds__Twist_>("geometry_msgs/msg/Twist", "herm.twist",
                                       geometry_msgs_msg_dds__Twist__desc,
                                       twist_to, twist_from),
    // [twist-row-end]
  };
  return types;
}

const ros_type* find_ros_type(const std::string& name) {
  for (auto& t : ros_types())
    if (name == t.name)
      return &t;
  return nullptr;
}

std::string dds_type_name(const std::string& ros_name) {
  auto slash = ros_name.rfind('/');
  if (slash == std::string::npos)
    return ros_name;
  std::string out = ros_name.substr(0, slash);
  for (size_t i; (i = out.find('/')) != std::string::npos;)
    out.replace(i, 1, "::");
  return out + "::dds_::" + ros_name.substr(slash + 1) + "_";
}

} // namespace herm::dds_gateway
