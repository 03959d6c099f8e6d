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

function(airground_test_binary target)
  if(AG_STATIC_TESTS AND NOT AG_SANITIZE)
    set_target_properties(${target} PROPERTIES AG_FULLY_STATIC ON)
    target_link_options(${target} PRIVATE -static)
    target_link_options(${target} PRIVATE -Wl,--whole-archive -lpthread -Wl,--no-whole-archive)
  endif()
endfunction()
