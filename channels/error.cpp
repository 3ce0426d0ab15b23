#include "channels/error.hpp"

#include <array>

#include "caf/atom.hpp"
#include "caf/make_message.hpp"
#include "caf/message.hpp"
#include "caf/sec.hpp"

namespace herm {

namespace {

constexpr caf::atom_value category = caf::atom("herm");

// One namer per code. Zero-initialised before any dynamic initialisation,
// so higher layers may add their ranges from their static initialisers;
// written only then, read afterwards.
std::array<error_namer, 256>& namers() {
  static std::array<error_namer, 256> table{};
  return table;
}

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
  }
  return "unknown_error_code";
}

caf::error make_herm_error(uint8_t code) {
  return caf::error{code, category};
}

caf::error make_herm_error(uint8_t code, std::string context) {
  return caf::error{code, category, caf::make_message(std::move(context))};
}

bool is_herm_error(const caf::error& err, uint8_t code) {
  // category() dereferences a null pointer on an empty error in CAF 0.17.
  return err && err.category() == category && err.code() == code;
}

void add_error_names(uint8_t first, uint8_t end, error_namer namer) {
  for (unsigned code = first; code < end; ++code)
    namers()[code] = namer;
}

const char* error_name(uint8_t code) {
  static thread_local std::string unnamed;
  (void) detail::error_names<ec>::added;
  if (auto namer = namers()[code])
    return namer(code);
  unnamed = "code_" + std::to_string(code);
  return unnamed.c_str();
}

std::string render(const caf::error& err) {
  if (!err)
    return "none";
  std::string result;
  if (err.category() == category) {
    result = "herm.";
    result += error_name(err.code());
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
