#pragma once

#include "caf/atom.hpp"

/// Defines atom `herm::atom::NAME` (the type) and `NAME_v` (its value), the
/// atom's text being TEXT. Use inside namespace herm::atom only; one line per
/// atom keeps the type and its value from drifting apart.
#define HERM_ATOM_TEXT(NAME, TEXT)                                             \
  using NAME = caf::atom_constant<caf::atom(TEXT)>;                            \
  constexpr NAME NAME##_v {}

/// Defines atom `herm::atom::NAME` and `NAME_v` whose text is the name itself
/// (which must then fit the limit below).
#define HERM_ATOM(NAME) HERM_ATOM_TEXT(NAME, #NAME)

/// HERM's atoms: the Network Interface Layer's, and the generic ones every
/// layer uses.
/// CAF 0.17 atoms hold at most 10 characters of [A-Za-z0-9_]; any other
/// character silently collides, so keep to that alphabet. Each atom is
/// defined once, in the lowest layer that uses it.
namespace herm::atom {

HERM_ATOM(add);
HERM_ATOM(channels);
HERM_ATOM(close);
HERM_ATOM(devices);
HERM_ATOM(get);
HERM_ATOM(info);
HERM_ATOM(open);
HERM_ATOM(retry);
HERM_ATOM(set);
HERM_ATOM(stats);
HERM_ATOM(subscribe);
HERM_ATOM(tick);
HERM_ATOM_TEXT(unsubscribe, "unsubscrib");

} // namespace herm::atom
