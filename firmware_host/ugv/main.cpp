// airground-ugv: the ugv role binary.
#include "role_main.hpp"
#include "roles.hpp"

int main(int argc, char** argv) { return ag::run_role(ag::ugv_role(), argc, argv); }
