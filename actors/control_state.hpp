#pragma once

// Internal to the control service (control.cpp, control_calls.cpp): its
// state and what those files share. Nothing but them includes it; the
// service's interface is actors/control.hpp. Everything here runs in the
// control actor's thread only.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <string>

#include "caf/stateful_actor.hpp"
#include "caf/typed_event_based_actor.hpp"
#include "caf/typed_response_promise.hpp"

#include "actors/control.hpp"
#include "actors/control_json.hpp"

namespace herm::control_detail {

using namespace control_json;
using clock_type = std::chrono::steady_clock;
using ms = std::chrono::milliseconds;

using clock_type = std::chrono::steady_clock;
using ms = std::chrono::milliseconds;

/// How long a forwarded request waits for the control APO's discovery.
constexpr uint32_t discovery_ms = 500;

/// Bounds on what a request may ask for.
constexpr uint32_t max_ping_count = 1000;
constexpr uint32_t max_timeout_ms = 600000;
/// The longest "wait_ms" of an apps --all (answers over slow, busy links
/// may need more than discovery_ms).
constexpr uint32_t max_wait_ms = 60000;

// -- the actor ------------------------------------------------------------------------------

struct control_state {
  static inline const char* name = "herm.control";

  module_handles m;
  std::string module_name;
  clock_type::time_point started;
  /// "yes" once registered as an APO, else why not (other modules cannot
  /// reach a service that is not registered).
  std::string registered = "pending";
  /// Proxies of other modules' control services (and of their read-only
  /// herm.info APOs); an entry is dropped when a request through it fails.
  std::map<module_id, caf::actor> proxies;
  std::map<module_id, caf::actor> info_proxies;
};

using control_impl = control_actor::stateful_pointer<control_state>;
using reply_promise = caf::typed_response_promise<std::string>;

/// Delivers any error as an error reply.
inline auto fail_with(reply_promise rp) {
  return [rp](caf::error& err) mutable { rp.deliver(error_reply(err)); };
}

/// Counts outstanding parallel requests; runs `done` after the last.
struct join_counter {
  size_t pending = 0;
  std::function<void()> done;

  void finish_one() {
    if (--pending == 0)
      done();
  }
};

// -- shared by the service's files (control.cpp) ----------------------------------------

/// Asks the agent for this module's id (it may change under dynamic
/// addressing, so it is never cached), then calls `next`; a failure is the
/// reply.
void with_self_id(control_impl self, ms timeout, reply_promise rp,
                  std::function<void(routing_stats&)> next);

/// Finds the control service of `target` (with `info`: its read-only
/// herm.info): ourselves, a cached proxy, a remote APO already in the
/// application table, or one discovered now; `next` gets it or why not.
void resolve(control_impl self, module_id target, module_id self_id,
             ms timeout, std::function<void(caf::expected<caf::actor>)> next,
             bool info = false);

// -- topics, publications, calls and streams (control_calls.cpp) -------------------------

/// This module's topics, or with "all": true every module's, merged.
void cmd_topics(control_impl self, const json& req, ms timeout,
                reply_promise rp);

/// Publishes the value of `req` (text form or hex payload) from here.
void cmd_publish(control_impl self, const json& req, ms timeout,
                 reply_promise rp);

/// A request to the APO named "apo", wherever it runs.
void cmd_call(control_impl self, const json& req, ms timeout,
              reply_promise rp);

/// A stream of values of topics, written by `writer`.
void open_stream(control_impl self, const std::string& text,
                 caf::actor writer,
                 caf::typed_response_promise<std::string> rp);

} // namespace herm::control_detail
