#include "routing/error.hpp"

namespace herm {

// Linking this file (whoever names these codes) adds the names at start-up.
template struct detail::error_names<routing_ec>;

const char* to_string(routing_ec x) {
  switch (x) {
    case routing_ec::no_route: return "no_route";
  }
  return "unknown_error_code";
}

} // namespace herm
