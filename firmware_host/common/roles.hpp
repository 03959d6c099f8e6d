// Every role's description, for the simulator and the tests that run several roles in one process.
#pragma once

#include "airground/platform/role_table.hpp"

namespace ag {
[[nodiscard]] const RoleDescription& uav_role();
[[nodiscard]] const RoleDescription& ugv_role();
[[nodiscard]] const RoleDescription& base_role();
}  // namespace ag
