#pragma once

// What the Application Support Layer's pure cores want sent: ASL messages
// to modules, in the order they were decided. A core appends; its actor
// transmits them all, in order, after the call (libcanard's TX queue in
// spirit: the core does no I/O). Tests read `items` directly.

#include <utility>
#include <vector>

#include "actors/asl_wire.hpp"
#include "routing/module_id.hpp"

namespace herm {

struct asl_outbox {
  struct item {
    /// A module, or broadcast_module.
    module_id dst = no_module;
    asl_message msg;
    /// Signed in a keyed network whatever its `auth.data`.
    bool sign = false;
  };

  std::vector<item> items;

  void push(module_id dst, asl_message msg, bool sign = false) {
    items.push_back(item{dst, std::move(msg), sign});
  }
};

} // namespace herm
