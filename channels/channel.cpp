#include "channels/channel.hpp"

#include <algorithm>
#include <array>
#include <deque>
#include <set>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/default_attachable.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "channels/error.hpp"
#include "channels/type_ids.hpp"
#include "channels/bundling_port.hpp"
#include "channels/port.hpp"
#include "channels/thread_cache.hpp"
#include "channels/tx_backlog.hpp"

namespace herm {

namespace {

/// At most this many peers are remembered for channel_info::peers (and
/// announced with peer_heard); frames of others are still processed and
/// counted in channel_stats::rx_peers_unrecorded.
constexpr size_t max_known_peers = 1024;

/// Bounds on frames waiting while the driver's transmit queue is full: half
/// a second of the link's bandwidth within 16 KiB .. 1 MiB (CAN at 1 Mbit/s:
/// 62.5 KB, about a second of payload once frame overhead is counted; UDP:
/// 1 MiB). A longer queue would only add latency. A packet larger than the
/// bound is still sent whole when it finds the backlog empty.
constexpr size_t min_backlog_bytes = 16 * 1024;
constexpr size_t max_backlog_bytes = 1024 * 1024;

size_t backlog_bound(const link_profile& p) {
  return static_cast<size_t>(std::clamp<uint64_t>(
    p.bandwidth_bps / 16, min_backlog_bytes, max_backlog_bytes));
}

struct channel_state {
  static inline const char* name = "herm.channel";

  channel_info info;
  link_driver_ptr driver;
  std::shared_ptr<device_counters> counters;
  std::shared_ptr<rx_queue_account> rx_queue;
  link_addr peer = broadcast_addr;
  std::unique_ptr<packet_port> port;
  std::vector<channel_reader_actor> readers;
  packet_tap_ptr tap;
  std::set<link_addr> peers;
  channel_stats stats;
  byte_buffer rx_buf;
  bool tick_pending = false;
  /// Frames the driver refused with queue_full, one queue per priority
  /// (channels/tx_backlog.hpp: bounded, with its drop policy).
  tx_backlog backlog{max_backlog_bytes}; // bound set by channel_fun
  bool flush_pending = false;
  /// How long to wait before retrying a full driver queue.
  caf::timespan flush_delay{std::chrono::milliseconds(1)};
  /// The packet being split: did any of its frames reach the driver, and
  /// do its frames go to the backlog now?
  bool packet_sent_any = false;
  bool packet_in_backlog = false;

  /// The frame_writer of this channel's port stack.
  caf::error write_frame(link_addr dst, uint8_t prio, const uint8_t* data,
                         size_t size) {
    if (!packet_in_backlog) {
      if (backlog.empty()) {
        auto err = driver->send(dst, data, size, prio);
        if (!is(err, ec::queue_full)) {
          packet_sent_any = packet_sent_any || !err;
          return err;
        }
      }
      backlog.open(prio, packet_sent_any);
      packet_in_backlog = true;
    }
    backlog.append(dst, data, size);
    return caf::none;
  }
};

/// The channel actor. Each message is one turn: at its end the port stack
/// is flushed when no further message waits (bundling_port.hpp), so that
/// packets written in one burst share frames and no handler has to send
/// what the stack holds back.
class channel_self : public channel_actor::stateful_base<channel_state> {
public:
  using super = channel_actor::stateful_base<channel_state>;

  using super::super;

  caf::invoke_message_result consume(caf::mailbox_element& x) override {
    // A write may join the bundle being built: it is flushed after the
    // write when the mailbox is empty. Any other message sees it flushed
    // first when it is the last one waiting, so that statistics and
    // timers account for every packet written before it.
    bool write = x.content().match_elements<write_packet>();
    if (!write)
      end_turn();
    auto res = super::consume(x);
    if (write)
      end_turn();
    return res;
  }

private:
  void end_turn() {
    if (state.port != nullptr && mailbox().empty())
      state.port->flush();
  }
};

using channel_impl = channel_self*;

} // namespace

packet_tap::~packet_tap() = default;

namespace {

void deliver(channel_impl self, link_addr src) {
  auto& st = self->state;
  ++st.stats.rx_packets;
  st.stats.rx_bytes += st.rx_buf.size();
  auto& readers = st.readers;
  if (readers.empty())
    return;
  if (readers.size() == 1 && st.tap != nullptr
      && st.tap->take(st.info.id, src, st.rx_buf)) {
    st.rx_buf.clear(); // whatever take() left of it is reused
    return;
  }
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

void schedule_flush(channel_impl self) {
  auto& st = self->state;
  if (st.flush_pending || st.backlog.empty())
    return;
  st.flush_pending = true;
  self->delayed_send(self, st.flush_delay, atom::tick_v);
}

/// Backlogged frames handed to the driver per link_driver::send_batch call
/// (a stack array; udp sends them with one sendmmsg).
constexpr size_t tx_batch = 64;

/// Hands backlogged frames to the driver, tx_batch per call, until its queue
/// is full again. A frame the driver refuses for good is dropped and counted;
/// the frames after it go in the next call.
void flush(channel_impl self) {
  auto& st = self->state;
  std::array<tx_frame, tx_batch> batch;
  while (auto n = st.backlog.peek(batch.data(), batch.size())) {
    caf::error err;
    auto taken = st.driver->send_batch(batch.data(), n, err);
    st.backlog.pop(taken);
    if (taken == n)
      continue;
    if (is(err, ec::queue_full))
      break;
    ++st.stats.tx_dropped;
    st.backlog.pop();
  }
  schedule_flush(self);
}

/// The channel's own layer of the port stack, below the bundling port and
/// above the fragmenting one: per packet (or bundle frame) it applies the
/// backlog's admission, starts the frame writer's per-packet state, counts
/// and arms the backlog timer.
class channel_tx_port : public port_decorator {
public:
  channel_tx_port(channel_impl self, std::unique_ptr<packet_port> inner)
    : port_decorator(std::move(inner)), self_(self) {
    // nop
  }

  /// Sends one packet through the port stack, or queues it in the backlog.
  caf::expected<size_t> send(link_addr dst, uint8_t prio, const uint8_t* data,
                             size_t size) override {
    auto& st = self_->state;
    if (!st.backlog.empty()) {
      // Queue the whole packet or none of it; a full backlog makes room by
      // dropping less urgent packets first (tx_backlog.hpp).
      auto frames = inner_->frames_for(size);
      if (!st.backlog.admit(prio, tx_backlog::cost(size, frames))) {
        ++st.stats.tx_dropped;
        return make_error(ec::queue_full, "the channel's backlog is full");
      }
    }
    st.packet_sent_any = false;
    st.packet_in_backlog = false;
    auto res = inner_->send(dst, prio, data, size);
    if (!res) {
      ++st.stats.tx_dropped;
      return res;
    }
    ++st.stats.tx_packets;
    st.stats.tx_bytes += size;
    st.stats.tx_frames += *res;
    schedule_flush(self_);
    return res;
  }

  /// One prepared frame (a bundle): counted by the port that made it.
  caf::expected<size_t> send_frame(link_addr dst, uint8_t prio,
                                   const uint8_t* data, size_t size) override {
    auto& st = self_->state;
    st.packet_sent_any = false;
    st.packet_in_backlog = false;
    auto res = inner_->send_frame(dst, prio, data, size);
    schedule_flush(self_);
    return res;
  }

  bool congested() const override {
    return !self_->state.backlog.empty();
  }

private:
  channel_impl self_;
};

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
  auto& init = self->state;
  init.info = std::move(setup.info);
  init.driver = std::move(setup.driver);
  init.counters = std::move(setup.counters);
  init.rx_queue = std::move(setup.rx_queue);
  init.peer = setup.peer;
  init.tap = std::move(setup.tap);
  init.port = std::move(*port);
  init.info.max_packet = init.port->max_packet();
  init.backlog = tx_backlog{backlog_bound(init.driver->profile())};
  {
    // Retry a full driver queue after about 16 frame times, 1 to 20 ms.
    auto& p = init.driver->profile();
    auto frame_ns = (uint64_t{p.mtu} * 8 + p.frame_overhead_bits) * 1'000'000'000ull
                    / std::max<uint64_t>(p.bandwidth_bps, 1);
    auto delay = std::chrono::nanoseconds(frame_ns * 16);
    init.flush_delay = std::clamp<caf::timespan>(delay, std::chrono::milliseconds(1),
                                               std::chrono::milliseconds(20));
  }
  init.stats.id = init.info.id;
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
      // Counted, dropped or held for a bundle by the port stack.
      (void) st.port->send(dst, msg.priority, msg.bytes.data(),
                           msg.bytes.size());
      // The sender took it from this thread's cache (application support's
      // fast path, channels/thread_cache.hpp).
      recycle_buffer(std::move(msg.bytes));
    },
    [self](atom::subscribe, channel_reader_actor& reader) -> channel_info {
      auto& readers = self->state.readers;
      if (std::find(readers.begin(), readers.end(), reader) == readers.end()) {
        self->monitor(reader);
        // The reader learns of our end with a down message even when it
        // does not monitor us itself.
        self->attach(caf::default_attachable::make_monitor(self->address(),
                                                           reader.address()));
        // A late reader learns the peers heard before it came, as if they
        // were heard now: how their addresses are written (the routing
        // agent shows them so). Bounded by max_known_peers.
        auto& st = self->state;
        for (auto p : st.peers)
          self->send(reader,
                     link_event{st.info.id,
                                static_cast<uint8_t>(link_event_kind::peer_heard),
                                p, st.driver->format_addr(p)});
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
      result.rx_kernel_dropped = st.counters->kernel_dropped.load();
      result.rx_queue_dropped = st.rx_queue->dropped();
      auto& bl = st.backlog.stats();
      uint64_t* overload[] = {&result.tx_overload_control,
                              &result.tx_overload_high,
                              &result.tx_overload_normal,
                              &result.tx_overload_bulk};
      for (size_t i = 0; i < tx_backlog::classes; ++i) {
        *overload[i] = bl.refused[i] + bl.evicted[i];
        result.tx_dropped += bl.evicted[i]; // refusals are counted already
      }
      result.backlog_bytes = st.backlog.bytes();
      result.backlog_peak_bytes = bl.peak_bytes;
      result.backlog_limit_bytes = st.backlog.max_bytes();
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
      // A closing channel sends what its port stack holds, even with
      // messages still waiting (they are dropped with the channel).
      self->state.port->flush();
      self->quit(make_error(ec::channel_closed,
                            "channel " + std::to_string(self->state.info.id)
                              + " closed by its owner"));
    },
    [self](frame_received& msg) {
      auto& st = self->state;
      st.rx_queue->release(msg.bytes.size());
      ++st.stats.rx_frames;
      if (st.peers.size() < max_known_peers) {
        if (st.peers.insert(msg.src).second)
          publish(self,
                  link_event{0,
                             static_cast<uint8_t>(link_event_kind::peer_heard),
                             msg.src, st.driver->format_addr(msg.src)});
      } else if (st.peers.count(msg.src) == 0) {
        ++st.stats.rx_peers_unrecorded;
      }
      auto now = self->clock().now();
      switch (st.port->receive(msg.src, msg.lane, msg.bytes.data(),
                               msg.bytes.size(), now, st.rx_buf)) {
        case packet_port::rx::packet:
          // A bundle frame carries more than one.
          do
            deliver(self, msg.src);
          while (st.port->next_packet(st.rx_buf));
          break;
        case packet_port::rx::pending:
          schedule_tick(self);
          break;
        case packet_port::rx::dropped:
          break;
      }
      // The frame's buffer, allocated by the device for this frame, holds
      // the next packet (a packet is at most as long as the frame that
      // carries it whole): one allocation per received frame, not two.
      if (st.rx_buf.capacity() < msg.bytes.capacity()) {
        msg.bytes.clear();
        st.rx_buf.swap(msg.bytes);
      }
      recycle_buffer(std::move(msg.bytes));
    },
    [self](link_event& ev) {
      publish(self, std::move(ev));
    },
    [self](atom::tick) {
      // Both the reassembly timer and the backlog timer send tick; doing
      // both jobs on either is harmless.
      auto& st = self->state;
      st.tick_pending = false;
      st.flush_pending = false;
      st.port->expire(self->clock().now());
      schedule_tick(self);
      flush(self);
    },
  };
}

} // namespace

channel_actor spawn_channel(caf::actor_system& sys, channel_setup setup) {
  return sys.spawn([setup = std::move(setup)](channel_impl self) mutable {
    auto* st = &self->state;
    auto writer = [st](link_addr dst, uint8_t prio, const uint8_t* data,
                       size_t size) {
      return st->write_frame(dst, prio, data, size);
    };
    // make_port fails only for MTUs below 8, which the device refuses.
    auto port = make_port(setup.driver, setup.limits, writer);
    auto ptr = with_bundling(
      std::make_unique<channel_tx_port>(self, std::move(*port)),
      setup.driver->profile().mtu);
    return channel_fun(self, std::move(setup), &ptr);
  });
}

} // namespace herm
