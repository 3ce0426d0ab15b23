#include "apps/hermd/apo_kinds.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <deque>
#include <functional>

#include <spdlog/spdlog.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/sec.hpp"
#include "caf/send.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/type_description.hpp"
#include "actors/unexpected.hpp"
#include "apps/hermd/testbed_types.hpp"
#include "routing/module_id.hpp"

#ifdef HERM_HAVE_DDS_GATEWAY
#  include "apps/dds_gateway/gateway.hpp"
#endif

namespace herm::hermd {

namespace {

using namespace std::chrono_literals;

// -- options ---------------------------------------------------------------------

/// "apos[NAME] (robot.yaml:14): option 'period_ms' expects ..."
std::string where(const apo_config& cfg) {
  return "APO '" + cfg.name + "'" + (cfg.line > 0 ? " (line " + std::to_string(cfg.line) + ")" : "");
}

/// Reads option `key` (an integer in [min, max], `fallback` when absent)
/// into `out`; an error naming the APO and the option when it is not one,
/// `out` then unchanged.
caf::error u64_option(const apo_config& cfg, const std::string& key,
                      uint64_t fallback, uint64_t min, uint64_t max,
                      uint64_t& out) {
  auto i = cfg.options.find(key);
  if (i == cfg.options.end()) {
    out = fallback;
    return caf::none;
  }
  char* end = nullptr;
  errno = 0;
  auto v = std::strtoull(i->second.c_str(), &end, 10);
  if (i->second.empty() || *end != '\0' || errno != 0 || v < min || v > max)
    return make_error(ec::invalid_config,
                      where(cfg) + ": option '" + key + "' expects an integer in ["
                        + std::to_string(min) + ", " + std::to_string(max)
                        + "], got '" + i->second + "'");
  out = v;
  return caf::none;
}

std::string str_option(const apo_config& cfg, const std::string& key,
                       std::string fallback = "") {
  auto i = cfg.options.find(key);
  return i == cfg.options.end() ? fallback : i->second;
}

/// The HERM topic an APO also publishes its data on: option `topic`,
/// `fallback` when absent; "" when it is `""` or `off` (not published).
std::string topic_option(const apo_config& cfg, std::string fallback) {
  auto t = str_option(cfg, "topic", std::move(fallback));
  return t == "off" ? std::string{} : t;
}

/// Publishes `x` on the APO's topic (none: nothing). One-way: a topic
/// has no acknowledgement, and the module keeps the last value for late
/// subscribers.
template <class Self, class T>
void publish_on_topic(Self* self, const T& x) {
  auto& st = self->state;
  if (!st.opt.topic.empty())
    self->send(st.ctx.module.apps, atom::publish_v, st.opt.topic,
               caf::make_message(x));
}

/// Refuses options a kind does not read (typos).
caf::error only_options(const apo_config& cfg, std::vector<std::string> known) {
  for (auto& kv : cfg.options)
    if (std::find(known.begin(), known.end(), kv.first) == known.end()) {
      std::string list;
      for (auto& k : known)
        list += (list.empty() ? "" : ", ") + k;
      return make_error(ec::invalid_config,
                        where(cfg) + ": unknown option '" + kv.first
                          + "' for kind '" + cfg.kind + "' (known: "
                          + (list.empty() ? "none" : list) + ")");
    }
  return caf::none;
}

/// An error for the log, in HERM's terms: an APO's own request that got no
/// answer in time is a timeout, not CAF's request_timeout.
std::string describe(const caf::error& err) {
  if (err == caf::sec::request_timeout)
    return render(make_error(ec::timeout, "no answer in time"));
  return render(err);
}

// -- binding to a remote APO -----------------------------------------------------

/// A binding by name that survives its target's restarts (rebind), and
/// what its APO had to send before the binding was made: held, in order,
/// and sent once it is (so nothing is lost at start-up). At most
/// `max_held`; what a full hold refuses is counted in `refused`.
template <class T>
struct binding {
  static constexpr size_t max_held = 16;
  caf::actor proxy;
  bool pending = false;
  std::deque<T> held;
  uint64_t refused = 0;

  /// Holds `x` until the binding is made; false (counted) when full.
  bool hold(T x) {
    if (held.size() >= max_held) {
      ++refused;
      return false;
    }
    held.push_back(std::move(x));
    return true;
  }

  /// Once bound: hands what was held to `send`, oldest first.
  template <class F>
  void release(F send) {
    while (proxy && !held.empty()) {
      auto x = std::move(held.front());
      held.pop_front();
      send(std::move(x));
    }
  }
};

/// Binds `b` to the APO named `target` unless bound or binding already;
/// `flush` runs once bound (to send what was held).
template <class Self, class T>
void ensure_bound(Self* self, binding<T>& b, const app_support_actor& apps,
                  const std::string& target,
                  std::function<void()> flush = nullptr) {
  if (b.proxy || b.pending)
    return;
  b.pending = true;
  self->request(apps, 5s, atom::bind_v,
                bind_request{query_by::name, target, 1000, true})
    .then(
      [&b, target, flush](caf::actor& proxy) {
        b.pending = false;
        b.proxy = proxy;
        spdlog::info("bound to APO '{}'", target);
        if (flush)
          flush();
      },
      [&b, target](caf::error& err) {
        b.pending = false;
        spdlog::debug("binding to '{}' not yet possible: {}", target,
                      render(err));
      });
}

/// What the log calls a message an APO sends to its target, and what it
/// holds.
std::string label(const sonar_batch& b) {
  return "sonar batch " + std::to_string(b.batch);
}
std::string contents(const sonar_batch& b) {
  return std::to_string(b.distances_mm.size()) + " readings";
}
std::string label(const vision_frame& f) {
  return "vision frame " + std::to_string(f.seq);
}
std::string contents(const vision_frame& f) {
  return std::to_string(f.data.size()) + " bytes";
}

// The three below serve every APO that sends to a target bound by name:
// `Self` is its stateful actor; the state has apo_name, opt.target,
// ack_timeout() and the binding `target`.

/// Requests `x` from the bound target: logs the send, then its
/// acknowledgement with the time it took, or its failure.
template <class Self, class T>
void request_target(Self* self, T x) {
  auto& st = self->state;
  auto what = label(x);
  auto t0 = std::chrono::steady_clock::now();
  spdlog::info("{}: {} ({}) -> '{}'", st.apo_name, what, contents(x),
               st.opt.target);
  self->request(st.target.proxy, st.ack_timeout(), std::move(x))
    .then(
      [self, what, t0](uint32_t) {
        auto us = std::chrono::duration_cast<std::chrono::microseconds>(
                    std::chrono::steady_clock::now() - t0)
                    .count();
        spdlog::info("{}: {} acknowledged ({:.1f} ms)", self->state.apo_name,
                     what, us / 1000.0);
      },
      [self, what](caf::error& err) {
        spdlog::warn("{}: {} failed: {}", self->state.apo_name, what,
                     describe(err));
      });
}

/// Binds the target unless bound or binding already; once bound, requests
/// what was held, oldest first.
template <class Self>
void bind_target(Self* self) {
  auto& st = self->state;
  ensure_bound(self, st.target, st.ctx.module.apps, st.opt.target, [self] {
    self->state.target.release(
      [self](auto x) { request_target(self, std::move(x)); });
  });
}

/// Requests `x` from the target when bound; otherwise binds and holds `x`
/// until then, or drops it (counted) when the hold is full. Logs which.
template <class Self, class T>
void send_to_target(Self* self, T x) {
  auto& st = self->state;
  bind_target(self);
  if (st.target.proxy) {
    request_target(self, std::move(x));
    return;
  }
  auto what = label(x);
  if (st.target.hold(std::move(x)))
    spdlog::info("{}: {} held until '{}' is bound ({} held)", st.apo_name,
                 what, st.opt.target, st.target.held.size());
  else
    spdlog::warn("{}: {} dropped: '{}' not bound yet and {} held already ({} "
                 "dropped so far)",
                 st.apo_name, what, st.opt.target, st.target.held.size(),
                 st.target.refused);
}

// -- collector ---------------------------------------------------------------------

struct collector_state {
  static inline const char* name = "herm.apo.collector";
  uint64_t batches = 0;
  uint64_t frames = 0;
};

caf::behavior collector(caf::stateful_actor<collector_state>* self) {
  self->set_default_handler(log_unexpected);
  return {
    [self](const sonar_batch& b) -> uint32_t {
      ++self->state.batches;
      auto [lo, hi] = std::minmax_element(b.distances_mm.begin(),
                                          b.distances_mm.end());
      spdlog::info("collector: sonar batch {} from {}: {} readings (seq {}..), "
                   "{}..{} mm",
                   b.batch, b.source, b.distances_mm.size(), b.first_seq,
                   b.distances_mm.empty() ? 0 : *lo,
                   b.distances_mm.empty() ? 0 : *hi);
      return b.batch;
    },
    [self](const vision_frame& f) -> uint32_t {
      ++self->state.frames;
      spdlog::info("collector: vision frame {} from {}: {} bytes", f.seq,
                   f.source, f.data.size());
      return f.seq;
    },
  };
}

// -- srf04_batcher -------------------------------------------------------------------

struct sonar_options {
  std::string device;
  uint64_t baud = 9600;
  uint64_t batch = 10;
  std::string target = "collector";
  /// Each reading is also published here ("": not published).
  std::string topic = "sonar";
};

struct sonar_state {
  static inline const char* name = "herm.apo.srf04_batcher";
  sonar_options opt;
  apo_context ctx;
  std::string apo_name;
  std::vector<uint16_t> readings;
  uint32_t first_seq = 0;
  uint32_t batches = 0;
  uint64_t malformed = 0;
  uint64_t out_of_range = 0;
  channel_actor line;
  binding<sonar_batch> target;

  std::chrono::milliseconds ack_timeout() const {
    return 10s;
  }
};

using sonar_actor = caf::stateful_actor<sonar_state>;

caf::expected<sonar_options> sonar_opts(const apo_config& cfg) {
  if (auto err = only_options(cfg, {"device", "baud", "batch", "target", "topic"}))
    return err;
  sonar_options o;
  // Without a device the readings come from a board that is a module of
  // its own (apps/mcu), as requests carrying herm::hermd::srf04_reading.
  o.device = str_option(cfg, "device");
  if (auto err = u64_option(cfg, "baud", 9600, 50, 4000000, o.baud))
    return err;
  if (auto err = u64_option(cfg, "batch", 10, 1, 1000, o.batch))
    return err;
  o.target = str_option(cfg, "target", "collector");
  o.topic = topic_option(cfg, "sonar");
  return o;
}

void open_sensor_line(sonar_actor* self);

void retry_sensor_line(sonar_actor* self) {
  self->delayed_send(self, 1s, atom::retry_v);
}

void open_sensor_line(sonar_actor* self) {
  auto& st = self->state;
  auto dev_name = "sonar:" + st.apo_name;
  device_config dev{dev_name, "serial", st.opt.device,
                    {{"baud", std::to_string(st.opt.baud)}}};
  auto io = st.ctx.module.io;
  auto failed = [self](caf::error& err) {
    spdlog::warn("{}: cannot open the sensor line: {}", self->state.apo_name,
                 render(err));
    retry_sensor_line(self);
  };
  // Forget an earlier attempt's device (absent the first time).
  self->request(io, 5s, atom::close_v, dev_name).then([] {}, [](caf::error&) {});
  self->request(io, 5s, atom::add_v, dev)
    .then(
      [self, io, dev_name, failed](device_info&) {
        self->request(io, 5s, atom::open_v,
                      channel_request{dev_name, "*", false, true})
          .then(
            [self](channel_actor& ch, channel_info& info) {
              self->state.line = ch;
              self->request(ch, 5s, atom::subscribe_v,
                            caf::actor_cast<channel_reader_actor>(self))
                .then([](channel_info&) {}, [](caf::error&) {});
              spdlog::info("{}: reading the SRF04 board on {} ({} baud, MTU {})",
                           self->state.apo_name, self->state.opt.device,
                           self->state.opt.baud, info.profile.mtu);
            },
            failed);
      },
      failed);
}

void send_batch(sonar_actor* self) {
  auto& st = self->state;
  sonar_batch b{st.ctx.module_name, ++st.batches, st.first_seq, std::move(st.readings)};
  st.readings.clear();
  send_to_target(self, std::move(b));
}

/// One reading, from the local line or from the board as a module: it is
/// published on the APO's topic as it came (nothing in range too: a
/// subscriber such as the DDS gateway says so its own way); a reading
/// without an echo in range is then counted, not batched.
void take_reading(sonar_actor* self, const srf04_reading& r) {
  auto& s = self->state;
  publish_on_topic(self, r);
  if (r.distance_mm == srf04_out_of_range) {
    ++s.out_of_range;
    spdlog::debug("{}: SRF04 reading {}: nothing in range ({} so far)",
                  s.apo_name, r.seq, s.out_of_range);
    return;
  }
  if (s.readings.empty())
    s.first_seq = r.seq;
  s.readings.push_back(r.distance_mm);
  spdlog::debug("{}: SRF04 reading {}: {} mm ({} us)", s.apo_name, r.seq,
                r.distance_mm, r.echo_us);
  if (s.readings.size() >= s.opt.batch)
    send_batch(self);
}

caf::behavior srf04_batcher(sonar_actor* self, apo_context ctx,
                            sonar_options opt, std::string apo_name) {
  auto& st = self->state;
  st.ctx = std::move(ctx);
  st.opt = std::move(opt);
  st.apo_name = std::move(apo_name);
  self->set_down_handler([self](caf::down_msg& msg) {
    if (self->state.line && msg.source == self->state.line.address()) {
      spdlog::warn("{}: sensor line ended: {}", self->state.apo_name,
                   render(msg.reason));
      self->state.line = nullptr;
      retry_sensor_line(self);
    }
  });
  self->attach_functor([io = st.ctx.module.io, dev = "sonar:" + st.apo_name] {
    caf::anon_send(io, atom::close_v, dev);
  });
  self->set_default_handler(log_unexpected);
  if (!st.opt.device.empty())
    open_sensor_line(self);
  else
    spdlog::info("{}: waiting for readings from an SRF04 board module",
                 st.apo_name);
  bind_target(self);
  return {
    [self](packet_received& pkt) {
      auto& s = self->state;
      auto r = decode_srf04(pkt.bytes.data(), pkt.bytes.size());
      if (!r) {
        ++s.malformed;
        spdlog::warn("{}: dropped a malformed reading ({} so far): {}",
                     s.apo_name, s.malformed, render(r.error()));
        return;
      }
      take_reading(self, *r);
    },
    // From a board that is a module (the C client): answered with an empty
    // message once taken.
    [self](const srf04_reading& r) { take_reading(self, r); },
    [](link_event&) {},
    [self](atom::retry) {
      if (!self->state.line && !self->state.opt.device.empty())
        open_sensor_line(self);
    },
  };
}

// -- vision_source -------------------------------------------------------------------

struct vision_options {
  uint64_t period_ms = 60000;
  uint64_t bytes = 100;
  std::string target = "collector";
  /// Each frame is also published here ("": not published).
  std::string topic = "vision";
};

struct vision_state {
  static inline const char* name = "herm.apo.vision_source";
  vision_options opt;
  apo_context ctx;
  std::string apo_name;
  uint32_t seq = 0;
  binding<vision_frame> target;

  /// A frame not acknowledged before the next one is due has failed.
  std::chrono::milliseconds ack_timeout() const {
    return std::chrono::milliseconds(opt.period_ms);
  }
};

using vision_actor = caf::stateful_actor<vision_state>;

caf::expected<vision_options> vision_opts(const apo_config& cfg) {
  if (auto err = only_options(cfg, {"period_ms", "bytes", "target", "topic"}))
    return err;
  vision_options o;
  if (auto err = u64_option(cfg, "period_ms", 60000, 1, 86400000, o.period_ms))
    return err;
  if (auto err = u64_option(cfg, "bytes", 100, 0, 60000, o.bytes))
    return err;
  o.target = str_option(cfg, "target", "collector");
  o.topic = topic_option(cfg, "vision");
  return o;
}

caf::behavior vision_source(vision_actor* self, apo_context ctx,
                            vision_options opt, std::string apo_name) {
  auto& init = self->state;
  init.ctx = std::move(ctx);
  init.opt = std::move(opt);
  init.apo_name = std::move(apo_name);
  self->set_default_handler(log_unexpected);
  bind_target(self);
  self->delayed_send(self, std::chrono::milliseconds(init.opt.period_ms),
                     atom::tick_v);
  return {
    [self](atom::tick) {
      auto& st = self->state;
      self->delayed_send(self, std::chrono::milliseconds(st.opt.period_ms),
                         atom::tick_v);
      auto seq = ++st.seq;
      vision_frame f{st.ctx.module_name, seq, std::vector<uint8_t>(st.opt.bytes)};
      for (size_t i = 0; i < f.data.size(); ++i)
        f.data[i] = static_cast<uint8_t>(seq + i);
      publish_on_topic(self, f);
      send_to_target(self, std::move(f));
    },
  };
}

// -- echo --------------------------------------------------------------------------

/// Answers any request with its own content, whatever its types (a
/// string, a struct, several values); one-way messages have nobody to go
/// back to and are dropped.
caf::behavior echo(caf::event_based_actor* self) {
  self->set_default_handler(
    [](caf::scheduled_actor*, caf::message_view& x) -> caf::result<caf::message> {
      return x.move_content_to_message();
    });
  // A behavior must not be empty (the actor would end at once): strings
  // are the usual probe.
  return {
    [](std::string& text) { return text; },
  };
}

// -- the registry ------------------------------------------------------------------

/// A kind whose options `parse` reads (check runs it, spawn runs it again)
/// and whose APO runs `fun` with them and its configured name.
template <class Options, class Actor>
apo_kind kind_with_options(std::string name, std::string description,
                           caf::expected<Options> (*parse)(const apo_config&),
                           caf::behavior (*fun)(Actor*, apo_context, Options,
                                                std::string)) {
  return {std::move(name), std::move(description),
          [parse](const apo_config& cfg) -> caf::error {
            auto o = parse(cfg);
            return o ? caf::error{} : o.error();
          },
          [parse, fun](const apo_context& ctx,
                       const apo_config& cfg) -> caf::expected<caf::actor> {
            auto o = parse(cfg);
            if (!o)
              return o.error();
            return ctx.sys->spawn(fun, ctx, *o, cfg.name);
          }};
}

std::vector<apo_kind> make_kinds() {
  std::vector<apo_kind> kinds;
  kinds.push_back(
    {"collector",
     "receives sonar batches and vision frames and acknowledges each (the "
     "main controller's APO)",
     [](const apo_config& cfg) { return only_options(cfg, {}); },
     [](const apo_context& ctx, const apo_config&) -> caf::expected<caf::actor> {
       return ctx.sys->spawn(collector);
     }});
  kinds.push_back(kind_with_options(
    "srf04_batcher",
    "collects SRF04 ultrasonic readings, from a board on a local serial line "
    "(option device) or from a board that is a HERM module (requests of "
    "herm::hermd::srf04_reading), publishes each on the topic `topic` and "
    "sends every `batch` readings to the APO `target` (options: device, baud, "
    "batch, target, topic)",
    sonar_opts, srf04_batcher));
  kinds.push_back(kind_with_options(
    "vision_source",
    "sends `bytes` bytes of vision data every `period_ms` to the APO `target` "
    "and publishes each frame on the topic `topic` (options: period_ms, bytes, "
    "target, topic)",
    vision_opts, vision_source));
  kinds.push_back({"echo", "answers every request with the request itself",
                   [](const apo_config& cfg) { return only_options(cfg, {}); },
                   [](const apo_context& ctx,
                      const apo_config&) -> caf::expected<caf::actor> {
                     return ctx.sys->spawn(echo);
                   }});
#ifdef HERM_HAVE_DDS_GATEWAY
  // The DDS / ROS 2 gateway (apps/dds_gateway, docs/gateway.md).
  kinds.push_back(
    {"dds_gateway",
     "joins HERM topics and DDS / ROS 2 topics (options: domain, "
     "<topic>.type, <topic>.direction, ...; docs/gateway.md)",
     [](const apo_config& cfg) -> caf::error {
       auto o = dds_gateway::parse_gateway_options(cfg.options);
       return o ? caf::error{} : o.error();
     },
     [](const apo_context& ctx,
        const apo_config& cfg) -> caf::expected<caf::actor> {
       auto o = dds_gateway::parse_gateway_options(cfg.options);
       if (!o)
         return o.error();
       return dds_gateway::spawn_dds_gateway(*ctx.sys, ctx.module,
                                             std::move(*o));
     }});
#endif
  return kinds;
}

} // namespace

const std::vector<apo_kind>& apo_kinds() {
  static const auto kinds = make_kinds();
  return kinds;
}

const apo_kind* find_apo_kind(const std::string& name) {
  for (auto& k : apo_kinds())
    if (k.name == name)
      return &k;
  return nullptr;
}

void add_apo_types(caf::actor_system_config& cfg) {
  cfg.add_message_types<caf::id_block::herm_apos>();
  // Field names, so that hermctl prints and parses them by name.
  for (auto err : {describe_type<srf04_reading>("herm::hermd::srf04_reading",
                                                {"seq", "distance_mm", "echo_us"}),
                   describe_type<sonar_batch>("herm::hermd::sonar_batch",
                                              {"source", "batch", "first_seq",
                                               "distances_mm"}),
                   describe_type<vision_frame>("herm::hermd::vision_frame",
                                               {"source", "seq", "data"})})
    if (err)
      throw std::logic_error(render(err));
#ifdef HERM_HAVE_DDS_GATEWAY
  dds_gateway::add_gateway_types(cfg);
#endif
}

} // namespace herm::hermd
