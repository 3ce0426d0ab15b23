#pragma once

// The Application Support Layer's errors as its users get them and as they
// cross the wire (asl_response, asl_down). Pure functions, no state; every
// one is O(length of the texts involved).

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>

#include "caf/error.hpp"

#include "actors/app_support.hpp"
#include "actors/asl_wire.hpp"

namespace herm {

/// The context of `err` as text: its string if it carries exactly one,
/// else CAF's rendering of the context (empty if none).
std::string context_of(const caf::error& err);

/// `err` as it travels: category, code and context (cut to
/// max_asl_string bytes). No error gives code 0.
wire_error to_wire(const caf::error& err);

/// The inverse of to_wire (code 0: no error; the context as one string).
caf::error from_wire(const wire_error& w);

/// "APO 'name' (number) on module hex", for error texts.
std::string describe(const apo_ref& ref);

namespace asl_error {

/// app_ec::apo_gone with `what`.
caf::error apo_gone(std::string what);

/// app_ec::apo_gone: module `self` has no APO number `apo`.
caf::error no_such_apo(uint32_t apo, module_id self);

/// routing_ec::no_route: "no route to module m".
caf::error no_route_to(module_id m);

/// ec::invalid_parameter unless 1 <= x.size() <= max_asl_string (`what`
/// names x in the text); none otherwise.
caf::error check_label(const std::string& what, const std::string& x);

/// ec::packet_too_large: a message marshalled to `size` bytes, above
/// `limit`.
caf::error too_large(size_t size, size_t limit);

/// ec::queue_full at the sender: `n` remote requests outstanding.
caf::error outstanding(size_t n);

/// ec::queue_full at the receiver: module `self` serves too many requests.
caf::error serving_full(module_id self);

/// app_ec::unauthorized: APO `name` of module `self` takes requests from
/// other modules only signed.
caf::error unauthorized(const std::string& name, module_id self);

/// app_ec::not_found: nothing matched a binding's query within `ms`.
caf::error not_found(query_by by, const std::string& pattern, uint32_t ms);

/// routing_ec::no_route: module `m` stayed unreachable past the grace
/// period.
caf::error unreachable(module_id m);

/// The error of a request whose deadline (`timeout` after it was made)
/// passed: app_ec::apo_gone when a reliable one had no target
/// (`target` 0), routing_ec::no_route when a reliable one's `target`
/// module stayed unreachable (`target_reachable` false), else ec::timeout
/// naming module `dst` (where it went).
caf::error deadline(bool reliable, module_id target, bool target_reachable,
                    module_id dst, std::chrono::milliseconds timeout);

/// app_ec::unavailable: the routing agent of `self` stopped for `reason`.
caf::error agent_stopped(module_id self, const caf::error& reason);

/// What an APO answered a remote request with, for the requester: CAF's
/// own codes never reach a user (request_receiver_down becomes
/// app_ec::apo_gone, unexpected_message ec::invalid_parameter); any other
/// error is passed on.
caf::error from_apo(caf::error err);

} // namespace asl_error

} // namespace herm
