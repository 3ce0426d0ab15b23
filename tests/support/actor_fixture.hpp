#pragma once

// The GoogleTest fixture for deterministic actor tests: HERM's public
// testing kit (actors/testing/deterministic_system.hpp) as a ::testing::Test.

#include <algorithm>
#include <string>

#include <gtest/gtest.h>

#include "actors/testing/deterministic_system.hpp"

namespace herm::test {

using namespace herm::testkit;

class actor_fixture : public ::testing::Test,
                      public herm::testkit::deterministic_system {};

/// The running test's suite and name as one word ("suite-name", '/' of
/// parameterised names made '-'): a prefix for paths and medium names that
/// no other test uses.
inline std::string test_prefix() {
  auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string{info->test_suite_name()} + "-" + info->name();
  std::replace(name.begin(), name.end(), '/', '-');
  return name;
}

} // namespace herm::test
