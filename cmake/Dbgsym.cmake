# Debian's -dbgsym convention for the role binaries: the role's package gets the binary stripped, with a
# .gnu_debuglink to its symbols; the <component>_dbgsym package gets the symbols at
# /usr/lib/debug/.build-id/xx/yyyy.debug (gdb finds them by the binary's build id), as dh_strip does.
# Both happen at install time (cmake --install, cpack), from the unstripped binary of the build tree.

# airground_install_split(<target> <component>): the stripped <target> in <component>, its symbols in
# <component>_dbgsym and a usr/share/doc/<doc_name>-dbgsym -> <doc_name> link (Debian's dbgsym packages
# carry their package's copyright that way).
function(airground_install_split target component doc_name)
  if(NOT CMAKE_OBJCOPY OR NOT CMAKE_READELF)
    message(FATAL_ERROR "airground_install_split(${target}): objcopy/readelf not found (binutils)")
  endif()
  # The symbols: extracted once per install into the build tree, named by build id.
  set(_split "
    if(NOT EXISTS \"$<TARGET_FILE:${target}>\")
      message(FATAL_ERROR \"$<TARGET_FILE:${target}> is not built: build it before installing or packaging\")
    endif()
    execute_process(COMMAND \"${CMAKE_READELF}\" -n \"$<TARGET_FILE:${target}>\" OUTPUT_VARIABLE _notes RESULT_VARIABLE _rc)
    if(NOT _rc EQUAL 0 OR NOT _notes MATCHES \"Build ID: ([0-9a-f][0-9a-f])([0-9a-f]+)\")
      message(FATAL_ERROR \"$<TARGET_FILE:${target}>: no build id (the role binaries link with -Wl,--build-id)\")
    endif()
    set(_id_dir \"\${CMAKE_MATCH_1}\")
    set(_id_file \"\${CMAKE_MATCH_2}.debug\")
    set(_debug \"${CMAKE_BINARY_DIR}/dbgsym/${target}/\${_id_file}\")
    file(MAKE_DIRECTORY \"${CMAKE_BINARY_DIR}/dbgsym/${target}\")
    if(NOT EXISTS \"\${_debug}\" OR \"$<TARGET_FILE:${target}>\" IS_NEWER_THAN \"\${_debug}\")
      execute_process(COMMAND \"${CMAKE_OBJCOPY}\" --only-keep-debug --compress-debug-sections \"$<TARGET_FILE:${target}>\" \"\${_debug}\"
                      RESULT_VARIABLE _rc ERROR_VARIABLE _err)
      if(NOT _rc EQUAL 0)
        message(FATAL_ERROR \"objcopy --only-keep-debug $<TARGET_FILE:${target}>: \${_err}\")
      endif()
    endif()
  ")
  install(CODE "${_split}
    set(_dest \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_BINDIR}\")
    file(MAKE_DIRECTORY \"\${_dest}\")
    message(STATUS \"Installing (stripped): \${_dest}/$<TARGET_FILE_NAME:${target}>\")
    execute_process(COMMAND \"${CMAKE_OBJCOPY}\" --strip-unneeded --remove-section=.comment --remove-section=.note
                            \"--add-gnu-debuglink=\${_debug}\" \"$<TARGET_FILE:${target}>\" \"\${_dest}/$<TARGET_FILE_NAME:${target}>\"
                    RESULT_VARIABLE _rc ERROR_VARIABLE _err)
    if(NOT _rc EQUAL 0)
      message(FATAL_ERROR \"objcopy --strip-unneeded $<TARGET_FILE:${target}>: \${_err}\")
    endif()
    file(CHMOD \"\${_dest}/$<TARGET_FILE_NAME:${target}>\" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
  " COMPONENT ${component})
  install(CODE "${_split}
    set(_dest \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/lib/debug/.build-id/\${_id_dir}\")
    file(MAKE_DIRECTORY \"\${_dest}\")
    message(STATUS \"Installing: \${_dest}/\${_id_file}\")
    file(COPY_FILE \"\${_debug}\" \"\${_dest}/\${_id_file}\")
    file(CHMOD \"\${_dest}/\${_id_file}\" PERMISSIONS OWNER_READ OWNER_WRITE GROUP_READ WORLD_READ)
    set(_doc \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_DATAROOTDIR}/doc\")
    file(MAKE_DIRECTORY \"\${_doc}\")
    file(CREATE_LINK \"${doc_name}\" \"\${_doc}/${doc_name}-dbgsym\" SYMBOLIC)
  " COMPONENT ${component}_dbgsym)
endfunction()
