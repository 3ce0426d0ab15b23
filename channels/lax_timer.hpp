#pragma once

// Housekeeping timers that need not wake the module on their own
// (docs/architecture.md, "Threads"). A periodic tick (the routing agent's
// quarter-hello tick, application support's housekeeping tick) is due at
// some time but may just as well run a little later. On the loop scheduler
// such a lax timer fires on the first wake of the loop at or after its
// time, whatever woke it (a packet, another timer), and wakes the loop
// itself only at its latest time: its delay plus an eighth of it, at most
// lax_timer_slack. A tick that sets the next one from now when it runs
// stretches its period by up to that much; one that counts from its last
// due time (send_lax_at) does not. So a module busy with traffic runs its
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

/// How late a lax timer set `delay` ahead may fire: an eighth of the delay,
/// at most lax_timer_slack.
constexpr caf::timespan lax_slack(caf::timespan delay) {
  return std::min<caf::timespan>(delay / 8, lax_timer_slack);
}

/// Sends `xs` from `self` to itself at `t`, lax, at `t + slack` at the
/// latest. A periodic tick that sets its next time from the last one's
/// (`t += period`) instead of from now keeps its period on average however
/// late each one fires. No type check: `xs` must be a message `self`
/// handles.
template <class Self, class... Ts>
void send_lax_at(Self* self, caf::actor_clock::time_point t,
                 caf::timespan slack, Ts&&... xs) {
  static_assert(sizeof...(Ts) > 0, "no message to send");
  schedule_lax(self->system(), t, t + slack, self->ctrl(),
               caf::make_mailbox_element(self->ctrl(), caf::make_message_id(),
                                         {}, std::forward<Ts>(xs)...));
}

/// Sends `xs` from `self` to itself after `delay`, as self->delayed_send
/// would, but lax (above): at most lax_slack(delay) late.
template <class Self, class... Ts>
void delayed_send_lax(Self* self, caf::timespan delay, Ts&&... xs) {
  send_lax_at(self, self->system().clock().now() + delay, lax_slack(delay),
              std::forward<Ts>(xs)...);
}

} // namespace herm
