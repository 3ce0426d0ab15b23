#include "apps/testbed/dds_view.hpp"

#include <cstdio>
#include <cstring>

namespace herm::testbed {

const char* const dds_loopback_only
  = "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name=\"lo\"/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<Peers><Peer address=\"127.0.0.1\"/></Peers><ParticipantIndex>auto"
    "</ParticipantIndex></Discovery></Domain></CycloneDDS>";

const char* const dds_sonar_frame = "srf04";

const char* const dds_vision_frame = "camera";

std::string dds_gateway_apo(uint32_t domain) {
  return R"(  - name: gateway      # the DDS / ROS 2 gateway (--dds-gateway)
    kind: dds_gateway
    options:
      domain: )"
         + std::to_string(domain) + R"(
      sonar.type: sensor_msgs/msg/Range
      sonar.frame_id: )"
         + dds_sonar_frame + R"(
      vision.type: sensor_msgs/msg/Image
      vision.frame_id: )"
         + dds_vision_frame + "\n";
}

dds_reader_view view_dds_reader(const std::vector<std::string>& lines,
                                long lo_mm, long hi_mm,
                                unsigned frame_bytes) {
  dds_reader_view v;
  for (auto& l : lines) {
    if (l.rfind("encoding 00 01", 0) == 0)
      v.xcdr1 = true;
    unsigned w = 0, h = 0, n = 0;
    char enc[32] = {0};
    char id[64] = {0};
    if (std::sscanf(l.c_str(), "image %ux%u %31s frame %63s bytes %u", &w, &h,
                    enc, id, &n)
        == 5) {
      if (v.images++ == 0)
        v.first_image = l;
      if (w == frame_bytes && h == 1 && n == frame_bytes
          && std::strcmp(enc, "mono8") == 0
          && std::strcmp(id, dds_vision_frame) == 0)
        ++v.frames;
      continue;
    }
    double m = 0;
    char frame[64] = {0};
    if (std::sscanf(l.c_str(), "range %lf frame %63s ", &m, frame) != 2)
      continue;
    if (v.ranges++ == 0)
      v.first = l;
    // dds_peer prints metres to the millimetre: half a millimetre either way.
    auto mm = m * 1000.0;
    if (mm >= lo_mm - 0.5 && mm <= hi_mm + 0.5
        && std::strcmp(frame, dds_sonar_frame) == 0)
      ++v.from_sensor;
  }
  return v;
}

} // namespace herm::testbed
