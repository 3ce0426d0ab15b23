#include "actors/runtime/error.hpp"

#include "caf/atom.hpp"
#include "caf/make_message.hpp"
#include "caf/message.hpp"
#include "caf/sec.hpp"

namespace herm {

namespace {

constexpr caf::atom_value category = caf::atom("herm");

} // namespace

const char* to_string(ec x) {
  switch (x) {
    case ec::none: return "none";
    case ec::unknown_device: return "unknown_device";
    case ec::unknown_link_kind: return "unknown_link_kind";
    case ec::invalid_address: return "invalid_address";
    case ec::invalid_parameter: return "invalid_parameter";
    case ec::device_unavailable: return "device_unavailable";
    case ec::device_failed: return "device_failed";
    case ec::channel_closed: return "channel_closed";
    case ec::unknown_channel: return "unknown_channel";
    case ec::packet_too_large: return "packet_too_large";
    case ec::queue_full: return "queue_full";
    case ec::already_exists: return "already_exists";
    case ec::invalid_config: return "invalid_config";
    case ec::timeout: return "timeout";
    case ec::no_route: return "no_route";
    case ec::unknown_type: return "unknown_type";
    case ec::apo_gone: return "apo_gone";
    case ec::not_found: return "not_found";
    case ec::unauthorized: return "unauthorized";
    case ec::unavailable: return "unavailable";
  }
  return "unknown_error_code";
}

caf::error make_error(ec x) {
  return caf::error{static_cast<uint8_t>(x), category};
}

caf::error make_error(ec x, std::string context) {
  return caf::error{static_cast<uint8_t>(x), category,
                    caf::make_message(std::move(context))};
}

bool is(const caf::error& err, ec x) {
  // category() dereferences a null pointer on an empty error in CAF 0.17.
  return err && err.category() == category
         && err.code() == static_cast<uint8_t>(x);
}

std::string render(const caf::error& err) {
  if (!err)
    return "none";
  std::string result;
  if (err.category() == category) {
    result = "herm.";
    result += to_string(static_cast<ec>(err.code()));
  } else if (err.category() == caf::atom("system")) {
    result = "system.";
    result += caf::to_string(static_cast<caf::sec>(err.code()));
  } else {
    result = caf::to_string(err.category());
    result += '.';
    result += std::to_string(err.code());
  }
  auto& ctx = err.context();
  if (ctx.match_elements<std::string>()) {
    result += ": ";
    result += ctx.get_as<std::string>(0);
  } else if (!ctx.empty()) {
    result += ": ";
    result += caf::to_string(ctx);
  }
  return result;
}

} // namespace herm
