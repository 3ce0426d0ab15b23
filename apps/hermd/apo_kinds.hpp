#pragma once

// The APO kinds hermd can load from a config file's `apos` section: a
// registry of factories by name, like the link kinds of the Network
// Interface Layer. Each APO is an ordinary actor registered in the module's
// application table under its configured name and type.

#include <functional>
#include <string>
#include <vector>

#include "caf/actor.hpp"
#include "caf/expected.hpp"
#include "caf/fwd.hpp"

#include "actors/config.hpp"
#include "actors/module.hpp"
#include "apps/hermd/srf04.hpp"

namespace herm::hermd {

/// What a factory gets: the actor system and the module the APO lives on.
struct apo_context {
  caf::actor_system* sys = nullptr;
  module_handles module;
  /// The module's configured name, for messages and logs.
  std::string module_name;
};

struct apo_kind {
  std::string name;
  std::string description;
  /// Checks the options (errors name the option and what was expected);
  /// spawns nothing.
  std::function<caf::error(const apo_config&)> check;
  /// Spawns the APO; it does its own start-up (binding, opening a sensor
  /// line) asynchronously.
  std::function<caf::expected<caf::actor>(const apo_context&, const apo_config&)>
    spawn;
};

/// Every APO kind hermd knows: collector, srf04_batcher, vision_source, echo.
const std::vector<apo_kind>& apo_kinds();

/// nullptr if unknown.
const apo_kind* find_apo_kind(const std::string& name);

/// Registers the APOs' message types (testbed_types.hpp).
void add_apo_types(caf::actor_system_config& cfg);

} // namespace herm::hermd
