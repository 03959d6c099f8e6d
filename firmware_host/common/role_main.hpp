// The main() every role binary shares: arguments, configuration, start-up, the service loop, shutdown.
#pragma once

#include "airground/platform/role_table.hpp"

namespace ag {

// Exit codes: 0 clean stop, 1 runtime failure, 2 usage or configuration error.
int run_role(const RoleDescription& role, int argc, char** argv);

}  // namespace ag
