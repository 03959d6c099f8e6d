// airground-ugv: the ugv role binary.
#include "../common/role_main.hpp"
#include "role.hpp"

int main(int argc, char** argv) { return ag::run_role(ag::ugv_role(), argc, argv); }
