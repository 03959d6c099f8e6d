// airground-base: the base role binary.
#include "../common/role_main.hpp"
#include "role.hpp"

int main(int argc, char** argv) { return ag::run_role(ag::base_role(), argc, argv); }
