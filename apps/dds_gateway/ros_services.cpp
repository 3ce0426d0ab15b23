#include "apps/dds_gateway/ros_services.hpp"

#include "caf/event_based_actor.hpp"

#include "actors/runtime/error.hpp"

#include "example_interfaces/AddTwoInts.h"

namespace herm::dds_gateway {

namespace {

caf::error bad(std::string what) {
  return make_error(ec::invalid_parameter, std::move(what));
}

cdds_request_header_ to_wire(const request_header& h) {
  return {h.guid, h.seq};
}

request_header from_wire(const cdds_request_header_& h) {
  return {h.guid, h.seq};
}

/// Requests `req` and hands the response, a `Response`, to `done`.
template <class Response>
void call_for(caf::event_based_actor* self, const caf::actor& target,
              std::chrono::milliseconds timeout, caf::message req,
              std::function<void(caf::expected<caf::message>)> done) {
  self->request(target, timeout, std::move(req))
    .then([done](Response& r) { done(caf::make_message(std::move(r))); },
          [done](caf::error& err) { done(std::move(err)); });
}

// -- example_interfaces/srv/AddTwoInts ---------------------------------------------

using add_request = example_interfaces_srv_dds__AddTwoInts_Request_;
using add_reply = example_interfaces_srv_dds__AddTwoInts_Response_;

caf::expected<caf::message> add_request_from(const void* sample,
                                             request_header& h) {
  auto* s = static_cast<const add_request*>(sample);
  h = from_wire(s->header);
  return caf::make_message(s->a, s->b);
}

caf::error add_request_to(const caf::message& req, const request_header& h,
                          void* sample) {
  if (!req.match_elements<int64_t, int64_t>())
    return bad("expected a request (int64_t a, int64_t b), got "
               + caf::to_string(req));
  auto* s = static_cast<add_request*>(sample);
  s->header = to_wire(h);
  s->a = req.get_as<int64_t>(0);
  s->b = req.get_as<int64_t>(1);
  return caf::none;
}

caf::error add_reply_to(const caf::message& resp, const request_header& h,
                        void* sample) {
  if (!resp.match_elements<int64_t>())
    return bad("expected a response int64_t, got " + caf::to_string(resp));
  auto* s = static_cast<add_reply*>(sample);
  s->header = to_wire(h);
  s->sum = resp.get_as<int64_t>(0);
  return caf::none;
}

caf::expected<caf::message> add_reply_from(const void* sample,
                                           request_header& h) {
  auto* s = static_cast<const add_reply*>(sample);
  h = from_wire(s->header);
  return caf::make_message(s->sum);
}

} // namespace

const std::vector<ros_service>& ros_services() {
  static const std::vector<ros_service> services{
    {"example_interfaces/srv/AddTwoInts", "(int64_t a, int64_t b)", "int64_t",
     &example_interfaces_srv_dds__AddTwoInts_Request__desc,
     &example_interfaces_srv_dds__AddTwoInts_Response__desc,
     sizeof(add_request), sizeof(add_reply), add_request_from, add_request_to,
     add_reply_to, add_reply_from, call_for<int64_t>},
  };
  return services;
}

const ros_service* find_ros_service(const std::string& name) {
  for (auto& s : ros_services())
    if (name == s.name)
      return &s;
  return nullptr;
}

} // namespace herm::dds_gateway
