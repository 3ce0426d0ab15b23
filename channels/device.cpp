#include "channels/device_actor.hpp"

#include <algorithm>
#include <map>
#include <mutex>

#include "caf/actor_system.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/type_ids.hpp"
#include "channels/channel.hpp"
#include "channels/link_driver.hpp"
#include "channels/thread_cache.hpp"

namespace herm {

namespace {

/// Receives from the driver's thread and hands each frame to the channel
/// that owns its source: the point-to-point channel for that peer, else the
/// device's "*" channel. Thread-safe; never blocks beyond a short lock.
class demux : public frame_handler {
public:
  explicit demux(std::shared_ptr<device_counters> counters)
    : counters_(std::move(counters)) {
    // nop
  }

  void on_frame(link_addr src, const uint8_t* data, size_t size) override {
    on_frame_in_lane(src, 0, data, size);
  }

  void on_frame_in_lane(link_addr src, uint8_t lane, const uint8_t* data,
                        size_t size) override {
    auto to = lookup(src);
    if (!to.ch) {
      ++counters_->unclaimed;
      return;
    }
    // The channel releases the charge when it takes the frame.
    if (!to.queue->charge(size))
      return;
    auto bytes = take_buffer(size);
    bytes.assign(data, data + size);
    pooled_anon_send(to.ch, frame_received{src, std::move(bytes), lane});
  }

  void on_malformed(link_addr, const char*) override {
    ++counters_->malformed;
  }

  void on_kernel_drops(uint64_t count) override {
    counters_->kernel_dropped += count;
  }

  void on_event(link_event_kind kind, link_addr peer,
                std::string detail) override {
    std::vector<channel_actor> targets;
    {
      std::lock_guard<std::mutex> guard{mtx_};
      if (wildcard_.ch)
        targets.push_back(wildcard_.ch);
      for (auto& kv : by_peer_)
        if (peer == 0 || kv.first == peer)
          targets.push_back(kv.second.ch);
    }
    for (auto& t : targets)
      caf::anon_send(t, link_event{0, static_cast<uint8_t>(kind), peer, detail});
  }

  void on_failure(caf::error reason) override {
    std::lock_guard<std::mutex> guard{mtx_};
    if (device_)
      caf::anon_send(device_, device_failed{std::move(reason)});
    else if (!failure_)
      failure_ = std::move(reason);
  }

  /// Sets the device to notify on failure; forwards an early failure.
  void set_device(device_actor dev) {
    std::lock_guard<std::mutex> guard{mtx_};
    device_ = dev;
    if (failure_)
      caf::anon_send(device_, device_failed{std::move(failure_)});
  }

  void add(link_addr peer, channel_actor ch,
           std::shared_ptr<rx_queue_account> queue) {
    std::lock_guard<std::mutex> guard{mtx_};
    if (peer == broadcast_addr)
      wildcard_ = target{std::move(ch), std::move(queue)};
    else
      by_peer_[peer] = target{std::move(ch), std::move(queue)};
  }

  void remove(const caf::actor_addr& addr) {
    std::lock_guard<std::mutex> guard{mtx_};
    if (wildcard_.ch && wildcard_.ch.address() == addr)
      wildcard_ = target{};
    for (auto i = by_peer_.begin(); i != by_peer_.end(); ++i)
      if (i->second.ch.address() == addr) {
        by_peer_.erase(i);
        break;
      }
  }

  bool taken(link_addr peer) {
    std::lock_guard<std::mutex> guard{mtx_};
    return peer == broadcast_addr ? static_cast<bool>(wildcard_.ch)
                                  : by_peer_.count(peer) > 0;
  }

  void clear() {
    std::lock_guard<std::mutex> guard{mtx_};
    wildcard_ = target{};
    by_peer_.clear();
    device_ = nullptr;
  }

private:
  /// A channel and its inbound queue.
  struct target {
    channel_actor ch;
    std::shared_ptr<rx_queue_account> queue;
  };

  target lookup(link_addr src) {
    std::lock_guard<std::mutex> guard{mtx_};
    if (!by_peer_.empty()) {
      auto i = by_peer_.find(src);
      if (i != by_peer_.end())
        return i->second;
    }
    return wildcard_;
  }

  std::shared_ptr<device_counters> counters_;
  std::mutex mtx_;
  target wildcard_;
  std::map<link_addr, target> by_peer_;
  device_actor device_;
  caf::error failure_;
};

struct device_state {
  static inline const char* name = "herm.device";

  device_config config;
  link_driver_ptr driver;
  std::shared_ptr<device_counters> counters;
  std::shared_ptr<demux> frames;
  std::map<caf::actor_addr, channel_actor> channels;
  packet_tap_ptr tap;

  ~device_state() {
    // The driver's thread must not outlive the actor it reports to.
    if (driver)
      driver->stop();
    if (frames)
      frames->clear();
  }
};

using device_impl = device_actor::stateful_pointer<device_state>;

void shut_down(device_impl self, const caf::error& reason) {
  auto& st = self->state;
  st.driver->stop();
  st.frames->clear();
  for (auto& kv : st.channels)
    self->send_exit(kv.second, reason);
  st.channels.clear();
  self->quit(reason);
}

device_actor::behavior_type
device_fun(device_impl self, device_config cfg, link_driver_ptr driver,
           std::shared_ptr<device_counters> counters,
           std::shared_ptr<demux> frames, packet_tap_ptr tap) {
  {
    auto& st = self->state;
    st.tap = std::move(tap);
    st.config = std::move(cfg);
    st.driver = std::move(driver);
    st.counters = std::move(counters);
    st.frames = std::move(frames);
  }
  self->set_down_handler([self](caf::down_msg& msg) {
    self->state.frames->remove(msg.source);
    self->state.channels.erase(msg.source);
  });
  return {
    [self](atom::open, const channel_request& req,
           channel_id id) -> caf::result<channel_actor, channel_info> {
      auto& st = self->state;
      link_addr peer = broadcast_addr;
      if (req.address != "*") {
        auto addr = st.driver->parse_addr(req.address);
        if (!addr)
          return make_error(ec::invalid_address,
                            "device '" + st.config.name + "': "
                              + render(addr.error()));
        peer = *addr;
      }
      if (st.frames->taken(peer))
        return make_error(ec::already_exists,
                          "device '" + st.config.name
                            + "' already has a channel for address '"
                            + req.address + "'");
      channel_info info;
      info.id = id;
      info.device = st.config.name;
      info.kind = st.config.kind;
      info.address = req.address;
      info.local = st.driver->format_addr(st.driver->local_addr());
      info.profile = st.driver->profile();
      channel_setup setup;
      info.max_packet = static_cast<uint32_t>(
        std::max<size_t>(info.profile.mtu, setup.limits.max_packet));
      setup.info = info;
      setup.driver = st.driver;
      setup.counters = st.counters;
      setup.peer = peer;
      setup.device = self;
      setup.tap = st.tap;
      auto queue = setup.rx_queue;
      auto ch = spawn_channel(self->system(), std::move(setup));
      self->monitor(ch);
      st.channels.emplace(ch.address(), ch);
      st.frames->add(peer, ch, std::move(queue));
      return {ch, info};
    },
    [self](atom::get, atom::info) -> device_info {
      auto& st = self->state;
      device_info result;
      result.config = st.config;
      result.profile = st.driver->profile();
      result.local = st.driver->format_addr(st.driver->local_addr());
      result.channels = static_cast<uint32_t>(st.channels.size());
      result.unclaimed_frames = st.counters->unclaimed.load();
      result.malformed_frames = st.counters->malformed.load();
      return result;
    },
    [self](device_failed& msg) { shut_down(self, msg.reason); },
    [self](atom::close) {
      shut_down(self, make_error(ec::channel_closed,
                                 "device '" + self->state.config.name
                                   + "' closed"));
    },
  };
}

} // namespace

caf::expected<device_actor> spawn_device(caf::actor_system& sys,
                                         const device_config& cfg,
                                         packet_tap_ptr tap) {
  auto* kind = find_link_kind(cfg.kind);
  if (kind == nullptr) {
    std::string known;
    for (auto* k : link_kinds())
      known += (known.empty() ? "" : ", ") + std::string{k->name};
    return make_error(ec::unknown_link_kind,
                      "device '" + cfg.name + "': unknown link kind '"
                        + cfg.kind + "' (known: " + known + ")");
  }
  auto driver = kind->open(cfg);
  if (!driver)
    return std::move(driver.error());
  if ((*driver)->profile().mtu < min_fragment_mtu)
    return make_error(ec::invalid_parameter,
                      "device '" + cfg.name + "': MTU "
                        + std::to_string((*driver)->profile().mtu)
                        + " is below the minimum of "
                        + std::to_string(min_fragment_mtu));
  auto counters = std::make_shared<device_counters>();
  auto frames = std::make_shared<demux>(counters);
  if (auto err = (*driver)->start(frames, io_loop_of(sys)))
    return err;
  auto dev = sys.spawn(device_fun, cfg, *driver, counters, frames,
                       std::move(tap));
  frames->set_device(dev);
  return dev;
}

} // namespace herm
