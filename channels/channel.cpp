#include "channels/channel.hpp"

#include <algorithm>
#include <set>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/default_attachable.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/port.hpp"

namespace herm {

namespace {

/// At most this many peers are remembered for channel_info::peers.
constexpr size_t max_known_peers = 1024;

struct channel_state {
  static inline const char* name = "herm.channel";

  channel_info info;
  link_driver_ptr driver;
  std::shared_ptr<device_counters> counters;
  link_addr peer = broadcast_addr;
  std::unique_ptr<packet_port> port;
  std::vector<channel_reader_actor> readers;
  std::set<link_addr> peers;
  channel_stats stats;
  byte_buffer rx_buf;
  bool tick_pending = false;
};

using channel_impl = channel_actor::stateful_pointer<channel_state>;

void deliver(channel_impl self, link_addr src) {
  auto& st = self->state;
  ++st.stats.rx_packets;
  st.stats.rx_bytes += st.rx_buf.size();
  auto& readers = st.readers;
  if (readers.empty())
    return;
  // Copy for all readers but the last, which gets the buffer itself.
  for (size_t i = 0; i + 1 < readers.size(); ++i)
    self->send(readers[i], packet_received{st.info.id, src, st.rx_buf});
  self->send(readers.back(),
             packet_received{st.info.id, src, std::move(st.rx_buf)});
  st.rx_buf = byte_buffer{};
}

void schedule_tick(channel_impl self) {
  auto& st = self->state;
  if (st.tick_pending)
    return;
  auto deadline = st.port->next_deadline();
  if (!deadline)
    return;
  auto now = self->clock().now();
  auto delay = *deadline > now ? *deadline - now : caf::timespan{0};
  st.tick_pending = true;
  self->delayed_send(self, delay + std::chrono::milliseconds(1),
                     atom::tick_v);
}

void publish(channel_impl self, link_event ev) {
  ev.channel = self->state.info.id;
  for (auto& r : self->state.readers)
    self->send(r, ev);
}

channel_info current_info(channel_impl self) {
  auto info = self->state.info;
  info.peers.clear();
  for (auto p : self->state.peers)
    info.peers.push_back(self->state.driver->format_addr(p));
  info.profile = self->state.driver->profile();
  return info;
}

channel_actor::behavior_type channel_fun(channel_impl self,
                                         channel_setup setup,
                                         std::unique_ptr<packet_port>* port) {
  auto& st = self->state;
  st.info = std::move(setup.info);
  st.driver = std::move(setup.driver);
  st.counters = std::move(setup.counters);
  st.peer = setup.peer;
  st.port = std::move(*port);
  st.info.max_packet = st.port->max_packet();
  st.stats.id = st.info.id;
  // The channel ends with its device.
  self->monitor(setup.device);
  self->set_down_handler([self](caf::down_msg& msg) {
    auto& readers = self->state.readers;
    auto i = std::find_if(readers.begin(), readers.end(), [&](auto& r) {
      return r.address() == msg.source;
    });
    if (i != readers.end()) {
      readers.erase(i);
      return;
    }
    // Our device went away.
    self->quit(msg.reason ? msg.reason
                          : make_error(ec::device_failed, "device closed"));
  });
  return {
    [self](write_packet& msg) {
      auto& st = self->state;
      auto dst = st.peer == broadcast_addr ? msg.dst : st.peer;
      auto res = st.port->send(dst, msg.priority, msg.bytes.data(),
                               msg.bytes.size());
      if (!res) {
        ++st.stats.tx_dropped;
        return;
      }
      ++st.stats.tx_packets;
      st.stats.tx_bytes += msg.bytes.size();
      st.stats.tx_frames += *res;
    },
    [self](atom::subscribe, channel_reader_actor& reader) -> channel_info {
      auto& readers = self->state.readers;
      if (std::find(readers.begin(), readers.end(), reader) == readers.end()) {
        self->monitor(reader);
        // The reader learns of our end with a down message even when it
        // does not monitor us itself.
        self->attach(caf::default_attachable::make_monitor(self->address(),
                                                           reader.address()));
        readers.push_back(std::move(reader));
      }
      return current_info(self);
    },
    [self](atom::unsubscribe, const channel_reader_actor& reader) {
      auto& readers = self->state.readers;
      auto i = std::find(readers.begin(), readers.end(), reader);
      if (i != readers.end()) {
        self->demonitor(i->address());
        self->detach(caf::default_attachable::observe_token{
          i->address(), caf::default_attachable::monitor});
        readers.erase(i);
      }
    },
    [self](atom::get, atom::info) -> channel_info {
      return current_info(self);
    },
    [self](atom::get, atom::stats) -> channel_stats {
      auto& st = self->state;
      auto result = st.stats;
      st.port->add_stats(result);
      result.rx_malformed += st.counters->malformed.load();
      return result;
    },
    [self](atom::get, const std::string& key) -> caf::result<std::string> {
      auto res = self->state.driver->get_param(key);
      if (!res)
        return std::move(res.error());
      return std::move(*res);
    },
    [self](atom::set, const std::string& key,
           const std::string& value) -> caf::result<channel_info> {
      if (key == "mtu")
        return make_error(ec::invalid_parameter,
                          "the MTU of channel " + std::to_string(self->state.info.id)
                            + " is fixed while open; change the device "
                              "configuration and reopen");
      if (auto err = self->state.driver->set_param(key, value))
        return err;
      return current_info(self);
    },
    [self](atom::close) {
      self->quit(make_error(ec::channel_closed,
                            "channel " + std::to_string(self->state.info.id)
                              + " closed by its owner"));
    },
    [self](frame_received& msg) {
      auto& st = self->state;
      ++st.stats.rx_frames;
      if (st.peers.size() < max_known_peers && st.peers.insert(msg.src).second)
        publish(self, link_event{0, static_cast<uint8_t>(link_event_kind::peer_heard),
                                 msg.src, st.driver->format_addr(msg.src)});
      auto now = self->clock().now();
      switch (st.port->receive(msg.src, msg.bytes.data(), msg.bytes.size(),
                               now, st.rx_buf)) {
        case packet_port::rx::packet:
          deliver(self, msg.src);
          break;
        case packet_port::rx::pending:
          schedule_tick(self);
          break;
        case packet_port::rx::dropped:
          break;
      }
    },
    [self](link_event& ev) { publish(self, std::move(ev)); },
    [self](atom::tick) {
      auto& st = self->state;
      st.tick_pending = false;
      st.port->expire(self->clock().now());
      schedule_tick(self);
    },
  };
}

} // namespace

channel_actor spawn_channel(caf::actor_system& sys, channel_setup setup) {
  auto port = make_port(setup.driver, setup.limits);
  // make_port fails only for MTUs below 8, which the device refuses before.
  auto ptr = std::move(*port);
  return sys.spawn(
    [setup = std::move(setup), ptr = std::move(ptr)](channel_impl self) mutable {
      return channel_fun(self, std::move(setup), &ptr);
    });
}

} // namespace herm
