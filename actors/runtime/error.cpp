#include "actors/runtime/error.hpp"

namespace herm {

// Linking this file (whoever names these codes) adds the names at start-up.
template struct detail::error_names<app_ec>;

const char* to_string(app_ec x) {
  switch (x) {
    case app_ec::unknown_type: return "unknown_type";
    case app_ec::apo_gone: return "apo_gone";
    case app_ec::not_found: return "not_found";
    case app_ec::unauthorized: return "unauthorized";
    case app_ec::unavailable: return "unavailable";
  }
  return "unknown_error_code";
}

} // namespace herm
