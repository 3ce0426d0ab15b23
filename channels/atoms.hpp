#pragma once

#include "caf/atom.hpp"

/// HERM's atoms: the Network Interface Layer's, and the generic ones every
/// layer uses.
/// CAF 0.17 atoms hold at most 10 characters of [A-Za-z0-9_]; any other
/// character silently collides, so keep to that alphabet. Each atom is
/// defined once, in the lowest layer that uses it.
namespace herm::atom {

using add = caf::atom_constant<caf::atom("add")>;
using channels = caf::atom_constant<caf::atom("channels")>;
using close = caf::atom_constant<caf::atom("close")>;
using devices = caf::atom_constant<caf::atom("devices")>;
using get = caf::atom_constant<caf::atom("get")>;
using info = caf::atom_constant<caf::atom("info")>;
using open = caf::atom_constant<caf::atom("open")>;
using retry = caf::atom_constant<caf::atom("retry")>;
using set = caf::atom_constant<caf::atom("set")>;
using stats = caf::atom_constant<caf::atom("stats")>;
using subscribe = caf::atom_constant<caf::atom("subscribe")>;
using tick = caf::atom_constant<caf::atom("tick")>;
using unsubscribe = caf::atom_constant<caf::atom("unsubscrib")>;

constexpr add add_v{};
constexpr channels channels_v{};
constexpr close close_v{};
constexpr devices devices_v{};
constexpr get get_v{};
constexpr info info_v{};
constexpr open open_v{};
constexpr retry retry_v{};
constexpr set set_v{};
constexpr stats stats_v{};
constexpr subscribe subscribe_v{};
constexpr tick tick_v{};
constexpr unsubscribe unsubscribe_v{};

} // namespace herm::atom
