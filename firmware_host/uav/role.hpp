// The uav role: its stage table and description (shared by the binary, the simulator and the timing tests).
#pragma once

#include "airground/platform/role_table.hpp"

namespace ag {
[[nodiscard]] const RoleDescription& uav_role();
}  // namespace ag
