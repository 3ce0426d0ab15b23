#pragma once

// A deterministic multi-module network inside one process: every module is
// an IO manager plus a routing agent; links are in-process segments with the
// link profile of any Table 1 interface. Runs under CAF's test_coordinator
// (actors/testing/deterministic_system.hpp): time moves only when the test
// advances it. Links can be cut and restored, modules killed and revived, and
// a packet-path checker records every module a data packet visits.
//
// Public testing kit. Typical use (actors/testing/sim_apps.hpp adds the
// Application Support Layer and APOs):
//
//   sim_network net{fx};                          // fx: deterministic_system
//   auto a = net.add_module(0x42), b = net.add_module(0x4E);
//   auto link = net.connect({a, b}, "can2.0");    // a Table 1 profile
//   net.start();
//   net.advance(std::chrono::seconds(2));         // routes converge
//   net.cut(link); ... net.restore(link);
//   net.kill(b); ... net.start_module(b);
//
// Indexes (`size_t`) name modules and links in the order they were added;
// module ids (`module_id`) are what the network knows them by. Link with
// herm_routing (herm_asl brings it along).

#include <atomic>
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

/// The receiver every module subscribes for protocol 0 (`sim_network::send`).
using sim_receiver_actor = caf::typed_actor<caf::reacts_to<packet_delivered>>;

/// A simulated network of modules and links; see the file comment. Owns no
/// actor itself: every actor it spawns is tracked by the deterministic_system,
/// which must outlive it. Not thread-safe (test thread only).
class sim_network {
public:
  /// One module and what runs on it now.
  struct module {
    module_id id = no_module;         ///< static id, or no_module if dynamic
    /// Its routing agent's configuration; edit before `start` to change
    /// timers (`hello_interval` defaults to the network's `hello`).
    routing_config cfg;
    io_manager_actor io;
    routing_agent_actor agent;
    /// Protocol-0 packets delivered here since the module last started.
    std::shared_ptr<delivery_log> received;
    std::vector<size_t> links;        ///< indexes into links_
    bool alive = false;
    /// Set by `on_start` hooks (e.g. the application support actor).
    caf::actor apps;
    /// Actors living on this module (spawned with `spawn_on`, e.g. APOs):
    /// `kill` kills them with it. Emptied by `kill`.
    std::vector<caf::actor> residents;
    /// APOs registered by `spawn_apo` (actors/testing/sim_apps.hpp) since the
    /// module last started, in the order their registrations completed.
    std::vector<apo_ref> apos;
  };

  /// Runs after a module's IO manager and agent started (every start, also
  /// after `kill`): spawn what else the module runs, e.g. its application
  /// support actor and APOs, tracked with `fx.track`. One hook: assigning
  /// replaces it (`add_app_support` assigns it); add more with
  /// `add_start_hook`.
  std::function<void(size_t index, module& m)> on_start;

  /// One medium joining two (point-to-point) or more (bus) modules.
  struct link {
    std::string segment;              ///< the in-process segment's name
    std::string profile;              ///< Table 1 profile, e.g. "can2.0"
    std::vector<size_t> modules;      ///< members; station i + 1 is modules[i]
    bool up = true;                   ///< false while cut or silenced
  };

  /// `prefix` names the in-process segments (`<prefix>-l<link index>`);
  /// segments are process-wide, so it must be unique among the networks
  /// alive in the process. Empty: a unique one is made up. `hello` is every
  /// module's hello interval (routes converge within a few of them).
  explicit sim_network(deterministic_system& fx, std::string prefix = {},
                       std::chrono::milliseconds hello
                       = std::chrono::milliseconds(100))
    : fx_(fx),
      prefix_(prefix.empty() ? unique_prefix() : std::move(prefix)),
      hello_(hello) {
    // nop
  }

  ~sim_network() {
    for (auto& l : links_)
      if (!l.up)
        inproc::replug(l.segment);
  }

  /// Adds a module with a static id (or dynamic with no_module and a seed).
  /// Returns its index. Modules added after `start` start with the next
  /// `start` or `start_module`.
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

  /// Joins `members` (module indexes) by one medium (two members: a
  /// point-to-point link; more: a bus) with the given profile: a Table 1
  /// name ("can2.0" (1 Mbit/s, 8-byte MTU), "ethernet", "rs232c", "usb1.1",
  /// "usb2.0", "ieee1394a", "ieee1394b"). Call before the members start.
  /// Returns the link's index.
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

  /// Starts module `i` (again, after `kill`): a fresh IO manager, routing
  /// agent and receiver, its links opened, then `on_start` and every start
  /// hook. Runs no actor: follow with `run()` or `advance()`. A module
  /// already running must be killed first.
  void start_module(size_t i) {
    auto& m = modules_[i];
    m.apos.clear();
    // With a route cell, the channels deliver through it as start_module's
    // do (routing/fast_routes.hpp).
    packet_tap_ptr tap;
    if (m.cfg.fast_routes)
      tap = std::make_shared<fast_receiver>(m.cfg.fast_routes);
    m.io = fx_.track(spawn_io_manager(fx_.sys(), {}, std::move(tap)));
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
    for (auto& hook : start_hooks_)
      hook(i, m);
  }

  /// Adds a hook that runs after `on_start` whenever a module starts (also
  /// after `kill`), in the order hooks were added: spawn a module's APOs
  /// here (with `spawn_on` or `spawn_apo`) so that they come back with it.
  void add_start_hook(std::function<void(size_t index, module& m)> hook) {
    start_hooks_.push_back(std::move(hook));
  }

  /// Spawns an actor living on module `i`, as `sys().spawn(xs...)` does:
  /// tracked by the harness and killed by `kill(i)`. Returns its handle.
  template <class... Ts>
  auto spawn_on(size_t i, Ts&&... xs) {
    auto hdl = fx_.track(fx_.sys().spawn(std::forward<Ts>(xs)...));
    modules_[i].residents.push_back(caf::actor_cast<caf::actor>(hdl));
    return hdl;
  }

  /// Kills module `i` as a power cut would (exit reason `kill`): its
  /// application support actor, its residents, its routing agent and IO
  /// manager (its links' stations go with it), with no goodbye to anyone.
  /// Neighbours notice when their channels end or hellos stop. Runs every
  /// actor. `start_module(i)` brings it back.
  void kill(size_t i) {
    auto& m = modules_[i];
    // The application support actor first: dying APOs are not withdrawn.
    if (m.apps)
      caf::anon_send_exit(m.apps, caf::exit_reason::kill);
    for (auto& hdl : m.residents)
      caf::anon_send_exit(hdl, caf::exit_reason::kill);
    m.residents.clear();
    caf::anon_send_exit(m.agent, caf::exit_reason::kill);
    caf::anon_send_exit(m.io, caf::exit_reason::kill);
    m.alive = false;
    fx_.run();
  }

  /// Cuts a link (the cable is pulled): every station on it fails at once
  /// with ec::device_failed, so its modules see the channel end; persistent
  /// channels retry (100 ms doubling to 5 s) until `restore`. Runs every
  /// actor.
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

  /// Ends `cut` or `silence`: frames flow again; a cut link's channels come
  /// back at their next retry. Runs no actor: follow with `advance()`.
  void restore(size_t li) {
    inproc::blackhole(links_[li].segment, false);
    links_[li].up = true;
    inproc::replug(links_[li].segment);
  }

  /// Advances simulated time; every timer fires at its exact time.
  void advance(std::chrono::milliseconds dt) {
    fx_.advance(dt);
  }

  /// Runs every actor until no message is left; fires no timer.
  void run() {
    fx_.run();
  }

  /// The actor system the network runs in.
  caf::actor_system& sys() {
    return fx_.sys();
  }

  /// The harness the network runs in.
  deterministic_system& harness() {
    return fx_;
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

  /// Module i's routing counters (empty when it does not answer).
  routing_stats stats(size_t i) {
    auto res = fx_.call<routing_stats>(modules_[i].agent, atom::get_v,
                                       atom::stats_v);
    return res ? std::get<0>(*res) : routing_stats{};
  }

  /// Module i's routing table, every size class.
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

  /// Module i (valid until the next `add_module`).
  module& at(size_t i) {
    return modules_[i];
  }

  /// Link li.
  const link& link_at(size_t li) const {
    return links_[li];
  }

  /// Number of modules.
  size_t size() const {
    return modules_.size();
  }

private:
  static std::string unique_prefix() {
    static std::atomic<uint64_t> count{0};
    return "testkit-sim" + std::to_string(++count);
  }

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
  std::vector<std::function<void(size_t, module&)>> start_hooks_;
  std::map<uint64_t, std::vector<module_id>> paths_;
  uint64_t next_tag_ = 1;
  size_t loops_ = 0;
};

} // namespace herm::testkit
