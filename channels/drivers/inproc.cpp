// The "inproc" link kind: an in-memory medium for unit and actor tests. A
// segment is a named bus inside one process; every driver on it is a
// station. Delivery is immediate and happens on the sender's thread, so
// actor tests under CAF's test_coordinator stay deterministic.
//
// Options: profile (default "ethernet") and its overrides, station
// (1..65534, default: lowest free).

#include "channels/drivers/inproc.hpp"

#include <map>
#include <mutex>
#include <vector>

#include "channels/drivers/params.hpp"
#include "channels/error.hpp"
#include "channels/link_driver.hpp"
#include "channels/options.hpp"

namespace herm {

namespace {

struct segment {
  std::map<link_addr, std::weak_ptr<frame_handler>> stations;
  bool unplugged = false;
  bool blackholed = false;
};

struct registry {
  std::mutex mtx;
  std::map<std::string, segment> segments;

  static registry& get() {
    static registry instance;
    return instance;
  }
};

class inproc_driver : public link_driver {
public:
  inproc_driver(std::string seg, link_addr station, link_profile profile)
    : segment_(std::move(seg)), station_(station), profile_(std::move(profile)) {
    // nop
  }

  ~inproc_driver() override {
    stop();
  }

  caf::error start(std::shared_ptr<frame_handler> handler,
                   event_loop&) override {
    auto& reg = registry::get();
    std::lock_guard<std::mutex> guard{reg.mtx};
    auto& seg = reg.segments[segment_];
    seg.stations[station_] = handler;
    handler_ = std::move(handler);
    return caf::none;
  }

  void stop() override {
    if (stopped_)
      return;
    stopped_ = true;
    auto& reg = registry::get();
    std::lock_guard<std::mutex> guard{reg.mtx};
    auto i = reg.segments.find(segment_);
    if (i != reg.segments.end()) {
      auto j = i->second.stations.find(station_);
      // Erase our entry: the reservation from open (expired) or our handler.
      if (j != i->second.stations.end()
          && (j->second.expired() || j->second.lock() == handler_))
        i->second.stations.erase(j);
      if (i->second.stations.empty() && !i->second.unplugged)
        reg.segments.erase(i);
    }
    handler_.reset();
  }

  caf::error send(link_addr dst, const uint8_t* data, size_t size,
                  uint8_t) override {
    if (size > profile_.mtu)
      return make_error(ec::packet_too_large,
                        std::to_string(size) + " bytes exceed the MTU of "
                          + std::to_string(profile_.mtu));
    receivers_.clear();
    {
      auto& reg = registry::get();
      std::lock_guard<std::mutex> guard{reg.mtx};
      auto i = reg.segments.find(segment_);
      if (i == reg.segments.end() || i->second.unplugged)
        return make_error(ec::device_failed,
                          "inproc segment '" + segment_ + "' is unplugged");
      if (i->second.blackholed)
        return caf::none;
      if (dst == broadcast_addr) {
        for (auto& kv : i->second.stations)
          if (kv.first != station_)
            if (auto hdl = kv.second.lock())
              receivers_.push_back(std::move(hdl));
      } else if (auto j = i->second.stations.find(dst);
                 j != i->second.stations.end()) {
        if (auto hdl = j->second.lock())
          receivers_.push_back(std::move(hdl));
      }
    }
    for (auto& hdl : receivers_)
      hdl->on_frame(station_, data, size);
    receivers_.clear();
    return caf::none;
  }

  const link_profile& profile() const override {
    return profile_;
  }

  link_addr local_addr() const override {
    return station_;
  }

  std::string format_addr(link_addr addr) const override {
    return std::to_string(addr);
  }

  caf::expected<link_addr> parse_addr(const std::string& str) const override {
    return parse_station(str);
  }

  static caf::expected<link_addr> parse_station(const std::string& str) {
    if (str.empty() || str.size() > 5
        || str.find_first_not_of("0123456789") != std::string::npos)
      return make_error(ec::invalid_address,
                        "'" + str + "' is not an inproc station (1..65534)");
    auto val = std::stoul(str);
    if (val < 1 || val > 65534)
      return make_error(ec::invalid_address,
                        "'" + str + "' is not an inproc station (1..65534)");
    return link_addr{val};
  }

private:
  std::string segment_;
  link_addr station_;
  link_profile profile_;
  std::shared_ptr<frame_handler> handler_;
  bool stopped_ = false;
  // Scratch list so a send does not allocate once warmed up; send is called
  // from the owning channel actor only.
  std::vector<std::shared_ptr<frame_handler>> receivers_;
};

/// An inproc device's options: its link profile and the station it asks
/// for (0: the first free one).
struct inproc_options {
  link_profile profile;
  uint64_t station = 0;
};

/// The one parser of open_inproc and the kind's check; touches no segment.
caf::expected<inproc_options> read_inproc_options(const device_config& cfg) {
  option_reader opts{cfg};
  inproc_options result;
  if (auto err = read_into(result.profile, opts.profile("ethernet")))
    return err;
  if (auto err = read_into(result.station, opts.u64("station", 0, 0, 65534)))
    return err;
  if (auto err = opts.finish())
    return err;
  if (cfg.interface.empty())
    return opts.fail(ec::invalid_address, "an inproc device needs a segment name");
  return result;
}

caf::error check_inproc(const device_config& cfg) {
  auto x = read_inproc_options(cfg);
  return x ? caf::error{} : std::move(x.error());
}

caf::expected<link_driver_ptr> open_inproc(const device_config& cfg) {
  auto parsed = read_inproc_options(cfg);
  if (!parsed)
    return std::move(parsed.error());
  option_reader opts{cfg};
  auto& reg = registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  auto& seg = reg.segments[cfg.interface];
  if (seg.unplugged)
    return opts.fail(ec::device_unavailable,
                     "inproc segment '" + cfg.interface + "' is unplugged");
  // An entry is either a running station or a reservation from an open
  // whose start has not happened yet.
  auto taken = [&](link_addr x) { return seg.stations.count(x) > 0; };
  link_addr addr = parsed->station;
  if (addr == 0) {
    addr = 1;
    while (taken(addr))
      ++addr;
  } else if (taken(addr)) {
    return opts.fail(ec::already_exists,
                     "station " + std::to_string(addr) + " on inproc segment '"
                       + cfg.interface + "' is taken");
  }
  // Reserve the station until start() installs the real handler.
  seg.stations[addr] = std::weak_ptr<frame_handler>{};
  return link_driver_ptr{
    std::make_shared<inproc_driver>(cfg.interface, addr, parsed->profile)};
}

} // namespace

namespace inproc {

void unplug(const std::string& name, caf::error reason) {
  std::vector<std::shared_ptr<frame_handler>> victims;
  {
    auto& reg = registry::get();
    std::lock_guard<std::mutex> guard{reg.mtx};
    auto& seg = reg.segments[name];
    seg.unplugged = true;
    for (auto& kv : seg.stations)
      if (auto hdl = kv.second.lock())
        victims.push_back(std::move(hdl));
    seg.stations.clear();
  }
  for (auto& hdl : victims)
    hdl->on_failure(reason);
}

void replug(const std::string& name) {
  auto& reg = registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  auto i = reg.segments.find(name);
  if (i != reg.segments.end()) {
    i->second.unplugged = false;
    if (i->second.stations.empty())
      reg.segments.erase(i);
  }
}

void blackhole(const std::string& name, bool on) {
  auto& reg = registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  auto i = reg.segments.find(name);
  if (i != reg.segments.end())
    i->second.blackholed = on;
}

size_t stations(const std::string& name) {
  auto& reg = registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  auto i = reg.segments.find(name);
  return i == reg.segments.end() ? 0 : i->second.stations.size();
}

} // namespace inproc

const link_kind& inproc_link_kind() {
  static const link_kind kind{"inproc", "in-process medium for tests",
                              open_inproc, check_inproc};
  return kind;
}

} // namespace herm
