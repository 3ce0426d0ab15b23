#include "channels/io_manager.hpp"

#include <algorithm>
#include <map>
#include <optional>

#include "caf/actor_system.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "channels/error.hpp"
#include "channels/type_ids.hpp"

namespace herm {

namespace {

/// How long the IO manager waits for a device to create a channel.
constexpr auto device_timeout = std::chrono::seconds(5);

struct device_slot {
  device_config config;
  device_actor handle; // null while the device is closed or failed
  device_info last_info;
};

struct channel_slot {
  channel_request request;
  channel_actor handle; // null unless up
  channel_info info;
  std::string state = "retrying";
  std::string last_error;
  uint32_t restarts = 0;
  caf::timespan backoff{0};
  bool retry_scheduled = false;
};

struct io_manager_state {
  static inline const char* name = "herm.io_manager";

  backoff_policy backoff;
  packet_tap_ptr tap;
  std::map<std::string, device_slot> devices;
  std::map<channel_id, channel_slot> channels;
  std::vector<io_listener_actor> listeners;
  channel_id next_id = 1;
  /// Devices to close when the IO manager exits; shared with the exit hook
  /// because the state is gone by the time attached functors run.
  std::shared_ptr<std::map<std::string, device_actor>> running
    = std::make_shared<std::map<std::string, device_actor>>();
};

using io_impl = io_manager_actor::stateful_pointer<io_manager_state>;

/// Errors after which retrying cannot help.
bool permanent(const caf::error& err) {
  return is(err, ec::unknown_link_kind) || is(err, ec::invalid_parameter)
         || is(err, ec::invalid_address) || is(err, ec::already_exists);
}

/// Returns the running device actor for `name`, opening it if needed.
caf::expected<device_actor> ensure_device(io_impl self,
                                          const std::string& name) {
  auto i = self->state.devices.find(name);
  if (i == self->state.devices.end())
    return make_error(ec::unknown_device, "no device named '" + name + "'");
  auto& slot = i->second;
  if (slot.handle)
    return slot.handle;
  auto dev = spawn_device(self->system(), slot.config, self->state.tap);
  if (!dev)
    return std::move(dev.error());
  slot.handle = *dev;
  self->monitor(slot.handle);
  (*self->state.running)[name] = slot.handle;
  return slot.handle;
}

/// True for a channel its client keeps to itself (channel_request::local):
/// listeners never hear of it.
bool is_local(io_impl self, channel_id id) {
  auto i = self->state.channels.find(id);
  return i != self->state.channels.end() && i->second.request.local;
}

void notify(io_impl self, const channel_up& msg) {
  if (is_local(self, msg.info.id))
    return;
  for (auto& l : self->state.listeners)
    self->send(l, msg);
}

void notify(io_impl self, const channel_down& msg) {
  if (is_local(self, msg.id))
    return;
  for (auto& l : self->state.listeners)
    self->send(l, msg);
}

void schedule_retry(io_impl self, channel_id id) {
  auto& slot = self->state.channels[id];
  if (slot.retry_scheduled)
    return;
  auto& policy = self->state.backoff;
  slot.backoff = slot.backoff.count() == 0
                   ? policy.first
                   : std::min(policy.max, slot.backoff * 2);
  slot.retry_scheduled = true;
  slot.state = "retrying";
  self->delayed_send(self, slot.backoff, atom::retry_v, id);
}

using open_promise = caf::typed_response_promise<channel_actor, channel_info>;

/// Creates channel `id` on its device; delivers to `rp` if given.
void open_channel(io_impl self, channel_id id, std::optional<open_promise> rp) {
  auto& slot = self->state.channels[id];
  auto fail = [self, id](caf::error err, std::optional<open_promise>& prom) {
    auto i = self->state.channels.find(id);
    if (i == self->state.channels.end())
      return;
    auto& s = i->second;
    s.last_error = render(err);
    if (s.request.persistent && !permanent(err)) {
      schedule_retry(self, id);
    } else {
      self->state.channels.erase(i);
    }
    if (prom)
      prom->deliver(std::move(err));
  };
  auto dev = ensure_device(self, slot.request.device);
  if (!dev) {
    fail(std::move(dev.error()), rp);
    return;
  }
  self->request(*dev, device_timeout, atom::open_v, slot.request, id)
    .then(
      [self, id, rp](channel_actor& ch, channel_info& info) mutable {
        auto i = self->state.channels.find(id);
        if (i == self->state.channels.end()) {
          // Closed while we waited.
          self->send(ch, atom::close_v);
          if (rp)
            rp->deliver(make_error(ec::channel_closed,
                                   "channel " + std::to_string(id)
                                     + " was closed while opening"));
          return;
        }
        auto& s = i->second;
        s.handle = ch;
        s.info = info;
        s.state = "up";
        s.last_error.clear();
        s.backoff = caf::timespan{0};
        self->monitor(ch);
        notify(self, channel_up{info, ch});
        if (rp)
          rp->deliver(std::move(ch), std::move(info));
      },
      [rp, fail](caf::error& err) mutable { fail(std::move(err), rp); });
}

io_manager_actor::behavior_type io_manager_fun(io_impl self,
                                               backoff_policy backoff,
                                               packet_tap_ptr tap) {
  self->state.backoff = backoff;
  self->state.tap = std::move(tap);
  // Devices (and with them their channels) end with the IO manager.
  self->attach_functor([running = self->state.running](const caf::error& reason) {
    for (auto& kv : *running)
    {
      // A normal exit would be ignored by the device: use user_shutdown.
      caf::error why = reason ? reason
                              : caf::make_error(caf::exit_reason::user_shutdown);
      kv.second->enqueue(nullptr, caf::make_message_id(),
                         caf::make_message(caf::exit_msg{kv.second.address(),
                                                         std::move(why)}),
                         nullptr);
    }
    running->clear();
  });
  self->set_down_handler([self](caf::down_msg& msg) {
    auto& st = self->state;
    // A listener?
    auto li = std::find_if(st.listeners.begin(), st.listeners.end(),
                           [&](auto& l) { return l.address() == msg.source; });
    if (li != st.listeners.end()) {
      st.listeners.erase(li);
      return;
    }
    // A device?
    for (auto& kv : st.devices)
      if (kv.second.handle && kv.second.handle.address() == msg.source) {
        kv.second.handle = nullptr;
        st.running->erase(kv.first);
        return;
      }
    // A channel.
    for (auto i = st.channels.begin(); i != st.channels.end(); ++i) {
      auto& slot = i->second;
      if (!slot.handle || slot.handle.address() != msg.source)
        continue;
      auto id = i->first;
      slot.handle = nullptr;
      slot.last_error = render(msg.reason);
      bool retry = slot.request.persistent
                   && !is(msg.reason, ec::channel_closed);
      notify(self, channel_down{id, msg.reason, retry});
      if (retry) {
        ++slot.restarts;
        schedule_retry(self, id);
      } else {
        st.channels.erase(i);
      }
      return;
    }
  });
  return {
    [self](atom::add, device_config& cfg) -> caf::result<device_info> {
      auto& st = self->state;
      if (cfg.name.empty())
        return make_error(ec::invalid_parameter, "a device needs a name");
      if (st.devices.count(cfg.name) > 0)
        return make_error(ec::already_exists,
                          "a device named '" + cfg.name + "' exists");
      auto dev = spawn_device(self->system(), cfg, st.tap);
      if (!dev && permanent(dev.error()))
        return std::move(dev.error());
      auto& slot = st.devices[cfg.name];
      slot.config = cfg;
      slot.last_info.config = cfg;
      if (!dev) {
        // Transient: keep the configuration; channels retry with backoff.
        return std::move(dev.error());
      }
      slot.handle = *dev;
      self->monitor(slot.handle);
      (*st.running)[cfg.name] = slot.handle;
      auto rp = self->make_response_promise<device_info>();
      self->request(slot.handle, device_timeout, atom::get_v, atom::info_v)
        .then(
          [self, rp, name = cfg.name](device_info& info) mutable {
            self->state.devices[name].last_info = info;
            rp.deliver(std::move(info));
          },
          [rp](caf::error& err) mutable { rp.deliver(std::move(err)); });
      return rp;
    },
    [self](atom::open, channel_request& req)
      -> caf::result<channel_actor, channel_info> {
      auto& st = self->state;
      if (st.devices.count(req.device) == 0)
        return make_error(ec::unknown_device,
                          "no device named '" + req.device + "'");
      auto id = st.next_id++;
      st.channels[id].request = std::move(req);
      auto rp = self->make_response_promise<channel_actor, channel_info>();
      open_channel(self, id, rp);
      return rp;
    },
    [self](atom::close, channel_id id) -> caf::result<void> {
      auto& st = self->state;
      auto i = st.channels.find(id);
      if (i == st.channels.end())
        return make_error(ec::unknown_channel,
                          "no channel with id " + std::to_string(id));
      if (i->second.handle) {
        self->demonitor(i->second.handle.address());
        self->send(i->second.handle, atom::close_v);
        notify(self,
               channel_down{id, make_error(ec::channel_closed, "closed"), false});
      }
      st.channels.erase(i);
      return caf::unit;
    },
    [self](atom::close, std::string& device) -> caf::result<void> {
      auto& st = self->state;
      auto d = st.devices.find(device);
      if (d == st.devices.end())
        return make_error(ec::unknown_device, "no device named '" + device + "'");
      for (auto i = st.channels.begin(); i != st.channels.end();) {
        if (i->second.request.device != device) {
          ++i;
          continue;
        }
        if (i->second.handle) {
          self->demonitor(i->second.handle.address());
          self->send(i->second.handle, atom::close_v);
          notify(self, channel_down{i->first,
                                    make_error(ec::channel_closed, "closed"),
                                    false});
        }
        i = st.channels.erase(i);
      }
      if (d->second.handle) {
        self->demonitor(d->second.handle.address());
        self->send_exit(d->second.handle, caf::exit_reason::user_shutdown);
      }
      st.running->erase(device);
      st.devices.erase(d);
      return caf::unit;
    },
    [self](atom::get, atom::channels) -> std::vector<channel_entry> {
      std::vector<channel_entry> result;
      for (auto& kv : self->state.channels) {
        auto& s = kv.second;
        result.push_back(channel_entry{kv.first, s.request, s.state,
                                       s.last_error, s.restarts, s.info});
      }
      return result;
    },
    [self](atom::get, atom::devices) -> std::vector<device_info> {
      std::vector<device_info> result;
      for (auto& kv : self->state.devices)
        result.push_back(kv.second.last_info);
      return result;
    },
    [self](atom::get, channel_id id) -> caf::result<channel_actor> {
      auto i = self->state.channels.find(id);
      if (i == self->state.channels.end() || !i->second.handle)
        return make_error(ec::unknown_channel,
                          "no open channel with id " + std::to_string(id));
      return i->second.handle;
    },
    [self](atom::subscribe, io_listener_actor& listener) {
      self->monitor(listener);
      for (auto& kv : self->state.channels)
        if (kv.second.handle && !kv.second.request.local)
          self->send(listener, channel_up{kv.second.info, kv.second.handle});
      self->state.listeners.push_back(std::move(listener));
    },
    [self](atom::retry, channel_id id) {
      auto i = self->state.channels.find(id);
      if (i == self->state.channels.end())
        return;
      i->second.retry_scheduled = false;
      if (!i->second.handle)
        open_channel(self, id, std::nullopt);
    },
  };
}

} // namespace

io_manager_actor spawn_io_manager(caf::actor_system& sys,
                                  backoff_policy backoff, packet_tap_ptr tap) {
  return sys.spawn(io_manager_fun, backoff, std::move(tap));
}

} // namespace herm
