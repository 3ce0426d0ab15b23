#pragma once

// herm-testbed --dds-gateway: the main controller runs a DDS / ROS 2
// gateway (docs/gateway.md) that sends the sensor module's readings, the
// HERM topic `sonar`, to DDS as sensor_msgs/msg/Range on rt/sonar, and the
// vision module's frames, the HERM topic `vision`, as sensor_msgs/msg/Image
// on rt/vision; a DDS reader with no HERM code in it (tests/gateway/
// dds_peer.c, Cyclone's C API only) reads them. This is the testbed's side of it: the gateway's
// piece of the main controller's configuration, the loopback-only Cyclone
// configuration every DDS participant of the run uses, and what the
// reader's output says. Pure: no I/O.

#include <cstdint>
#include <string>
#include <vector>

namespace herm::testbed {

/// Cyclone DDS's configuration for the run (CYCLONEDDS_URI): loopback
/// only, unicast discovery to 127.0.0.1, so that nothing leaves the
/// machine and nothing from the network comes in.
extern const char* const dds_loopback_only;

/// The frame_id the gateway puts in every Range's header.
extern const char* const dds_sonar_frame;

/// The frame_id the gateway puts in every Image's header.
extern const char* const dds_vision_frame;

/// The `apos` entry (YAML, indented for the list) of the main
/// controller's gateway: `sonar` to DDS as sensor_msgs/msg/Range on
/// rt/sonar and `vision` as sensor_msgs/msg/Image (one mono8 row of the
/// frame's bytes) on rt/vision, on `domain` (0 to 232), ROS 2's default QoS.
std::string dds_gateway_apo(uint32_t domain);

/// What the DDS reader printed, judged: the testbed's readings reached it.
struct dds_reader_view {
  /// "range <m> frame <id> ..." lines.
  int ranges = 0;
  /// Of those, ranges within [lo, hi] with the gateway's frame_id.
  int from_sensor = 0;
  /// It printed "encoding 00 01" (XCDR1 little-endian, rmw_cyclonedds's).
  bool xcdr1 = false;
  /// The first range line, for the trace.
  std::string first;
  /// "image ..." lines.
  int images = 0;
  /// Of those, mono8 images of one row of `frame_bytes` bytes with the
  /// gateway's frame_id.
  int frames = 0;
  /// The first image line, for the trace.
  std::string first_image;
};

/// Reads the lines of dds_peer (usage in tests/gateway/dds_peer.c) and
/// counts the readings whose distance is in [lo_mm, hi_mm] (the board's
/// obstacle) and whose frame is dds_sonar_frame, and the images that are
/// vision frames of `frame_bytes` bytes. Other lines are ignored. O(lines).
dds_reader_view view_dds_reader(const std::vector<std::string>& lines,
                                long lo_mm, long hi_mm,
                                unsigned frame_bytes);

} // namespace herm::testbed
