#include "routing/metric.hpp"

#include <string>
#include <utility>

namespace herm {

uint8_t size_class_of(size_t bytes) {
  for (uint8_t k = 0; k < size_classes; ++k)
    if (bytes <= size_class_bytes[k])
      return k;
  return size_classes - 1;
}

metric add_metric(metric x, metric y) {
  if (x == infinite_metric || y == infinite_metric)
    return infinite_metric;
  auto sum = uint64_t{x} + y;
  return sum >= infinite_metric ? infinite_metric : static_cast<metric>(sum);
}

metric_vector add_metrics(const metric_vector& x, const metric_vector& y) {
  metric_vector result;
  for (size_t k = 0; k < size_classes; ++k)
    result[k] = add_metric(x[k], y[k]);
  return result;
}

metric_vector link_metrics(const link_profile& p) {
  metric_vector result;
  auto cost = uint64_t{link_cost(p)};
  for (size_t k = 0; k < size_classes; ++k) {
    if (p.mtu == 0 || cost >= infinite_metric) {
      result[k] = infinite_metric;
      continue;
    }
    auto frames = (uint64_t{size_class_bytes[k]} + p.mtu - 1) / p.mtu;
    auto total = cost * frames;
    result[k] = total >= infinite_metric ? infinite_metric
                                         : static_cast<metric>(total);
  }
  return result;
}

link_code link_code_of(const std::string& name) {
  // The link kinds' names as link profiles spell them (lower case).
  static constexpr std::pair<const char*, link_code> codes[] = {
    {"usb1.1", link_code::usb11},       {"usb2.0", link_code::usb20},
    {"ieee1394a", link_code::ieee1394a}, {"ieee1394b", link_code::ieee1394b},
    {"can2.0", link_code::can20},       {"ethernet", link_code::ethernet},
    {"rs232c", link_code::rs232c},
  };
  for (auto& [text, code] : codes)
    if (name == text)
      return code;
  return link_code::unknown;
}

const char* to_string(link_code x) {
  switch (x) {
    case link_code::usb11: return "USB1.1";
    case link_code::usb20: return "USB2.0";
    case link_code::ieee1394a: return "IEEE1394a";
    case link_code::ieee1394b: return "IEEE1394b";
    case link_code::can20: return "CAN2.0";
    case link_code::ethernet: return "Ethernet";
    case link_code::rs232c: return "RS232C";
    case link_code::unknown: break;
  }
  return "?";
}

} // namespace herm
