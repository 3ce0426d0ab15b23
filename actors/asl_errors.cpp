#include "actors/asl_errors.hpp"

#include "caf/make_message.hpp"
#include "caf/sec.hpp"

#include "actors/runtime/error.hpp"

namespace herm {

std::string context_of(const caf::error& err) {
  auto& ctx = err.context();
  if (ctx.match_elements<std::string>())
    return ctx.get_as<std::string>(0);
  return ctx.empty() ? std::string{} : caf::to_string(ctx);
}

wire_error to_wire(const caf::error& err) {
  wire_error result;
  if (!err)
    return result;
  result.category = static_cast<uint64_t>(err.category());
  result.code = err.code();
  result.context = context_of(err);
  if (result.context.size() > max_asl_string)
    result.context.resize(max_asl_string);
  return result;
}

caf::error from_wire(const wire_error& w) {
  if (w.code == 0)
    return caf::error{};
  return caf::error{w.code, static_cast<caf::atom_value>(w.category),
                    w.context.empty() ? caf::message{}
                                      : caf::make_message(w.context)};
}

std::string describe(const apo_ref& ref) {
  return "APO '" + ref.name + "' (" + std::to_string(ref.apo) + ") on module "
         + to_hex(ref.module);
}

namespace asl_error {

caf::error apo_gone(std::string what) {
  return make_error(app_ec::apo_gone, std::move(what));
}

caf::error no_such_apo(uint32_t apo, module_id self) {
  return apo_gone("no APO " + std::to_string(apo) + " on module "
                  + to_hex(self));
}

caf::error no_route_to(module_id m) {
  return make_error(routing_ec::no_route, "no route to module " + to_hex(m));
}

caf::error check_label(const std::string& what, const std::string& x) {
  if (x.empty() || x.size() > max_asl_string)
    return make_error(ec::invalid_parameter,
                      what + " must be 1 to 255 bytes, got "
                        + std::to_string(x.size()));
  return caf::none;
}

caf::error too_large(size_t size, size_t limit) {
  return make_error(ec::packet_too_large,
                    "message of " + std::to_string(size)
                      + " bytes marshalled; the limit is "
                      + std::to_string(limit));
}

caf::error outstanding(size_t n) {
  return make_error(ec::queue_full,
                    std::to_string(n) + " remote requests outstanding");
}

caf::error serving_full(module_id self) {
  return make_error(ec::queue_full, "module " + to_hex(self)
                                      + " is serving too many requests");
}

caf::error unauthorized(const std::string& name, module_id self) {
  return make_error(app_ec::unauthorized,
                    "APO '" + name + "' of module " + to_hex(self)
                      + " takes requests from other modules only signed "
                        "with the network's key (on a module without "
                        "a key: only with control.allow_unsigned_remote)");
}

caf::error not_found(query_by by, const std::string& pattern, uint32_t ms) {
  return make_error(app_ec::not_found,
                    "no APO "
                      + std::string{by == query_by::type ? "of type '"
                                                         : "named '"}
                      + pattern + "' answered within " + std::to_string(ms)
                      + " ms");
}

caf::error unreachable(module_id m) {
  return make_error(routing_ec::no_route,
                    "module " + to_hex(m) + " unreachable");
}

caf::error deadline(bool reliable, module_id target, bool target_reachable,
                    module_id dst, std::chrono::milliseconds timeout) {
  auto within = " within " + std::to_string(timeout.count()) + " ms";
  if (reliable && target == no_module)
    return apo_gone("no APO to send it to" + within);
  if (reliable && !target_reachable)
    return make_error(routing_ec::no_route, "module " + to_hex(target)
                                              + " stayed unreachable"
                                              + within);
  return make_error(ec::timeout,
                    "no response from module " + to_hex(dst) + within);
}

caf::error agent_stopped(module_id self, const caf::error& reason) {
  return make_error(app_ec::unavailable, "the routing agent of module "
                                           + to_hex(self) + " stopped ("
                                           + render(reason) + ")");
}

caf::error from_apo(caf::error err) {
  if (err == caf::sec::request_receiver_down)
    return apo_gone("the APO exited before it answered");
  if (err == caf::sec::unexpected_message)
    return make_error(ec::invalid_parameter,
                      "the APO does not handle a message of this type");
  return err;
}

} // namespace asl_error

} // namespace herm
