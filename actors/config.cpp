// Placeholder: implemented in the config helper's change.
#include "actors/config.hpp"
