// hermctl: looks into and steers a running HERM module through its control
// socket (actors/control.hpp), and through it every module the routing
// reaches ("--module 0x31"). Usage and sample output: "Running hermctl"
// in docs/.
//
//   hermctl info                       hermctl routes --all
//   hermctl --module 0x31 neighbors    hermctl ping 0x31 -c 5
//   hermctl trace 0x33                 hermctl topology --svg robot.svg
//   hermctl link can0 down             hermctl cost --bandwidth 1M --mtu 8
//
// Plain aligned tables for people; --json prints the reply's result as
// JSON for scripts. Exit status: 0 success, 1 the module answered with an
// error (unknown module, no route, unknown device, ...) or a ping got no
// reply, 2 bad usage, 3 no module to talk to (nothing listening at the
// socket, or no reply in time). Errors are one line on stderr.

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "actors/config.hpp"
#include "actors/control.hpp"
#include "actors/runtime/error.hpp"
#include "apps/hermctl/format.hpp"
#include "apps/hermctl/graphviz.hpp"
#include "apps/hermctl/topology.hpp"
#include "apps/hermctl/local_modules.hpp"
#include "apps/hermctl/topics.hpp"
#include "apps/hermctl/views.hpp"
#include "apps/hermctl/watch.hpp"
#include "channels/link_profile.hpp"
#include "routing/metric.hpp"
#include "routing/module_id.hpp"
#include "routing/route_table.hpp"

using json = nlohmann::json;

namespace {

using namespace hermctl;

enum exit_status : int {
  exit_ok = 0,
  exit_failed = 1,
  exit_usage = 2,
  exit_unreachable = 3,
};

/// Ends the command: `message` goes to stderr, `status` is the exit status.
struct failure {
  int status;
  std::string message;
};

struct options {
  std::string socket;
  std::string name = "hermd";
  std::string module;
  bool json_out = false;
  uint32_t timeout_ms = 5000;
  bool all = false;
  uint32_t wait_ms = 0;
  std::string target;
  uint32_t count = 3;
  std::string dot_file;
  std::string svg_file;
  std::string png_file;
  std::string bandwidth;
  uint32_t mtu = 0;
  uint64_t size = 0;
  double coef = 1.0;
  std::string device;
  std::string state;
  bool quiet = false;
  double interval_s = 1.0;
  uint64_t frames = 0;
};

herm::module_id parse_mid(const std::string& text) {
  auto id = herm::parse_module_id(text);
  if (!id || !herm::is_unicast(*id))
    throw failure{exit_usage,
                  "'" + text + "' is not a module id (such as 0x4E or 78)"};
  return *id;
}

// -- talking to the module -------------------------------------------------------------

class client {
public:
  client(std::string path, uint32_t timeout_ms)
    : path_(std::move(path)), timeout_ms_(timeout_ms) {
  }

  /// Sends `req` (to `module`, unless no_module: the local one) and returns
  /// the reply's result; throws a failure for an error reply or no reply.
  json call(json req, herm::module_id module = herm::no_module) {
    req["timeout_ms"] = timeout_ms_;
    if (module != herm::no_module)
      req["module"] = herm::to_hex(module);
    auto text = req.dump();
    auto wait = herm::control_deadline(text) + std::chrono::seconds(1);
    auto reply = herm::control_call(path_, text, wait);
    if (!reply)
      throw failure{exit_unreachable, message_of(reply.error())};
    auto j = json::parse(*reply, nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("ok"))
      throw failure{exit_failed, "the module at " + path_
                                   + " sent a reply that is not a control "
                                     "reply: "
                                   + reply->substr(0, 200)};
    if (j["ok"] != true) {
      auto err = j.value("error", json::object());
      auto code = err.value("code", std::string{"error"});
      auto msg = err.value("message", std::string{});
      throw failure{exit_failed, msg.empty() ? code : msg + " [" + code + "]"};
    }
    return j.value("result", json{});
  }

private:
  static std::string message_of(const caf::error& err) {
    if (err.context().match_elements<std::string>())
      return err.context().get_as<std::string>(0);
    return herm::render(err);
  }

  std::string path_;
  uint32_t timeout_ms_;
};

// -- commands ---------------------------------------------------------------------------

/// Runs request `req` on module `m`: with --json prints the result as it
/// is, else `view` prints it for people.
int show(client& c, const options& o, herm::module_id m, json req,
         const std::function<void(std::ostream&, const json&)>& view) {
  auto r = c.call(std::move(req), m);
  if (o.json_out)
    print_json(std::cout, r);
  else
    view(std::cout, r);
  return exit_ok;
}

int cmd_routes(client& c, const options& o, herm::module_id m) {
  auto rows = route_rows(c.call({{"cmd", "routes"}, {"all", o.all}}, m), o.all);
  if (o.json_out)
    print_json(std::cout, rows);
  else
    show_routes(std::cout, rows, o.all);
  return exit_ok;
}

int cmd_ping(client& c, const options& o) {
  auto target = parse_mid(o.target);
  if (o.count == 0)
    throw failure{exit_usage, "-c must be at least 1"};
  auto r = c.call({{"cmd", "ping"},
                   {"module", herm::to_hex(target)},
                   {"count", o.count}});
  if (o.json_out) {
    print_json(std::cout, r);
    return r.value("received", 0) > 0 ? exit_ok : exit_failed;
  }
  show_ping(std::cout, r, herm::to_hex(target), o.count);
  return r.value("rtt_us", json::array()).empty() ? exit_failed : exit_ok;
}


/// One hop of a trace.
struct hop {
  herm::module_id id;
  std::string name;
  std::string link = "-";
  std::string channel = "-";
  std::string cost = "0";
  std::string rtt = "-";
};

int cmd_trace(client& c, const options& o) {
  auto dst = parse_mid(o.target);
  auto me = c.call({{"cmd", "echo"}});
  auto self_id = herm::module_id(me.value("id", 0));
  std::vector<hop> hops{{self_id, me.value("name", std::string{})}};
  std::set<herm::module_id> visited{self_id};
  auto current = self_id;
  uint64_t cost = 0;
  bool cost_known = true;
  json trace = json::array();
  trace.push_back({{"module", herm::to_hex(self_id)},
                   {"name", hops[0].name},
                   {"cost", 0}});
  while (current != dst) {
    if (hops.size() > herm::max_route_hops)
      throw failure{exit_failed, "no end after " + std::to_string(herm::max_route_hops)
                                   + " hops"};
    auto at = current == self_id ? herm::no_module : current;
    auto routes = c.call({{"cmd", "routes"}, {"all", false}}, at);
    json route;
    for (auto& r : routes)
      if (mid_number(r["destination"]) == dst && r.value("selected", false)
          && r.value("size_class", 0) == 0)
        route = r;
    if (route.is_null())
      throw failure{exit_failed, "no route from " + herm::to_hex(current)
                                   + " to " + herm::to_hex(dst)};
    auto next_text = route.value("neighbour_module", json{});
    auto next = next_text.is_string()
                  ? herm::parse_module_id(next_text.get<std::string>())
                  : std::nullopt;
    if (!next)
      throw failure{exit_failed, herm::to_hex(current)
                                   + " routes to " + herm::to_hex(dst)
                                   + " through an unknown neighbour (link "
                                   + text(route, "neighbour") + ")"};
    if (visited.count(*next) > 0)
      throw failure{exit_failed, "routing loop: " + herm::to_hex(*next)
                                   + " seen twice on the way to "
                                   + herm::to_hex(dst)};
    visited.insert(*next);
    auto link_cost = route.value("link_cost", json{});
    if (link_cost.is_number())
      cost += link_cost.get<uint64_t>();
    else
      cost_known = false;
    hop h{*next, "", text(route, "link_kind"), text(route, "channel"),
          cost_known ? std::to_string(cost) : "?"};
    json jh{{"module", herm::to_hex(*next)},
            {"link_kind", route.value("link_kind", json{})},
            {"channel", route.value("channel", json{})},
            {"cost", cost_known ? json(cost) : json(nullptr)}};
    try {
      h.name = c.call({{"cmd", "echo"}}, *next).value("name", std::string{});
      auto p = c.call({{"cmd", "ping"}, {"module", herm::to_hex(*next)},
                       {"count", 1}});
      h.rtt = text(p, "avg_us") + " us";
      jh["rtt_us"] = p.value("avg_us", json{});
    } catch (const failure& f) {
      if (f.status == exit_unreachable)
        throw;
      h.rtt = "*";
      jh["rtt_us"] = nullptr;
    }
    jh["name"] = h.name;
    trace.push_back(std::move(jh));
    hops.push_back(std::move(h));
    current = *next;
  }
  if (o.json_out) {
    print_json(std::cout, trace);
    return exit_ok;
  }
  std::cout << "trace to " << herm::to_hex(dst) << ": " << hops.size() - 1
            << " hops\n";
  std::vector<std::vector<std::string>> rows;
  for (size_t i = 0; i < hops.size(); ++i)
    rows.push_back({std::to_string(i), herm::to_hex(hops[i].id),
                    hops[i].name.empty() ? "-" : hops[i].name, hops[i].link,
                    hops[i].channel, hops[i].cost, hops[i].rtt});
  print_table(std::cout, {"HOP", "MODULE", "NAME", "LINK", "VIA CHANNEL", "COST", "RTT"},
              rows);
  return exit_ok;
}


int cmd_topology(client& c, const options& o) {
  auto me = c.call({{"cmd", "echo"}});
  auto self_id = herm::module_id(me.value("id", 0));
  std::set<herm::module_id> modules{self_id};
  for (auto& r : c.call({{"cmd", "routes"}, {"all", false}}))
    if (r.value("selected", false) && r.value("size_class", 0) == 0)
      if (auto id = mid_number(r["destination"]); id <= 0xFFFF)
        modules.insert(static_cast<herm::module_id>(id));
  // What each module says of itself (name, APOs, channels) and its
  // neighbours; apps/hermctl/topology.hpp draws it.
  topo_input in;
  for (auto id : modules) {
    auto at = id == self_id ? herm::no_module : id;
    try {
      auto echo = id == self_id ? me : c.call({{"cmd", "echo"}}, at);
      auto rows = c.call({{"cmd", "neighbors"}}, at);
      auto& m = in.modules[id];
      m.name = echo.value("name", std::string{});
      for (auto& ch : c.call({{"cmd", "channels"}}, at))
        if (ch.value("routed", true))
          m.channels[ch.value("id", 0u)] = ch.value("device", std::string{});
      // Every module has herm.control and herm.info: the drawing shows
      // the user's APOs only.
      for (auto& a : c.call({{"cmd", "apps"}}, at)) {
        auto name = a.value("name", std::string{});
        if (a.value("local", false) && name != "herm.control"
            && name != "herm.info")
          m.apos.push_back(name);
      }
      for (auto& n : rows) {
        auto other = mid_number(n["module"]);
        if (other > 0xFFFF)
          continue;
        auto cost = n.value("cost", json::array());
        in.neighbours.push_back(
          {id, n.value("channel", 0u), static_cast<herm::module_id>(other),
           n.value("link_kind", std::string{"?"}),
           cost.empty() ? json(nullptr) : cost[0]});
      }
    } catch (const failure& f) {
      if (f.status == exit_unreachable)
        throw;
      std::cerr << "hermctl: " << herm::to_hex(id) << ": " << f.message << '\n';
      in.modules[id]; // drawn with its id only
    }
  }
  auto g = make_topology(in);
  if (o.json_out) {
    print_json(std::cout, to_json(g));
    return exit_ok;
  }
  auto graph = to_dot(g);
  if (o.dot_file.empty() && o.svg_file.empty() && o.png_file.empty()) {
    std::cout << graph;
    return exit_ok;
  }
  auto summary = " (" + std::to_string(g.modules.size()) + " modules, "
                 + std::to_string(g.links.size()) + " links"
                 + (g.buses.empty() ? std::string{}
                                    : ", " + std::to_string(g.buses.size())
                                        + (g.buses.size() == 1 ? " bus" : " buses"))
                 + ")";
  if (!o.dot_file.empty()) {
    std::ofstream out{o.dot_file};
    out << graph;
    if (!out)
      throw failure{exit_failed, "cannot write " + o.dot_file};
    std::cout << "wrote " << o.dot_file << summary << '\n';
  }
  for (auto& [file, format] : {std::pair{o.svg_file, std::string{"svg"}},
                               std::pair{o.png_file, std::string{"png"}}}) {
    if (file.empty())
      continue;
    if (!have_dot())
      throw failure{exit_failed, "cannot render " + file
                                   + ": graphviz's 'dot' is not on PATH "
                                     "(install graphviz, or write --dot FILE "
                                     "and render it elsewhere)"};
    if (auto err = render_dot(graph, format, file))
      throw failure{exit_failed, *err};
    std::cout << "wrote " << file << summary << '\n';
  }
  return exit_ok;
}

int cmd_profiles(const options& o) {
  json j = json::array();
  std::vector<std::vector<std::string>> rows;
  for (auto& p : herm::builtin_profiles()) {
    auto cost = herm::link_cost(p);
    j.push_back({{"name", p.name},
                 {"bandwidth_bps", p.bandwidth_bps},
                 {"mtu", p.mtu},
                 {"multi_access", p.multi_access},
                 {"cost", cost}});
    rows.push_back({p.name, bandwidth_text(p.bandwidth_bps),
                    std::to_string(p.mtu), std::to_string(cost),
                    p.multi_access ? "bus" : "point-to-point"});
  }
  if (o.json_out)
    print_json(std::cout, j);
  else
    print_table(std::cout, {"NAME", "BANDWIDTH", "MTU", "COST", "ACCESS"}, rows);
  return exit_ok;
}


int cmd_cost(const options& o) {
  auto parsed = parse_bandwidth(o.bandwidth);
  if (!parsed)
    throw failure{exit_usage, "--bandwidth '" + o.bandwidth
                                + "' is not a bit rate (such as 1000000, 1M, "
                                  "19.2k)"};
  auto bps = *parsed;
  if (!(o.coef > 0))
    throw failure{exit_usage, "--coef must be above 0"};
  if (o.size > 0 && o.mtu == 0)
    throw failure{exit_usage, "--size needs --mtu (frames are ceil(size / mtu))"};
  herm::link_profile p{"custom", bps, o.mtu, false, o.coef, 0};
  auto cost = herm::link_cost(bps, o.coef);
  json j{{"bandwidth_bps", bps}, {"delay_coef", o.coef}, {"link_cost", cost}};
  std::vector<std::pair<std::string, std::string>> pairs{
    {"bandwidth", bandwidth_text(bps)},
    {"coefficient", number(o.coef)},
    {"link cost", std::to_string(cost)}};
  if (o.mtu > 0) {
    j["mtu"] = o.mtu;
    pairs.emplace_back("mtu", std::to_string(o.mtu) + " bytes");
    auto size = o.size > 0 ? o.size : uint64_t{o.mtu};
    auto frames = (size + o.mtu - 1) / o.mtu;
    auto mc = herm::message_cost(p, size);
    j["size"] = size;
    j["frames"] = frames;
    j["message_cost"] = mc;
    pairs.emplace_back("message size", std::to_string(size) + " bytes = "
                                         + std::to_string(frames) + " frames");
    pairs.emplace_back("message cost", std::to_string(mc));
    auto classes = herm::link_metrics(p);
    std::string per_class;
    j["class_costs"] = json::array();
    for (size_t k = 0; k < herm::size_classes; ++k) {
      j["class_costs"].push_back(classes[k] == herm::infinite_metric
                                   ? json(nullptr)
                                   : json(classes[k]));
      if (!per_class.empty())
        per_class += ", ";
      per_class += std::to_string(herm::size_class_bytes[k]) + " B: "
                   + cost_text(classes[k] == herm::infinite_metric
                                 ? json(nullptr)
                                 : json(classes[k]));
    }
    pairs.emplace_back("size classes", per_class);
  }
  if (o.json_out)
    print_json(std::cout, j);
  else
    print_pairs(std::cout, pairs);
  return exit_ok;
}

/// `watch` (apps/hermctl/watch.hpp): frames of module `m` until --count.
int cmd_watch(client& c, const options& o, herm::module_id m) {
  if (o.json_out)
    throw failure{exit_usage, "watch draws for people: for scripts, poll "
                              "'hermctl stats --json' or 'routes --json'"};
  watch_options w;
  w.module = m;
  w.interval = std::chrono::milliseconds(static_cast<int64_t>(o.interval_s * 1000));
  w.count = o.frames;
  w.ansi = ::isatty(STDOUT_FILENO) == 1;
  w.width = w.ansi ? 80 : 0;
  auto call = [&c](json req, herm::module_id at) {
    try {
      return watch_reply{true, c.call(std::move(req), at), {}};
    } catch (const failure& f) {
      if (f.status != exit_failed)
        throw;
      return watch_reply{false, {}, f.message};
    }
  };
  run_watch(call, w, std::cout);
  return exit_ok;
}

} // namespace

int main(int argc, char** argv) {
  options o;
  CLI::App app{"hermctl: inspect and steer HERM modules through a module's "
               "control socket"};
  app.fallthrough();
  app.require_subcommand(1);
  auto* socket_opt = app.add_option("-s,--socket", o.socket,
                                    "control socket (default: $HERM_CONTROL, "
                                    "else the socket of --name, else the one "
                                    "module running here)");
  app.add_option("--name", o.name, "module name whose socket in the runtime "
                                   "directory to use")
    ->excludes(socket_opt);
  app.add_flag("--quiet", o.quiet, "do not say which module was found");
  app.add_option("--module", o.module,
                 "run the command on this module (0x4E or 78), through the "
                 "local one");
  app.add_flag("--json", o.json_out, "print the result as JSON");
  app.add_option("--timeout", o.timeout_ms,
                 "milliseconds to wait for each answer (default 5000)")
    ->check(CLI::Range(1u, 600000u));
  auto* info = app.add_subcommand("info", "module name, id, uptime, summary");
  auto* channels = app.add_subcommand("channels",
                                      "the Channel Table with counters");
  auto* routes = app.add_subcommand("routes", "the routing table");
  routes->add_flag("--all", o.all,
                   "every size class and every route, not only selected ones");
  auto* neighbors = app.add_subcommand("neighbors", "neighbour modules");
  neighbors->alias("neighbours");
  auto* apps = app.add_subcommand("apps", "application objects, local and "
                                          "discovered");
  apps->add_flag("--all", o.all,
                 "ask the whole network first: every APO with its module");
  apps->add_option("--wait", o.wait_ms,
                   "with --all: ms to collect the answers (default 500; "
                   "more for slow or busy links)")
    ->check(CLI::Range(1, 60000));
  auto* stats = app.add_subcommand("stats", "every counter");
  auto* ping = app.add_subcommand("ping", "round-trip times to a module's "
                                          "control service");
  ping->add_option("MID", o.target, "module id")->required();
  ping->add_option("-c,--count", o.count, "echoes (default 3)");
  auto* trace = app.add_subcommand("trace", "the path to a module, hop by hop");
  trace->add_option("MID", o.target, "module id")->required();
  auto* topology = app.add_subcommand("topology", "every reachable module and "
                                                  "link as a graph");
  topology->add_option("--dot", o.dot_file, "write the DOT graph to FILE");
  topology->add_option("--svg", o.svg_file, "render to FILE with graphviz");
  topology->add_option("--png", o.png_file, "render to FILE with graphviz");
  auto* profiles = app.add_subcommand("profiles", "the built-in link profiles "
                                                  "(Table 1)");
  auto* cost = app.add_subcommand("cost", "link and message cost of a link");
  cost->add_option("--bandwidth", o.bandwidth, "bit/s: 1000000, 1M, 19.2k")
    ->required();
  cost->add_option("--mtu", o.mtu, "frame payload, bytes");
  cost->add_option("--size", o.size, "message size, bytes");
  cost->add_option("--coef", o.coef, "delay coefficient c (default 1)");
  auto* link = app.add_subcommand("link", "take a device's channels down or "
                                          "bring them up");
  link->add_option("DEVICE", o.device, "device name")->required();
  link->add_option("STATE", o.state, "up or down")->required();
  auto* reload = app.add_subcommand("reload", "make hermd re-read its "
                                              "configuration");
  auto* modules = app.add_subcommand("modules", "the modules running on this "
                                                "machine (their control sockets)");
  modules->alias("ls");
  auto* watch = app.add_subcommand("watch", "a live view: modules, links with "
                                            "rates, route changes");
  watch->add_option("--interval", o.interval_s,
                    "seconds between frames (default 1)")
    ->check(CLI::Range(0.1, 3600.0));
  watch->add_option("--count", o.frames, "stop after N frames (default: never)");
  hermctl::topic_commands topic_cmds{app};
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    auto status = app.exit(e);
    return status == 0 ? exit_ok : exit_usage;
  }
  try {
    if (profiles->parsed())
      return cmd_profiles(o);
    if (cost->parsed())
      return cmd_cost(o);
    if (topic_cmds.parsed() && !topic_cmds.needs_module())
      return topic_cmds.run({}, o.timeout_ms, o.json_out);
    auto module = herm::no_module;
    if (!o.module.empty()) {
      if (ping->parsed() || trace->parsed() || topology->parsed())
        throw failure{exit_usage, "--module does not apply to ping, trace and "
                                  "topology: they start at the local module"};
      module = parse_mid(o.module);
    }
    if (modules->parsed()) {
      if (module != herm::no_module)
        throw failure{exit_usage, "--module does not apply to modules: it "
                                  "lists this machine's modules"};
      auto dir = runtime_dir();
      show_modules(std::cout,
                   list_modules(scan_runtime_dir(dir),
                                std::chrono::milliseconds(o.timeout_ms)),
                   dir, o.json_out);
      return exit_ok;
    }
    std::string path = o.socket;
    if (path.empty()) {
      auto* env = std::getenv("HERM_CONTROL");
      bool named = app.count("--name") > 0;
      if (env != nullptr && *env != '\0' && !named) {
        path = env;
      } else if (named) {
        path = socket_of(o.name);
      } else {
        // Nothing named a module: the one running here, if there is one.
        auto dir = runtime_dir();
        auto found = scan_runtime_dir(dir);
        auto pick = choose_module(found, o.name);
        if (pick.kind == module_choice::ambiguous)
          throw failure{exit_usage, ambiguous_message(found, dir)};
        path = pick.kind == module_choice::use ? pick.chosen.path : socket_of(o.name);
        if (pick.kind == module_choice::use && !o.json_out && !o.quiet)
          std::cerr << using_line(pick.chosen) << '\n';
      }
    }
    if (topic_cmds.parsed()) {
      if (module != herm::no_module)
        throw failure{exit_usage, "--module does not apply to topic, call, "
                                  "record and play: topics and APOs of every "
                                  "module reach the local one"};
      return topic_cmds.run(path, o.timeout_ms, o.json_out);
    }
    client c{path, o.timeout_ms};
    if (info->parsed())
      return show(c, o, module, {{"cmd", "info"}}, show_info);
    if (channels->parsed())
      return show(c, o, module, {{"cmd", "channels"}}, show_channels);
    if (routes->parsed())
      return cmd_routes(c, o, module);
    if (neighbors->parsed())
      return show(c, o, module, {{"cmd", "neighbors"}}, show_neighbors);
    if (apps->parsed()) {
      json req{{"cmd", "apps"}, {"all", o.all}};
      if (o.wait_ms > 0) {
        if (!o.all)
          throw failure{exit_usage, "--wait goes with --all"};
        req["wait_ms"] = o.wait_ms;
      }
      return show(c, o, module, std::move(req), show_apps);
    }
    if (stats->parsed())
      return show(c, o, module, {{"cmd", "stats"}}, show_stats);
    if (ping->parsed())
      return cmd_ping(c, o);
    if (trace->parsed())
      return cmd_trace(c, o);
    if (topology->parsed())
      return cmd_topology(c, o);
    if (link->parsed()) {
      if (o.state != "up" && o.state != "down")
        throw failure{exit_usage, "link state must be 'up' or 'down', got '"
                                    + o.state + "'"};
      return show(c, o, module,
                  {{"cmd", "link"}, {"device", o.device}, {"state", o.state}},
                  [&o](std::ostream& out, const json& r) {
                    show_link(out, r, o.device, o.state);
                  });
    }
    if (reload->parsed())
      return show(c, o, module, {{"cmd", "reload"}}, show_reload);
    if (watch->parsed())
      return cmd_watch(c, o, module);
    return exit_usage;
  } catch (const failure& f) {
    std::cout.flush();
    std::cerr << "hermctl: " << f.message << '\n';
    return f.status;
  } catch (const hermctl::topic_failure& f) {
    std::cout.flush();
    std::cerr << "hermctl: " << f.message << '\n';
    return f.status;
  }
}
