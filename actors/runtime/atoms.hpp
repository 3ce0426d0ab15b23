#pragma once

#include "routing/atoms.hpp"

/// HERM's atoms: the Application Support Layer's atoms (HERM_ATOM: see
/// channels/atoms.hpp); including this header gives every layer's.
namespace herm::atom {

HERM_ATOM(apps);
HERM_ATOM(bind);
HERM_ATOM(done);
HERM_ATOM(find);
HERM_ATOM(forward);
HERM_ATOM(publish);
HERM_ATOM(reply);
HERM_ATOM(sample);
HERM_ATOM(topics);
HERM_ATOM(unregister);

} // namespace herm::atom
