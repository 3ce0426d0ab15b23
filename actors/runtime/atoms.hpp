#pragma once

#include "caf/atom.hpp"

/// HERM's atoms. CAF 0.17 atoms hold at most 10 characters of [A-Za-z0-9_];
/// any other character silently collides, so keep to that alphabet.
namespace herm::atom {

using add = caf::atom_constant<caf::atom("add")>;
using apps = caf::atom_constant<caf::atom("apps")>;
using bind = caf::atom_constant<caf::atom("bind")>;
using channels = caf::atom_constant<caf::atom("channels")>;
using close = caf::atom_constant<caf::atom("close")>;
using devices = caf::atom_constant<caf::atom("devices")>;
using done = caf::atom_constant<caf::atom("done")>;
using find = caf::atom_constant<caf::atom("find")>;
using flush = caf::atom_constant<caf::atom("flush")>;
using forward = caf::atom_constant<caf::atom("forward")>;
using get = caf::atom_constant<caf::atom("get")>;
using info = caf::atom_constant<caf::atom("info")>;
using neighbors = caf::atom_constant<caf::atom("neighbors")>;
using open = caf::atom_constant<caf::atom("open")>;
using publish = caf::atom_constant<caf::atom("publish")>;
using reply = caf::atom_constant<caf::atom("reply")>;
using retry = caf::atom_constant<caf::atom("retry")>;
using routes = caf::atom_constant<caf::atom("routes")>;
using send = caf::atom_constant<caf::atom("send")>;
using set = caf::atom_constant<caf::atom("set")>;
using stats = caf::atom_constant<caf::atom("stats")>;
using subscribe = caf::atom_constant<caf::atom("subscribe")>;
using tick = caf::atom_constant<caf::atom("tick")>;
using unregister = caf::atom_constant<caf::atom("unregister")>;
using unsubscribe = caf::atom_constant<caf::atom("unsubscrib")>;

constexpr add add_v{};
constexpr apps apps_v{};
constexpr bind bind_v{};
constexpr channels channels_v{};
constexpr close close_v{};
constexpr devices devices_v{};
constexpr done done_v{};
constexpr find find_v{};
constexpr flush flush_v{};
constexpr forward forward_v{};
constexpr get get_v{};
constexpr info info_v{};
constexpr neighbors neighbors_v{};
constexpr open open_v{};
constexpr publish publish_v{};
constexpr reply reply_v{};
constexpr retry retry_v{};
constexpr routes routes_v{};
constexpr send send_v{};
constexpr set set_v{};
constexpr stats stats_v{};
constexpr subscribe subscribe_v{};
constexpr tick tick_v{};
constexpr unregister unregister_v{};
constexpr unsubscribe unsubscribe_v{};

} // namespace herm::atom
