#pragma once

#include "channels/atoms.hpp"

/// HERM's atoms: the Network Adaptation Layer's atoms.
namespace herm::atom {

using flush = caf::atom_constant<caf::atom("flush")>;
using neighbors = caf::atom_constant<caf::atom("neighbors")>;
using routes = caf::atom_constant<caf::atom("routes")>;
using send = caf::atom_constant<caf::atom("send")>;

constexpr flush flush_v{};
constexpr neighbors neighbors_v{};
constexpr routes routes_v{};
constexpr send send_v{};

} // namespace herm::atom
