// airground-base: the base role binary.
#include "role_main.hpp"
#include "roles.hpp"

int main(int argc, char** argv) { return ag::run_role(ag::base_role(), argc, argv); }
