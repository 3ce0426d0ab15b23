#pragma once

// Plain message types of the Network Interface Layer. Every struct has an
// `inspect` overload right below it and a type ID in actors/runtime/type_ids.hpp.

#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "caf/error.hpp"
#include "caf/meta/type_name.hpp"

#include "channels/link_profile.hpp"

namespace herm {

/// Raw bytes as they travel over a link.
using byte_buffer = std::vector<uint8_t>;

/// A link-layer address, meaningful only on its link kind: IPv4 address and
/// port for udp (ip << 16 | port), a station number for emulated and
/// in-process media, a node id for CAN. Each link kind formats and parses its
/// own addresses.
using link_addr = uint64_t;

/// Sends to every station the channel reaches.
constexpr link_addr broadcast_addr = std::numeric_limits<uint64_t>::max();

/// Index of a channel in the IO manager's Channel Table (the paper's "next
/// channel index"). 0 is never assigned.
using channel_id = uint32_t;

/// Message priorities: lower is more urgent (CAN arbitration order).
enum priority : uint8_t {
  prio_control = 0,
  prio_high = 1,
  prio_normal = 2,
  prio_bulk = 3,
};

// -- client <-> channel ----------------------------------------------------------

/// Asks a channel to send one packet (any size up to the channel's maximum
/// packet size; fragmented if larger than the link MTU). One-way: failures
/// are counted in channel_stats, never returned.
struct write_packet {
  link_addr dst = broadcast_addr;
  uint8_t priority = prio_normal;
  byte_buffer bytes;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, write_packet& x) {
  return f(caf::meta::type_name("write_packet"), x.dst, x.priority, x.bytes);
}

bool operator==(const write_packet& x, const write_packet& y);

/// A complete packet delivered by a channel to its subscribers.
struct packet_received {
  channel_id channel = 0;
  link_addr src = 0;
  byte_buffer bytes;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, packet_received& x) {
  return f(caf::meta::type_name("packet_received"), x.channel, x.src, x.bytes);
}

bool operator==(const packet_received& x, const packet_received& y);

/// What a link reports besides packets.
enum class link_event_kind : uint8_t {
  /// A frame from a peer not heard before arrived (multi-access links).
  peer_heard = 1,
  /// The medium reported an error frame (CAN) or a framing error (serial).
  error_frame = 2,
  /// The controller went bus-off (CAN); sending is impossible until recovery.
  bus_off = 3,
  /// The controller recovered from bus-off or an error-passive state.
  bus_recovered = 4,
};

const char* to_string(link_event_kind x);

/// An event on a link, delivered to channel subscribers.
struct link_event {
  channel_id channel = 0;
  uint8_t kind = 0; ///< a link_event_kind
  link_addr peer = 0;
  std::string detail;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, link_event& x) {
  return f(caf::meta::type_name("link_event"), x.channel, x.kind, x.peer,
           x.detail);
}

// -- driver -> channel / device ----------------------------------------------------

/// One frame as received by a driver (at most MTU bytes), with the lane it
/// travelled in (link_driver.hpp: 0 on links that keep frames in order).
struct frame_received {
  link_addr src = 0;
  byte_buffer bytes;
  uint8_t lane = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, frame_received& x) {
  return f(caf::meta::type_name("frame_received"), x.src, x.bytes, x.lane);
}

/// A driver failed for good (socket error, device removed).
struct device_failed {
  caf::error reason;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, device_failed& x) {
  return f(caf::meta::type_name("device_failed"), x.reason);
}

// -- descriptions ----------------------------------------------------------------

/// Key/value options of a device, kind-specific (e.g. "profile", "peers",
/// "station", "loss").
using option_map = std::map<std::string, std::string>;

/// How to create a device: one physical interface.
struct device_config {
  /// Unique name clients use, e.g. "eth0", "fw0", "can0".
  std::string name;
  /// Link kind, e.g. "udp", "emu", "inproc".
  std::string kind;
  /// The interface: "0.0.0.0:47000" (udp), a medium directory (emu), a
  /// segment name (inproc).
  std::string interface;
  option_map options;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, device_config& x) {
  return f(caf::meta::type_name("device_config"), x.name, x.kind, x.interface,
           x.options);
}

/// What a client asks the IO manager for: a channel on a device.
struct channel_request {
  /// Name of a registered device.
  std::string device;
  /// "*" for every peer on the link (segment or bus), or one peer's link
  /// address in the kind's notation for a point-to-point channel.
  std::string address = "*";
  /// Re-create the channel with backoff when its device fails.
  bool persistent = false;
  /// A channel for its client's own use (an APO reading a sensor line): the
  /// IO manager does not announce it to its listeners, so the routing agent
  /// leaves it alone (no hellos, no routes over it).
  bool local = false;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, channel_request& x) {
  return f(caf::meta::type_name("channel_request"), x.device, x.address,
           x.persistent, x.local);
}

/// What a channel says about itself.
struct channel_info {
  channel_id id = 0;
  std::string device;
  std::string kind;
  std::string address;
  /// This module's own address on the link.
  std::string local;
  link_profile profile;
  /// Largest packet the channel accepts (fragmented when above the MTU).
  uint32_t max_packet = 0;
  /// Link-layer addresses of the peers heard so far, formatted.
  std::vector<std::string> peers;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, channel_info& x) {
  return f(caf::meta::type_name("channel_info"), x.id, x.device, x.kind,
           x.address, x.local, x.profile, x.max_packet, x.peers);
}

/// Counters of one channel. Every dropped packet or frame is counted once,
/// under the reason it was dropped for.
struct channel_stats {
  channel_id id = 0;
  uint64_t tx_packets = 0;
  uint64_t tx_bytes = 0;
  uint64_t tx_frames = 0;
  /// Packets not sent: too large, driver refused, queue full.
  uint64_t tx_dropped = 0;
  uint64_t rx_packets = 0;
  uint64_t rx_bytes = 0;
  uint64_t rx_frames = 0;
  /// Frames that did not decode (bad header, oversized, truncated).
  uint64_t rx_malformed = 0;
  /// Packets dropped during reassembly: timed out, memory bound exceeded,
  /// checksum mismatch, or a new packet reused an incomplete packet's tag.
  uint64_t rx_reassembly_dropped = 0;
  /// Duplicate fragments ignored (the packet had that fragment already).
  uint64_t rx_duplicates = 0;
  /// Packets lost to overload (the transmit backlog was full), by priority:
  /// refused on arrival or evicted for a more urgent packet. Included in
  /// tx_dropped.
  uint64_t tx_overload_control = 0;
  uint64_t tx_overload_high = 0;
  uint64_t tx_overload_normal = 0;
  uint64_t tx_overload_bulk = 0;
  /// The transmit backlog now and at its fullest, bytes; its bound.
  uint64_t backlog_bytes = 0;
  uint64_t backlog_peak_bytes = 0;
  uint64_t backlog_limit_bytes = 0;
  /// Bundle frames sent and received: each carried two or more small
  /// packets (counted in tx_packets / rx_packets too).
  uint64_t tx_bundles = 0;
  uint64_t rx_bundles = 0;
  /// Orphan fragments ignored: consecutive fragments of a packet whose
  /// first fragment never arrived or was dropped already.
  uint64_t rx_orphans = 0;
  /// Frames the kernel dropped because the device's receive buffer was full
  /// (SO_RXQ_OVFL on udp and can sockets), before the driver saw them. A
  /// device-wide count: every channel of the device reports it.
  uint64_t rx_kernel_dropped = 0;
  /// Frames dropped because this channel's inbound queue (frames the driver
  /// received that the channel has not processed yet) held its bound.
  uint64_t rx_queue_dropped = 0;
  /// Frames from peers not remembered in channel_info::peers (nor
  /// announced with a peer_heard event) because the channel knew its
  /// maximum number of peers (1024) already. The frames are processed.
  uint64_t rx_peers_unrecorded = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, channel_stats& x) {
  return f(caf::meta::type_name("channel_stats"), x.id, x.tx_packets,
           x.tx_bytes, x.tx_frames, x.tx_dropped, x.rx_packets, x.rx_bytes,
           x.rx_frames, x.rx_malformed, x.rx_reassembly_dropped,
           x.rx_duplicates, x.tx_overload_control, x.tx_overload_high,
           x.tx_overload_normal, x.tx_overload_bulk, x.backlog_bytes,
           x.backlog_peak_bytes, x.backlog_limit_bytes, x.tx_bundles,
           x.rx_bundles, x.rx_orphans, x.rx_kernel_dropped,
           x.rx_queue_dropped, x.rx_peers_unrecorded);
}

} // namespace herm
