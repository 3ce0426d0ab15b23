#pragma once

// herm.info: every module's read-only, open companion of its control
// service (actors/control.hpp, info_apo_name). It answers the JSON requests
// "types" (descriptions of message types, with the described types their
// fields name) and "topics" (this module's topics) to any module, without a
// key or control.allow_unsigned_remote; any other "cmd" is unknown_command.
// Protocol: docs/protocol.md ("Control requests").

#include "caf/actor.hpp"
#include "caf/fwd.hpp"

#include "actors/app_support.hpp"

namespace herm {

/// Spawns herm.info linked to `parent` (the control service: it ends with
/// it), answering "topics" from `apps`. The caller registers it in the
/// application table (apo_access::open). Takes std::string, replies
/// std::string; never fails at the CAF level.
caf::actor spawn_info_apo(caf::local_actor* parent, app_support_actor apps);

} // namespace herm
