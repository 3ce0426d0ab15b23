#pragma once

// Housekeeping timers that need not wake the module on their own
// (docs/architecture.md, "Threads"). A periodic tick (the routing agent's
// quarter-hello tick, application support's housekeeping tick) is due at
// some time but may just as well run a little later. On the loop scheduler
// such a lax timer fires on the first wake of the loop at or after its
// time, whatever woke it (a packet, another timer), and wakes the loop
// itself only at its latest time: its delay plus an eighth of it, at most
// lax_timer_slack (a tick that sets the next one when it runs stretches
// its period by at most that much). So a module busy with traffic runs its
// ticks on the wakes the traffic makes, and ticks set in the same turn go
// on firing together. Elsewhere (CAF's schedulers, the test coordinator)
// it is an ordinary delayed message, due exactly.
//
// Never early; at most the slack late, plus what an ordinary timer may be
// late on a busy loop. Cost: as a delayed message (one mailbox element);
// the loop clock scans its lax timers (a few per module: one per ticking
// actor) before each wait.

#include <algorithm>
#include <chrono>
#include <utility>

#include "caf/actor_clock.hpp"
#include "caf/actor_system.hpp"
#include "caf/mailbox_element.hpp"
#include "caf/message_id.hpp"

namespace herm {

/// How late a lax timer may fire on the loop scheduler at the most.
constexpr auto lax_timer_slack = std::chrono::milliseconds(20);

/// Delivers `content` to `receiver` at `t`, on the loop scheduler on a
/// wake at or after `t` and at `latest` at the latest; exactly at `t`
/// elsewhere.
void schedule_lax(caf::actor_system& sys, caf::actor_clock::time_point t,
                  caf::actor_clock::time_point latest,
                  caf::strong_actor_ptr receiver,
                  caf::mailbox_element_ptr content);

/// Sends `xs` from `self` to itself after `delay`, as self->delayed_send
/// would, but lax (above). No type check: `xs` must be a message `self`
/// handles.
template <class Self, class... Ts>
void delayed_send_lax(Self* self, caf::timespan delay, Ts&&... xs) {
  static_assert(sizeof...(Ts) > 0, "no message to send");
  auto& sys = self->system();
  auto t = sys.clock().now() + delay;
  auto slack = std::min<caf::timespan>(delay / 8, lax_timer_slack);
  schedule_lax(sys, t, t + slack, self->ctrl(),
               caf::make_mailbox_element(self->ctrl(), caf::make_message_id(),
                                         {}, std::forward<Ts>(xs)...));
}

} // namespace herm
