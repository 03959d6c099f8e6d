// airground-uav: the uav role binary.
#include "role_main.hpp"
#include "roles.hpp"

int main(int argc, char** argv) { return ag::run_role(ag::uav_role(), argc, argv); }
