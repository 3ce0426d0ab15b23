#pragma once

#include "routing/atoms.hpp"

/// HERM's atoms: the Application Support Layer's atoms; including this header gives every layer's.
namespace herm::atom {

using apps = caf::atom_constant<caf::atom("apps")>;
using bind = caf::atom_constant<caf::atom("bind")>;
using done = caf::atom_constant<caf::atom("done")>;
using find = caf::atom_constant<caf::atom("find")>;
using forward = caf::atom_constant<caf::atom("forward")>;
using publish = caf::atom_constant<caf::atom("publish")>;
using reply = caf::atom_constant<caf::atom("reply")>;
using unregister = caf::atom_constant<caf::atom("unregister")>;

constexpr apps apps_v{};
constexpr bind bind_v{};
constexpr done done_v{};
constexpr find find_v{};
constexpr forward forward_v{};
constexpr publish publish_v{};
constexpr reply reply_v{};
constexpr unregister unregister_v{};

} // namespace herm::atom
