#include "actors/runtime/error.hpp"

namespace herm {

namespace {

const char* name_own(uint8_t code) {
  return to_string(static_cast<app_ec>(code));
}

const bool names_added
  = (add_error_names(routing_ec_end, app_ec_end, name_own), true);

} // namespace

const char* to_string(app_ec x) {
  (void) names_added;
  switch (x) {
    case app_ec::unknown_type: return "unknown_type";
    case app_ec::apo_gone: return "apo_gone";
    case app_ec::not_found: return "not_found";
    case app_ec::unauthorized: return "unauthorized";
    case app_ec::unavailable: return "unavailable";
  }
  return "unknown_error_code";
}

caf::error make_error(app_ec x) {
  return make_herm_error(static_cast<uint8_t>(x));
}

caf::error make_error(app_ec x, std::string context) {
  return make_herm_error(static_cast<uint8_t>(x), std::move(context));
}

bool is(const caf::error& err, app_ec x) {
  return is_herm_error(err, static_cast<uint8_t>(x));
}

} // namespace herm
