#pragma once

#include "channels/atoms.hpp"

/// HERM's atoms: the Network Adaptation Layer's atoms (HERM_ATOM: see
/// channels/atoms.hpp).
namespace herm::atom {

HERM_ATOM(flush);
HERM_ATOM(neighbors);
HERM_ATOM(routes);
HERM_ATOM(send);

} // namespace herm::atom
