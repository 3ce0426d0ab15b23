// Placeholder: implemented in the control helper's change.
#include "actors/control.hpp"
