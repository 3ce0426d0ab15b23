#include "channels/link_driver.hpp"

#include <deque>
#include <mutex>

#include "channels/error.hpp"
#include "channels/event_loop.hpp"
#include "channels/options.hpp"

namespace herm {

#define HERM_LINK_KIND(x) const link_kind& x##_link_kind();
#include "channels/link_kinds.def"
#undef HERM_LINK_KIND

frame_handler::~frame_handler() = default;

void frame_handler::on_frame_in_lane(link_addr src, uint8_t, const uint8_t* data,
                                     size_t size) {
  on_frame(src, data, size);
}

void frame_handler::on_kernel_drops(uint64_t) {
  // nop
}

link_driver::~link_driver() = default;

caf::error link_driver::start(std::shared_ptr<frame_handler> handler) {
  return start(std::move(handler), shared_io_loop());
}

size_t link_driver::send_batch(const tx_frame* frames, size_t n,
                               caf::error& err) {
  err = caf::error{};
  for (size_t i = 0; i < n; ++i) {
    auto& f = frames[i];
    if (auto e = send(f.dst, f.data, f.size, f.priority)) {
      err = std::move(e);
      return i;
    }
  }
  return n;
}

uint8_t link_driver::lane(link_addr, uint8_t) const {
  return 0;
}

caf::error link_driver::set_param(const std::string& key, const std::string&) {
  return make_error(ec::invalid_parameter,
                    "parameter '" + key + "' cannot be changed on this link");
}

caf::expected<std::string> link_driver::get_param(const std::string& key) const {
  auto& p = profile();
  if (key == "bandwidth")
    return std::to_string(p.bandwidth_bps);
  if (key == "mtu")
    return std::to_string(p.mtu);
  if (key == "delay_coef")
    return format_double(p.delay_coef);
  if (key == "profile")
    return p.name;
  return make_error(ec::invalid_parameter, "unknown parameter '" + key + "'");
}

namespace {

/// Every known kind. A deque keeps the added entries where they are, so the
/// pointers find_link_kind hands out stay valid while others are added.
struct kind_registry {
  std::mutex mtx;
  std::vector<const link_kind*> kinds{
#define HERM_LINK_KIND(x) &x##_link_kind(),
#include "channels/link_kinds.def"
#undef HERM_LINK_KIND
  };
  std::deque<link_kind> added;

  static kind_registry& get() {
    static kind_registry instance;
    return instance;
  }
};

} // namespace

caf::error add_link_kind(const link_kind& kind) {
  if (kind.name == nullptr || kind.open == nullptr)
    return make_error(ec::invalid_parameter,
                      "a link kind needs a name and an open function");
  auto& reg = kind_registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  for (auto* k : reg.kinds)
    if (std::string{k->name} == kind.name)
      return make_error(ec::already_exists,
                        std::string{"link kind '"} + kind.name
                          + "' is already known");
  reg.added.push_back(kind);
  reg.kinds.push_back(&reg.added.back());
  return caf::none;
}

std::vector<const link_kind*> link_kinds() {
  auto& reg = kind_registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  return reg.kinds;
}

const link_kind* find_link_kind(const std::string& name) {
  auto& reg = kind_registry::get();
  std::lock_guard<std::mutex> guard{reg.mtx};
  for (auto* k : reg.kinds)
    if (name == k->name)
      return k;
  return nullptr;
}

} // namespace herm
