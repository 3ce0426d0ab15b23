#include "actors/runtime/error.hpp"

#include "caf/sec.hpp"

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

caf::error typed_error(const caf::error& err) {
  if (!err || err.category() != caf::atom("system"))
    return err;
  auto code = static_cast<caf::sec>(err.code());
  switch (code) {
    case caf::sec::request_timeout:
      return make_error(ec::timeout, "no response in time");
    case caf::sec::request_receiver_down:
      return make_error(app_ec::apo_gone, "the receiver exited before it "
                                          "answered");
    case caf::sec::unexpected_message:
      return make_error(ec::invalid_parameter,
                        "the receiver does not handle a message of this type");
    default:
      return make_error(app_ec::unavailable, render(err));
  }
}

} // namespace herm
