# The one warning set for every target and toolchain; warnings are errors.
add_library(airground_warnings INTERFACE)
target_compile_options(airground_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Werror
  -Wshadow -Wconversion -Wsign-conversion -Wold-style-cast -Wcast-align
  -Wnon-virtual-dtor -Woverloaded-virtual -Wnull-dereference -Wdouble-promotion
  -Wformat=2 -Wimplicit-fallthrough -Wmisleading-indentation -Wduplicated-cond
  -Wduplicated-branches -Wlogical-op
  # std::hardware_destructive_interference_size is ABI-unstable; we pin the line size ourselves.
  -Wno-interference-size
  # GCC 12 false positive inside std::string at -O3 (GCC bug 105329).
  -Wno-restrict)
