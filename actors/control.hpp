#pragma once

// The control service of a module: what hermctl talks to. Requests and
// replies are JSON text (docs/protocol.md, "Control requests"); a request
// that names another module ("module": "0x4E") is forwarded to that
// module's control service through the Application Support Layer, so one
// local endpoint reaches every module the routing can reach.

#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "caf/expected.hpp"
#include "caf/fwd.hpp"
#include "caf/replies_to.hpp"
#include "caf/typed_actor.hpp"

#include "actors/module.hpp"

namespace herm {

/// Name and type under which every module's control service is registered
/// as an APO.
constexpr const char* control_apo_name = "herm.control";
constexpr const char* control_apo_type = "herm.control/1";

/// Name and type of every module's read-only companion of its control
/// service: it answers "types" (descriptions of message types) and
/// "topics" (this module's topics) to any module, without a key or
/// control.allow_unsigned_remote, so that tools on other modules can print
/// values by field name and list topics network-wide.
constexpr const char* info_apo_name = "herm.info";
constexpr const char* info_apo_type = "herm.info/1";

/// How long the service waits for what a request needs (another module's
/// reply, each echo of a ping) unless the request says "timeout_ms".
constexpr std::chrono::milliseconds default_control_timeout{5000};

/// The longest a control service may take to answer `request` (derived from
/// its "timeout_ms", default_control_timeout, and a ping's "count"): what a
/// caller should wait before giving up.
std::chrono::milliseconds control_deadline(const std::string& request);

/// One request (a JSON object with at least "cmd") in, one reply out:
/// {"ok": true, "result": ...} or {"ok": false, "error": {"code": "no_route",
/// "message": "..."}}. Never fails at the CAF level.
///
/// A stream ({"cmd": "subscribe", "topics": [...]}, the control socket's
/// topic echo and record) comes with the actor that writes its lines: the
/// service sends it one std::string per value until it ends, and replies
/// the stream's first line.
using control_actor
  = caf::typed_actor<caf::replies_to<std::string>::with<std::string>,
                     caf::replies_to<atom::subscribe, std::string,
                                     caf::actor>::with<std::string>>;

/// Spawns the control service of module `m` (named `module_name` in
/// replies) and registers it in the module's application table.
control_actor spawn_control(caf::actor_system& sys, const module_handles& m,
                            std::string module_name);

/// Commands a server answers on its own thread instead of the service
/// (hermd's "reload"): the request text in, the reply text out. They may
/// block.
using local_commands
  = std::map<std::string, std::function<std::string(const std::string&)>>;

/// A Unix-domain stream socket at `path` (mode 0600, parent directory
/// created 0700 if missing, a stale socket file replaced; a live one is an
/// error): one JSON request per line, one JSON reply per line, any number
/// of clients one after another. Stops, joins its thread and removes the
/// socket file when destroyed (a request in progress is abandoned; its
/// client gets an "unavailable" error reply).
class control_server {
public:
  static caf::expected<std::unique_ptr<control_server>>
  start(caf::actor_system& sys, control_actor service, std::string path,
        local_commands locals = {});
  virtual ~control_server();
  const std::string& path() const;

protected:
  control_server() = default;
};

/// Client side (hermctl, tests): connects to `path`, sends one request line
/// and reads one reply line. Errors name the path: "no module listening at
/// PATH (is hermd running?)", timeouts.
caf::expected<std::string> control_call(const std::string& path,
                                        const std::string& request,
                                        std::chrono::milliseconds timeout);

} // namespace herm
