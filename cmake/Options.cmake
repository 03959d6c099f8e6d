# Target tuning and sanitizers, applied through one interface target that every airground target links.
add_library(airground_options INTERFACE)
if(AG_ARCH_FLAGS)
  separate_arguments(_ag_arch UNIX_COMMAND "${AG_ARCH_FLAGS}")
  target_compile_options(airground_options INTERFACE ${_ag_arch})
endif()
if(AG_SANITIZE)
  target_compile_options(airground_options INTERFACE -fsanitize=${AG_SANITIZE} -fno-omit-frame-pointer)
  target_link_options(airground_options INTERFACE -fsanitize=${AG_SANITIZE})
endif()
target_link_libraries(airground_options INTERFACE airground_warnings)
# Native builds link with LLD when it is installed (tools/deps/debian-packages.txt): GNU ld spent about a
# sixth of a fresh build's CPU time linking, and LLD links airground-sim 4.5x faster (9.9 -> 2.1 s,
# the same machine, in turn). The cross build keeps its toolchain's linker.
option(AG_USE_LLD "link native builds with LLD when it is installed" ON)
if(AG_USE_LLD AND NOT CMAKE_CROSSCOMPILING)
  find_program(AG_LLD ld.lld)
  if(AG_LLD)
    target_link_options(airground_options INTERFACE -fuse-ld=lld)
  endif()
endif()

# A role binary: one static executable per robot role, with a build id (the -dbgsym package files its
# symbols under /usr/lib/debug/.build-id/, where gdb looks them up).
function(airground_role_binary target)
  target_link_options(${target} PRIVATE -Wl,--build-id=sha1)
  if(AG_STATIC_ROLES AND NOT AG_SANITIZE)
    set_target_properties(${target} PROPERTIES AG_FULLY_STATIC ON)
    target_link_options(${target} PRIVATE -static)
    # glibc's static libpthread needs the whole archive so weak pthread symbols resolve.
    target_link_options(${target} PRIVATE -Wl,--whole-archive -lpthread -Wl,--no-whole-archive)
  endif()
endfunction()

# A test executable. Its own sources get line tables only (-g1) in RelWithDebInfo: gdb and sanitizer
# backtraces keep function, file and line, and those files compile about a third faster with objects an
# eighth the size (measured on test_pose_graph_sim.cpp: 20.3 s -> 14.0 s, 21 -> 2.7 MB), which is most of
# what `make test` builds. The code the robots run keeps full -g for its -dbgsym packages.
function(airground_test_binary target)
  target_compile_options(${target} PRIVATE $<$<CONFIG:RelWithDebInfo>:-g1>)
  if(AG_STATIC_TESTS AND NOT AG_SANITIZE)
    set_target_properties(${target} PROPERTIES AG_FULLY_STATIC ON)
    target_link_options(${target} PRIVATE -static)
    target_link_options(${target} PRIVATE -Wl,--whole-archive -lpthread -Wl,--no-whole-archive)
  endif()
endfunction()
