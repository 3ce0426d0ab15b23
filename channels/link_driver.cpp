#include "channels/link_driver.hpp"

#include "channels/error.hpp"
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

const std::vector<const link_kind*>& link_kinds() {
  static const std::vector<const link_kind*> kinds{
#define HERM_LINK_KIND(x) &x##_link_kind(),
#include "channels/link_kinds.def"
#undef HERM_LINK_KIND
  };
  return kinds;
}

const link_kind* find_link_kind(const std::string& name) {
  for (auto* k : link_kinds())
    if (name == k->name)
      return k;
  return nullptr;
}

} // namespace herm
