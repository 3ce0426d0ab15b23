#include "routing/error.hpp"

namespace herm {

namespace {

const char* name_own(uint8_t code) {
  return to_string(static_cast<routing_ec>(code));
}

const bool names_added
  = (add_error_names(ec_end, routing_ec_end, name_own), true);

} // namespace

const char* to_string(routing_ec x) {
  (void) names_added;
  switch (x) {
    case routing_ec::no_route: return "no_route";
  }
  return "unknown_error_code";
}

caf::error make_error(routing_ec x) {
  return make_herm_error(static_cast<uint8_t>(x));
}

caf::error make_error(routing_ec x, std::string context) {
  return make_herm_error(static_cast<uint8_t>(x), std::move(context));
}

bool is(const caf::error& err, routing_ec x) {
  return is_herm_error(err, static_cast<uint8_t>(x));
}

} // namespace herm
