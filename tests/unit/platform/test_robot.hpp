// Test helper: one robot built from a role table with default parameters, kept alive with its config.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/role_instance.hpp"

namespace ag::test {

struct TestRobot {
  Config config;
  std::unique_ptr<RoleInstance> robot;
};

inline std::unique_ptr<TestRobot> build(const RoleDescription& role, const Clock& clock, std::string name) {
  auto b = std::make_unique<TestRobot>(TestRobot{Config::defaults(role_schema(role)), nullptr});
  auto r = RoleInstance::create(role, b->config, clock, std::move(name));
  EXPECT_TRUE(r.ok()) << r.error().message;
  if (!r.ok()) return nullptr;
  b->robot = std::move(r).value();
  return b;
}

}  // namespace ag::test
