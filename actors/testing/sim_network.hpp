#pragma once

// A deterministic multi-module network inside one process: every module is
// an IO manager plus a routing agent; links are in-process segments with the
// link profile of any Table 1 interface. Runs under CAF's test_coordinator
// (actors/testing/deterministic_system.hpp): time moves only when the test advances
// it. Links can be cut and restored, modules killed and revived, and a
// packet-path checker records every module a data packet visits.

#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "actors/testing/deterministic_system.hpp"

#include "channels/drivers/inproc.hpp"
#include "channels/io_manager.hpp"
#include "routing/routing_agent.hpp"

namespace herm::testkit {

/// Everything delivered to one module's receiver.
using delivery_log = std::vector<packet_delivered>;

using sim_receiver_actor = caf::typed_actor<caf::reacts_to<packet_delivered>>;

class sim_network {
public:
  struct module {
    module_id id = no_module;         ///< static id, or no_module if dynamic
    routing_config cfg;
    io_manager_actor io;
    routing_agent_actor agent;
    std::shared_ptr<delivery_log> received;
    std::vector<size_t> links;        ///< indexes into links_
    bool alive = false;
    /// Set by `on_start` hooks (e.g. the application support actor).
    caf::actor apps;
  };

  /// Runs after a module's IO manager and agent started (every start, also
  /// after `kill`): spawn what else the module runs, e.g. its application
  /// support actor and APOs, tracked with `fx.track`.
  std::function<void(size_t index, module& m)> on_start;

  struct link {
    std::string segment;
    std::string profile;
    std::vector<size_t> modules;
    bool up = true;
  };

  /// `prefix` keeps segment names unique per test.
  sim_network(deterministic_system& fx, std::string prefix,
              std::chrono::milliseconds hello = std::chrono::milliseconds(100))
    : fx_(fx), prefix_(std::move(prefix)), hello_(hello) {
    // nop
  }

  ~sim_network() {
    for (auto& l : links_)
      if (!l.up)
        inproc::replug(l.segment);
  }

  /// Adds a module with a static id (or dynamic with no_module and a seed).
  size_t add_module(module_id id, uint64_t seed = 0) {
    module m;
    m.id = id;
    m.cfg.id = id;
    m.cfg.hello_interval = hello_;
    m.cfg.instance = 1000 + modules_.size();
    m.cfg.seed = seed != 0 ? seed : 77 + modules_.size();
    m.cfg.observer = [this](module_id self, const data_header& h,
                            const byte_buffer& bytes) {
      observe(self, h, bytes);
    };
    modules_.push_back(std::move(m));
    return modules_.size() - 1;
  }

  /// Joins `members` by one medium (two members: a point-to-point link;
  /// more: a bus) with the given profile. Returns the link's index.
  size_t connect(std::vector<size_t> members, std::string profile) {
    link l;
    l.segment = prefix_ + "-l" + std::to_string(links_.size());
    l.profile = std::move(profile);
    l.modules = members;
    links_.push_back(l);
    for (auto m : members)
      modules_[m].links.push_back(links_.size() - 1);
    return links_.size() - 1;
  }

  /// Starts every module not running yet and opens its links.
  void start() {
    for (size_t i = 0; i < modules_.size(); ++i)
      if (!modules_[i].alive)
        start_module(i);
    fx_.run();
  }

  void start_module(size_t i) {
    auto& m = modules_[i];
    m.io = fx_.track(spawn_io_manager(fx_.sys()));
    m.agent = fx_.track(spawn_routing_agent(fx_.sys(), m.io, m.cfg));
    m.received = std::make_shared<delivery_log>();
    auto log = m.received;
    auto rcv = fx_.track(fx_.sys().spawn(
      [log](sim_receiver_actor::pointer) -> sim_receiver_actor::behavior_type {
        return {[log](packet_delivered& x) { log->push_back(std::move(x)); }};
      }));
    caf::anon_send(m.agent, atom::subscribe_v, uint8_t{0},
                   caf::actor_cast<network_receiver_actor>(rcv));
    for (auto li : m.links) {
      auto& l = links_[li];
      auto station = std::find(l.modules.begin(), l.modules.end(), i)
                     - l.modules.begin() + 1;
      device_config dev{"d" + std::to_string(li), "inproc", l.segment,
                        {{"profile", l.profile},
                         {"station", std::to_string(station)}}};
      caf::anon_send(m.io, atom::add_v, dev);
      caf::anon_send(m.io, atom::open_v,
                     channel_request{dev.name, "*", true});
    }
    m.alive = true;
    if (on_start)
      on_start(i, m);
  }

  /// Kills module `i` (its IO manager, links and agent end).
  void kill(size_t i) {
    auto& m = modules_[i];
    if (m.apps)
      caf::anon_send_exit(m.apps, caf::exit_reason::kill);
    caf::anon_send_exit(m.agent, caf::exit_reason::kill);
    caf::anon_send_exit(m.io, caf::exit_reason::kill);
    m.alive = false;
    fx_.run();
  }

  /// Cuts a link: every station on it fails; persistent channels retry.
  void cut(size_t li) {
    links_[li].up = false;
    inproc::unplug(links_[li].segment,
                   make_error(ec::device_failed, "link cut by the test"));
    fx_.run();
  }

  /// Fails a link silently: frames vanish, no driver notices; only missed
  /// hellos reveal it. `restore` ends it.
  void silence(size_t li) {
    links_[li].up = false;
    inproc::blackhole(links_[li].segment, true);
  }

  void restore(size_t li) {
    inproc::blackhole(links_[li].segment, false);
    links_[li].up = true;
    inproc::replug(links_[li].segment);
  }

  /// Advances simulated time; every timer fires at its exact time.
  void advance(std::chrono::milliseconds dt) {
    fx_.advance(dt);
  }

  /// Sends a packet from module a to module b's id; returns the packet's
  /// tag (first 8 payload bytes) for path lookups.
  uint64_t send(size_t a, module_id dst, size_t size = 16) {
    auto tag = next_tag_++;
    byte_buffer payload(std::max<size_t>(size, 8));
    for (int i = 0; i < 8; ++i)
      payload[i] = static_cast<uint8_t>(tag >> (8 * i));
    caf::anon_send(modules_[a].agent, send_packet{dst, 0, prio_normal, payload});
    fx_.run();
    return tag;
  }

  /// Modules (ids) a packet visited, in order.
  const std::vector<module_id>& path(uint64_t tag) {
    return paths_[tag];
  }

  /// Number of packets that visited some module twice (must stay 0).
  size_t loops() const {
    return loops_;
  }

  routing_stats stats(size_t i) {
    auto res = fx_.call<routing_stats>(modules_[i].agent, atom::get_v,
                                       atom::stats_v);
    return res ? std::get<0>(*res) : routing_stats{};
  }

  std::vector<route_info> routes(size_t i) {
    auto res = fx_.call<std::vector<route_info>>(modules_[i].agent,
                                                 atom::get_v, atom::routes_v);
    return res ? std::get<0>(*res) : std::vector<route_info>{};
  }

  /// The selected route from module i to `dst` in class k, if any.
  std::optional<route_info> route(size_t i, module_id dst, uint8_t k = 0) {
    for (auto& r : routes(i))
      if (r.destination == dst && r.size_class == k && r.selected)
        return r;
    return std::nullopt;
  }

  /// The id module i holds now.
  module_id id_of(size_t i) {
    return stats(i).self;
  }

  module& at(size_t i) {
    return modules_[i];
  }

  size_t size() const {
    return modules_.size();
  }

private:
  void observe(module_id self, const data_header& h, const byte_buffer& bytes) {
    auto at = header_size(h);
    if (h.protocol != 0 || bytes.size() < at + 8)
      return;
    uint64_t tag = 0;
    for (size_t i = 0; i < 8; ++i)
      tag |= uint64_t{bytes[at + i]} << (8 * i);
    auto& p = paths_[tag];
    if (std::find(p.begin(), p.end(), self) != p.end())
      ++loops_;
    p.push_back(self);
  }

  deterministic_system& fx_;
  std::string prefix_;
  std::chrono::milliseconds hello_;
  std::vector<module> modules_;
  std::vector<link> links_;
  std::map<uint64_t, std::vector<module_id>> paths_;
  uint64_t next_tag_ = 1;
  size_t loops_ = 0;
};

} // namespace herm::testkit
