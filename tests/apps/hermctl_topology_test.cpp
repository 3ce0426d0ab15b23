// hermctl's topology picture (apps/hermctl/topology.hpp), pure: a shared
// medium with more than two stations is one bus node with its stations
// attached, a link between two stations is one edge with a short label,
// and every module's node shows its name, APOs and channels.

#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "apps/hermctl/topology.hpp"

using namespace hermctl;

namespace {

topo_module module(const std::string& name, std::vector<std::string> apos,
                   std::map<uint32_t, std::string> channels) {
  topo_module m;
  m.name = name;
  m.apos = std::move(apos);
  m.channels = std::move(channels);
  return m;
}

/// Every module of `stations` hears every other on its channel `ch`.
void mesh(topo_input& in, const std::vector<herm::module_id>& stations,
          uint32_t ch, const std::string& kind, int cost) {
  for (auto a : stations)
    for (auto b : stations)
      if (a != b)
        in.neighbours.push_back({a, ch, b, kind, json(cost)});
}

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

/// Three modules on one CAN bus (channel 2, "can0"); 0x30 and 0x31 also
/// share an Ethernet link (channel 1, "eth0").
topo_input robot() {
  topo_input in;
  in.modules[0x30] = module("main", {"planner", "logger"},
                            {{1, "eth0"}, {2, "can0"}});
  in.modules[0x31] = module("vision", {"camera"}, {{1, "eth0"}, {2, "can0"}});
  in.modules[0x32] = module("motors", {}, {{2, "can0"}});
  mesh(in, {0x30, 0x31, 0x32}, 2, "CAN2.0", 30);
  mesh(in, {0x30, 0x31}, 1, "Ethernet", 10);
  return in;
}

} // namespace

TEST(hermctl_topology, a_bus_of_three_stations_is_one_node_not_a_mesh) {
  auto g = make_topology(robot());
  ASSERT_EQ(g.buses.size(), 1u);
  EXPECT_EQ(g.buses[0].id, "bus1");
  EXPECT_EQ(g.buses[0].link_kind, "CAN2.0");
  EXPECT_EQ(g.buses[0].cost, json(30));
  std::map<herm::module_id, std::string> stations{
    {0x30, "can0"}, {0x31, "can0"}, {0x32, "can0"}};
  EXPECT_EQ(g.buses[0].stations, stations);
  ASSERT_EQ(g.links.size(), 1u);
  EXPECT_EQ(g.links[0].a, 0x30);
  EXPECT_EQ(g.links[0].b, 0x31);
  EXPECT_EQ(g.links[0].link_kind, "Ethernet");
  auto dot = to_dot(g);
  EXPECT_TRUE(has(dot, "\"bus1\" [shape=ellipse, label=\"CAN2.0 bus\\ncost 30\"];"))
    << dot;
  for (auto m : {"0x30", "0x31", "0x32"})
    EXPECT_TRUE(has(dot, std::string{"\""} + m + "\" -- \"bus1\" [label=\"can0\"];"))
      << dot;
  EXPECT_FALSE(has(dot, "\"0x30\" -- \"0x32\"")) << dot;
  EXPECT_FALSE(has(dot, "\"0x31\" -- \"0x32\"")) << dot;
  EXPECT_TRUE(has(dot, "\"0x30\" -- \"0x31\" [label=\"Ethernet 10\"];")) << dot;
}

TEST(hermctl_topology, module_nodes_show_name_apos_and_channels) {
  auto dot = to_dot(make_topology(robot()));
  EXPECT_TRUE(has(dot, "\"0x30\" [label=\"0x30\\nmain\\nAPOs: planner, "
                       "logger\\nchannels: eth0, can0\"];"))
    << dot;
  EXPECT_TRUE(has(dot, "\"0x32\" [label=\"0x32\\nmotors\\nchannels: can0\"];"))
    << dot;
}

TEST(hermctl_topology, two_stations_on_a_bus_kind_are_one_edge) {
  topo_input in;
  in.modules[0x30] = module("a", {}, {{5, "can0"}});
  in.modules[0x31] = module("b", {}, {{7, "can1"}});
  mesh(in, {0x30, 0x31}, 0, "CAN2.0", 30);
  in.neighbours[0].channel = 5;
  in.neighbours[1].channel = 7;
  auto g = make_topology(in);
  EXPECT_TRUE(g.buses.empty());
  ASSERT_EQ(g.links.size(), 1u);
  EXPECT_TRUE(has(to_dot(g), "\"0x30\" -- \"0x31\" [label=\"CAN2.0 30\"];"));
}

TEST(hermctl_topology, a_station_that_did_not_answer_still_joins_its_bus) {
  auto in = robot();
  in.modules.erase(0x32);
  in.neighbours.erase(std::remove_if(in.neighbours.begin(), in.neighbours.end(),
                                     [](const topo_neighbour& n) {
                                       return n.from == 0x32;
                                     }),
                      in.neighbours.end());
  auto g = make_topology(in);
  ASSERT_EQ(g.buses.size(), 1u);
  EXPECT_EQ(g.buses[0].stations.size(), 3u);
  EXPECT_EQ(g.buses[0].stations.at(0x32), "");
  auto dot = to_dot(g);
  EXPECT_TRUE(has(dot, "\"0x32\" [label=\"0x32\"];")) << dot;
  EXPECT_TRUE(has(dot, "\"0x32\" -- \"bus1\";")) << dot;
}

TEST(hermctl_topology, two_separate_buses_stay_apart) {
  topo_input in;
  for (herm::module_id m = 0x30; m <= 0x35; ++m)
    in.modules[m] = module("m", {}, {{1, "can0"}});
  mesh(in, {0x30, 0x31, 0x32}, 1, "CAN2.0", 30);
  mesh(in, {0x33, 0x34, 0x35}, 1, "CAN2.0", 30);
  auto g = make_topology(in);
  ASSERT_EQ(g.buses.size(), 2u);
  EXPECT_EQ(g.buses[0].stations.begin()->first, 0x30);
  EXPECT_EQ(g.buses[1].id, "bus2");
  EXPECT_EQ(g.buses[1].stations.begin()->first, 0x33);
}

TEST(hermctl_topology, long_lists_are_cut_and_names_escaped) {
  topo_input in;
  std::vector<std::string> apos;
  for (int i = 0; i < 12; ++i)
    apos.push_back("a" + std::to_string(i));
  in.modules[0x30] = module("say \"hi\"", apos, {});
  auto dot = to_dot(make_topology(in));
  EXPECT_TRUE(has(dot, "say \\\"hi\\\"")) << dot;
  EXPECT_TRUE(has(dot, "a7 +4 more")) << dot;
  EXPECT_FALSE(has(dot, "a8")) << dot;
}

TEST(hermctl_topology, json_has_nodes_edges_and_buses) {
  auto j = to_json(make_topology(robot()));
  ASSERT_EQ(j["nodes"].size(), 3u);
  EXPECT_EQ(j["nodes"][0]["module"], "0x30");
  EXPECT_EQ(j["nodes"][0]["apos"], json({"planner", "logger"}));
  EXPECT_EQ(j["nodes"][0]["channels"], json({"eth0", "can0"}));
  ASSERT_EQ(j["edges"].size(), 1u);
  EXPECT_EQ(j["edges"][0]["link_kind"], "Ethernet");
  EXPECT_EQ(j["edges"][0]["cost"], 10);
  ASSERT_EQ(j["buses"].size(), 1u);
  EXPECT_EQ(j["buses"][0]["bus"], "bus1");
  EXPECT_EQ(j["buses"][0]["stations"].size(), 3u);
  EXPECT_EQ(j["buses"][0]["stations"][2],
            json({{"module", "0x32"}, {"channel", "can0"}}));
}
