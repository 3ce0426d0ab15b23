// The topology picture (apps/hermctl/topology.hpp).

#include "apps/hermctl/topology.hpp"

#include <algorithm>
#include <limits>
#include <set>
#include <sstream>
#include <tuple>

#include "apps/hermctl/format.hpp"

namespace hermctl {

namespace {

/// A station's side of a medium: a module and its channel on it. A module
/// that did not answer has no channel id: it is `unknown_channel` and the
/// link kind tells its media apart.
struct side {
  herm::module_id module;
  uint32_t channel;
  std::string kind;

  friend bool operator<(const side& x, const side& y) {
    return std::tie(x.module, x.channel, x.kind)
           < std::tie(y.module, y.channel, y.kind);
  }
};

constexpr uint32_t unknown_channel = std::numeric_limits<uint32_t>::max();

/// Union-find over the sides seen.
class media {
public:
  void join(const side& a, const side& b) {
    auto ra = root(a);
    auto rb = root(b);
    if (ra < rb)
      parent_[rb] = ra;
    else if (rb < ra)
      parent_[ra] = rb;
  }

  side root(const side& x) {
    auto i = parent_.find(x);
    if (i == parent_.end()) {
      parent_.emplace(x, x);
      return x;
    }
    if (!(i->second < x) && !(x < i->second))
      return x;
    auto r = root(i->second);
    parent_[x] = r;
    return r;
  }

  std::vector<side> sides() const {
    std::vector<side> out;
    for (auto& kv : parent_)
      out.push_back(kv.first);
    return out;
  }

private:
  std::map<side, side> parent_;
};

/// The smaller of two costs (numbers; null is infinite).
json min_cost(const json& a, const json& b) {
  if (!a.is_number())
    return b;
  if (!b.is_number())
    return a;
  return a.get<double>() <= b.get<double>() ? a : b;
}

/// At most `max` of `xs`, comma-separated, then "+N more".
std::string some(const std::vector<std::string>& xs, size_t max = 8) {
  std::string out;
  for (size_t i = 0; i < xs.size() && i < max; ++i)
    out += (i == 0 ? "" : ", ") + xs[i];
  if (xs.size() > max)
    out += " +" + std::to_string(xs.size() - max) + " more";
  return out;
}

std::string quoted(const std::string& s) {
  return "\"" + dot_escape(s) + "\"";
}

} // namespace

topo_graph make_topology(const topo_input& in) {
  topo_graph g;
  g.modules = in.modules;
  for (auto& [id, m] : g.modules)
    m.id = id;
  auto answered = [&](herm::module_id m) { return in.modules.count(m) > 0; };
  media md;
  // The channels each module hears each other on, per link kind.
  std::map<std::tuple<herm::module_id, herm::module_id, std::string>,
           std::set<uint32_t>>
    heard_on;
  for (auto& r : in.neighbours)
    heard_on[{r.from, r.to, r.link_kind}].insert(r.channel);
  // The other side of a row: the channel of its reverse row, if any.
  for (auto& r : in.neighbours) {
    side here{r.from, r.channel, r.link_kind};
    md.root(here);
    auto back = heard_on.find({r.to, r.from, r.link_kind});
    bool found = back != heard_on.end();
    if (found)
      for (auto ch : back->second)
        md.join(here, side{r.to, ch, r.link_kind});
    if (!found)
      md.join(here, side{r.to, answered(r.to) ? unknown_channel - 1
                                              : unknown_channel,
                         r.link_kind});
    for (auto m : {r.from, r.to})
      if (g.modules.count(m) == 0)
        g.modules[m].id = m;
  }
  // One medium per root: its stations, kind and cost.
  struct medium {
    std::map<herm::module_id, std::string> stations;
    std::string kind;
    json cost;
  };
  std::map<side, medium> by_root;
  for (auto& s : md.sides()) {
    auto& m = by_root[md.root(s)];
    m.kind = s.kind;
    std::string channel;
    if (auto i = in.modules.find(s.module); i != in.modules.end())
      if (auto c = i->second.channels.find(s.channel);
          c != i->second.channels.end())
        channel = c->second;
    auto& name = m.stations[s.module];
    if (name.empty())
      name = channel;
  }
  for (auto& r : in.neighbours) {
    auto& m = by_root[md.root(side{r.from, r.channel, r.link_kind})];
    m.cost = m.cost.is_null() ? r.cost : min_cost(m.cost, r.cost);
  }
  std::vector<medium> buses;
  for (auto& [root, m] : by_root) {
    if (m.stations.size() > 2) {
      buses.push_back(m);
    } else if (m.stations.size() == 2) {
      auto a = m.stations.begin()->first;
      auto b = std::next(m.stations.begin())->first;
      g.links.push_back(topo_link{a, b, m.kind, m.cost});
    }
  }
  std::sort(g.links.begin(), g.links.end(),
            [](const topo_link& x, const topo_link& y) {
              return std::tie(x.a, x.b, x.link_kind)
                     < std::tie(y.a, y.b, y.link_kind);
            });
  std::sort(buses.begin(), buses.end(), [](const medium& x, const medium& y) {
    return std::tie(x.stations.begin()->first, x.kind)
           < std::tie(y.stations.begin()->first, y.kind);
  });
  for (size_t i = 0; i < buses.size(); ++i)
    g.buses.push_back(topo_bus{"bus" + std::to_string(i + 1), buses[i].kind,
                               buses[i].cost, buses[i].stations});
  return g;
}

std::string to_dot(const topo_graph& g) {
  std::ostringstream dot;
  dot << "graph herm {\n  node [shape=box];\n";
  for (auto& [id, m] : g.modules) {
    auto label = herm::to_hex(id);
    if (!m.name.empty())
      label += "\n" + m.name;
    if (!m.apos.empty())
      label += "\nAPOs: " + some(m.apos);
    std::vector<std::string> channels;
    for (auto& kv : m.channels)
      channels.push_back(kv.second);
    if (!channels.empty())
      label += "\nchannels: " + some(channels);
    // dot_escape drops newlines: escape each line, join with \n.
    std::string escaped;
    std::istringstream lines{label};
    for (std::string line; std::getline(lines, line);)
      escaped += (escaped.empty() ? "" : "\\n") + dot_escape(line);
    dot << "  " << quoted(herm::to_hex(id)) << " [label=\"" << escaped
        << "\"];\n";
  }
  for (auto& b : g.buses)
    dot << "  " << quoted(b.id) << " [shape=ellipse, label=\""
        << dot_escape(b.link_kind) << " bus\\ncost " << cost_text(b.cost)
        << "\"];\n";
  for (auto& l : g.links)
    dot << "  " << quoted(herm::to_hex(l.a)) << " -- "
        << quoted(herm::to_hex(l.b)) << " [label=\""
        << dot_escape(l.link_kind) << " " << cost_text(l.cost) << "\"];\n";
  for (auto& b : g.buses)
    for (auto& [station, channel] : b.stations) {
      dot << "  " << quoted(herm::to_hex(station)) << " -- " << quoted(b.id);
      if (!channel.empty())
        dot << " [label=" << quoted(channel) << "]";
      dot << ";\n";
    }
  dot << "}\n";
  return dot.str();
}

json to_json(const topo_graph& g) {
  json j{{"nodes", json::array()},
         {"edges", json::array()},
         {"buses", json::array()}};
  for (auto& [id, m] : g.modules) {
    json channels = json::array();
    for (auto& kv : m.channels)
      channels.push_back(kv.second);
    j["nodes"].push_back({{"module", herm::to_hex(id)},
                          {"name", m.name},
                          {"apos", m.apos},
                          {"channels", std::move(channels)}});
  }
  for (auto& l : g.links)
    j["edges"].push_back({{"a", herm::to_hex(l.a)},
                          {"b", herm::to_hex(l.b)},
                          {"link_kind", l.link_kind},
                          {"cost", l.cost}});
  for (auto& b : g.buses) {
    json stations = json::array();
    for (auto& [station, channel] : b.stations)
      stations.push_back({{"module", herm::to_hex(station)},
                          {"channel", channel}});
    j["buses"].push_back({{"bus", b.id},
                          {"link_kind", b.link_kind},
                          {"cost", b.cost},
                          {"stations", std::move(stations)}});
  }
  return j;
}

} // namespace hermctl
