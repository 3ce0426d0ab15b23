#pragma once

// Internal to the Application Support Layer: the two hand-made actors that
// let CAF messages cross modules transparently.
//
// A *proxy* stands for a remote APO. It is a CAF actor without a mailbox or
// thread: enqueueing a message (send, request, delegate) hands the sender,
// the message id and the message to the application support actor, which
// marshals and routes it. Its monitors and links work like any actor's;
// `kill_apo_proxy` ends it with a reason when the remote APO or its module is
// gone. When the last handle to a proxy is dropped, the application support
// actor hears about it and forgets the binding.
//
// The *reply sink* is the sender that remote requests appear to come from on
// the serving module: the APO's response (a value or an error) reaches the
// sink under the request's id and goes back to the application support
// actor, which routes it to the requesting module.

#include <cstdint>

#include "caf/actor.hpp"
#include "caf/actor_control_block.hpp"
#include "caf/error.hpp"
#include "caf/fwd.hpp"

namespace herm::detail {

/// A new proxy for binding `binding` of application support actor `asl`
/// (held weakly: a proxy does not keep the layer alive).
caf::actor make_apo_proxy(caf::actor_system& sys, const caf::actor& asl,
                          uint32_t binding);

/// Ends `proxy` (if it is one and still alive) with `reason`: monitors get a
/// down message, linked actors an exit message, later messages bounce with
/// `reason`. Returns false if it had ended already.
bool kill_apo_proxy(const caf::strong_actor_ptr& proxy, caf::error reason,
                    caf::execution_unit* ctx);

/// A new reply sink for application support actor `asl` (held weakly).
caf::strong_actor_ptr make_reply_sink(caf::actor_system& sys,
                                      const caf::actor& asl);

} // namespace herm::detail
