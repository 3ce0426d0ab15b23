#pragma once

// Test controls of the in-process link kind ("inproc"): segments are named
// in-memory media shared by every driver of one process. Used by unit and
// actor tests to build topologies and to unplug and replug links.

#include <string>

#include "caf/error.hpp"

namespace herm::inproc {

/// Makes every station on `segment` fail with `reason` (as if the cable was
/// pulled) and refuses new stations until `replug(segment)`.
void unplug(const std::string& segment, caf::error reason);

/// Allows stations on `segment` again after `unplug`.
void replug(const std::string& segment);

/// Makes `segment` drop every frame silently (`on`) or carry them again:
/// a failure that no driver notices, only missed hellos reveal.
void blackhole(const std::string& segment, bool on);

/// Number of stations attached to `segment` now.
size_t stations(const std::string& segment);

} // namespace herm::inproc
