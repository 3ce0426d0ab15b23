#pragma once

// The GoogleTest fixture for deterministic actor tests: HERM's public
// testing kit (actors/testing/deterministic_system.hpp) as a ::testing::Test.

#include <gtest/gtest.h>

#include "actors/testing/deterministic_system.hpp"

namespace herm::test {

using namespace herm::testkit;

class actor_fixture : public ::testing::Test,
                      public herm::testkit::deterministic_system {};

} // namespace herm::test
