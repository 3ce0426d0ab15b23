#pragma once

// The picture of `hermctl topology`: what every module said about itself
// (name, APOs, channels) and its neighbours, drawn as a DOT graph or a
// JSON object. Pure: no I/O, no clock; O((modules + neighbour rows) log n).
//
// A shared medium with more than two stations (a CAN bus, an Ethernet
// segment, an emulated IEEE 1394 bus) is one bus node with its stations
// attached by one edge each (labelled with the station's channel), instead
// of a full mesh of edges; a link between two stations only is one edge
// between them. Edge labels stay short: the link kind and its class-0 cost
// ("Ethernet 10"). Each module's node shows its id, name, APO names and
// channel names.

#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "routing/module_id.hpp"

namespace hermctl {

using json = nlohmann::json;

/// One module as it answered (or not).
struct topo_module {
  herm::module_id id = herm::no_module;
  std::string name;
  /// Names of its local APOs.
  std::vector<std::string> apos;
  /// Its channels' device names ("eth0", "can0"), by channel id.
  std::map<uint32_t, std::string> channels;
};

/// One row of a module's neighbour table: `from` hears `to` on its channel
/// `channel` over a link of `link_kind` ("CAN2.0"), cost `cost` (a number,
/// or null for unreachable).
struct topo_neighbour {
  herm::module_id from = herm::no_module;
  uint32_t channel = 0;
  herm::module_id to = herm::no_module;
  std::string link_kind;
  json cost;
};

/// What the modules said. Modules named only as neighbours may be left out
/// of `modules` (they are drawn with their id only).
struct topo_input {
  std::map<herm::module_id, topo_module> modules;
  std::vector<topo_neighbour> neighbours;
};

/// A link between two stations only: one edge.
struct topo_link {
  herm::module_id a = herm::no_module;
  herm::module_id b = herm::no_module;
  std::string link_kind;
  json cost;
};

/// A shared medium with more than two stations: one node.
struct topo_bus {
  /// "bus1", "bus2", ... in order of the smallest station.
  std::string id;
  std::string link_kind;
  json cost;
  /// Each station and the name of its channel on the bus ("" when the
  /// station did not say).
  std::map<herm::module_id, std::string> stations;
};

struct topo_graph {
  std::map<herm::module_id, topo_module> modules;
  std::vector<topo_link> links;
  std::vector<topo_bus> buses;
};

/// Groups the neighbour rows into links and buses. Stations that hear each
/// other over the same link kind on one channel each form one medium (the
/// connected stations of a (module, channel) graph); a medium of more than
/// two stations is a bus. A neighbour heard from one side only counts as
/// heard from both. Every module named anywhere gets a node.
topo_graph make_topology(const topo_input& in);

/// The graph in DOT ("graph herm { ... }").
std::string to_dot(const topo_graph& g);

/// {"nodes": [{"module", "name", "apos", "channels"}],
///  "edges": [{"a", "b", "link_kind", "cost"}],
///  "buses": [{"bus", "link_kind", "cost", "stations": [{"module",
///  "channel"}]}]}.
json to_json(const topo_graph& g);

} // namespace hermctl
