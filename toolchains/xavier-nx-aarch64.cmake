# NVIDIA Xavier NX (Carmel cores, ARMv8.2-A) cross build with Debian's g++-aarch64-linux-gnu.
# Libraries come from the arm64 -dev packages that tools/install-deps.sh unpacks into a sysroot folder.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

get_filename_component(_ag_top "${CMAKE_CURRENT_LIST_DIR}/.." ABSOLUTE)
if(NOT AG_ARM64_SYSROOT)
  if(DEFINED ENV{AG_ARM64_SYSROOT})
    set(AG_ARM64_SYSROOT "$ENV{AG_ARM64_SYSROOT}")
  else()
    set(AG_ARM64_SYSROOT "${_ag_top}/build/sysroot-aarch64")
  endif()
endif()
set(AG_ARM64_SYSROOT "${AG_ARM64_SYSROOT}" CACHE PATH "arm64 -dev packages unpacked by tools/install-deps.sh")
if(NOT EXISTS "${AG_ARM64_SYSROOT}/usr/lib/aarch64-linux-gnu")
  message(FATAL_ERROR "arm64 sysroot missing at ${AG_ARM64_SYSROOT}: run 'make deps' (tools/install-deps.sh)")
endif()
set(CMAKE_FIND_ROOT_PATH /usr/aarch64-linux-gnu "${AG_ARM64_SYSROOT}")
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
# Absolute PATHS/HINTS given to find_* (e.g. /usr/lib/aarch64-linux-gnu/lapack in cmake/Ceres.cmake) are
# re-rooted under these roots, so they resolve in the sysroot; CMAKE_SYSROOT stays unset on purpose (the
# sysroot folder holds only unpacked -dev packages, the C library comes with the cross gcc).

# Eigen is header-only and architecture-independent (libeigen3-dev is Architecture: all, so it cannot
# be downloaded as :arm64 into the sysroot): use the native package's config, which points at
# /usr/include/eigen3. An explicit <Package>_DIR is not re-rooted.
if(NOT Eigen3_DIR AND EXISTS /usr/share/eigen3/cmake/Eigen3Config.cmake)
  set(Eigen3_DIR /usr/share/eigen3/cmake)
endif()

# Carmel is ARMv8.2-A with crypto and half-precision; GCC 12 has no -mcpu=carmel, and its wide
# out-of-order core schedules best with the Cortex-A76 model of the options GCC has.
set(AG_ARCH_FLAGS "-march=armv8.2-a+crypto+fp16 -mtune=cortex-a76" CACHE STRING "Target CPU flags" FORCE)

# Tests are linked static and run under qemu-user.
find_program(AG_QEMU_AARCH64 NAMES qemu-aarch64-static qemu-aarch64 REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR "${AG_QEMU_AARCH64}")
