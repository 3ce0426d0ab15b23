#include "channels/messages.hpp"

namespace herm {

bool operator==(const write_packet& x, const write_packet& y) {
  return x.dst == y.dst && x.priority == y.priority && x.bytes == y.bytes;
}

bool operator==(const packet_received& x, const packet_received& y) {
  return x.channel == y.channel && x.src == y.src && x.bytes == y.bytes;
}

const char* to_string(link_event_kind x) {
  switch (x) {
    case link_event_kind::peer_heard: return "peer_heard";
    case link_event_kind::error_frame: return "error_frame";
    case link_event_kind::bus_off: return "bus_off";
    case link_event_kind::bus_recovered: return "bus_recovered";
  }
  return "unknown";
}

} // namespace herm
