# CPack: one .deb per role, each with its stripped binary, its systemd unit and its default config, and
# one airground-<role>-dbgsym per role with the binary's symbols (cmake/Dbgsym.cmake); lintian-clean
# (make package runs it on every package; docs/packaging.md lists the warnings left and why).
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME airground)
set(CPACK_PACKAGE_VENDOR "airground")
# Policy wants a deliverable address (lintian: bogus-mail-host for localhost); set yours with -DAG_PACKAGE_CONTACT.
set(AG_PACKAGE_CONTACT "airground maintainers <airground@example.org>" CACHE STRING "Maintainer field of the .deb packages")
set(CPACK_PACKAGE_CONTACT "${AG_PACKAGE_CONTACT}")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_ALL uav ugv base uav_dbgsym ugv_dbgsym base_dbgsym)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
if(CMAKE_SYSTEM_PROCESSOR MATCHES "aarch64|arm64")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)
else()
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE amd64)
endif()
# The binaries are static: nothing to depend on but adduser for the service account.
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser")
set(CPACK_PACKAGE_DIRECTORY ${CMAKE_BINARY_DIR}/packages)
# Not CPack's own CPACK_DEBIAN_DEBUGINFO_PACKAGE: CMake 3.25's lists absolute staging paths in the
# .ddeb's md5sums (lintian: md5sums-lists-nonexistent-file); cmake/Dbgsym.cmake splits the binaries
# with the toolchain's objcopy (aarch64's for the cross build) instead.

# Each package's own synopsis (policy: under 80 characters), not the project's description before it.
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "")
set(_ag_summary_uav "airground quadrotor role: semantic ortho-mapping")
set(_ag_summary_ugv "airground ground-robot role: semantic localization, planning, drive")
set(_ag_summary_base "airground base station role: monitor, relay, mission log")
# The changelog's date: the commit's, so two builds of one commit give the same package.
set(AG_CHANGELOG_DATE "Thu, 01 Jan 1970 00:00:00 +0000")
set(AG_GIT_REVISION "unknown")
find_package(Git QUIET)
if(GIT_FOUND AND EXISTS ${PROJECT_SOURCE_DIR}/.git)
  execute_process(COMMAND ${GIT_EXECUTABLE} log -1 --format=%cD WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
                  OUTPUT_VARIABLE _ag_date OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
  execute_process(COMMAND ${GIT_EXECUTABLE} rev-parse --short HEAD WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
                  OUTPUT_VARIABLE _ag_rev OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
  if(_ag_date AND _ag_rev)
    set(AG_CHANGELOG_DATE "${_ag_date}")
    set(AG_GIT_REVISION "${_ag_rev}")
  endif()
endif()
find_program(AG_GZIP gzip REQUIRED)
foreach(role uav ugv base)
  string(TOUPPER ${role} ROLE)
  set(AG_ROLE ${role})
  set(_dir ${CMAKE_BINARY_DIR}/debian/${role})
  configure_file(${PROJECT_SOURCE_DIR}/firmware_host/packaging/postinst.in ${_dir}/postinst @ONLY)
  configure_file(${PROJECT_SOURCE_DIR}/firmware_host/packaging/prerm.in ${_dir}/prerm @ONLY)
  configure_file(${PROJECT_SOURCE_DIR}/firmware_host/packaging/postrm.in ${_dir}/postrm @ONLY)
  file(WRITE ${_dir}/conffiles "/etc/airground/${role}.yaml\n")
  file(CHMOD ${_dir}/postinst ${_dir}/prerm ${_dir}/postrm PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
  set(CPACK_DEBIAN_${ROLE}_PACKAGE_NAME airground-${role})
  set(CPACK_DEBIAN_${ROLE}_DESCRIPTION "${_ag_summary_${role}}\nThe airground-${role} boot service of the airground robot team: one static\nbinary that runs the role's stage table, its systemd unit and its default\nconfiguration, /etc/airground/${role}.yaml. Symbols: airground-${role}-dbgsym.")
  set(CPACK_COMPONENT_${ROLE}_DESCRIPTION "${_ag_summary_${role}}")
  set(CPACK_DEBIAN_${ROLE}_PACKAGE_CONTROL_EXTRA "${_dir}/postinst;${_dir}/prerm;${_dir}/postrm;${_dir}/conffiles")
  set(CPACK_DEBIAN_${ROLE}_PACKAGE_CONTROL_STRICT_PERMISSION TRUE)
  # Policy 12.5 and 12.7: the copyright file and a (native package's) changelog.gz in /usr/share/doc/<package>.
  set(AG_PACKAGE airground-${role})
  set(AG_VERSION ${PROJECT_VERSION})
  set(AG_CONTACT "${AG_PACKAGE_CONTACT}")
  configure_file(${PROJECT_SOURCE_DIR}/firmware_host/packaging/copyright.in ${_dir}/doc/copyright @ONLY)
  configure_file(${PROJECT_SOURCE_DIR}/firmware_host/packaging/changelog.in ${_dir}/doc/changelog @ONLY)
  execute_process(COMMAND ${AG_GZIP} -9nf ${_dir}/doc/changelog RESULT_VARIABLE _rc)
  if(NOT _rc EQUAL 0)
    message(FATAL_ERROR "gzip ${_dir}/doc/changelog failed")
  endif()
  install(FILES ${_dir}/doc/copyright ${_dir}/doc/changelog.gz DESTINATION ${CMAKE_INSTALL_DATAROOTDIR}/doc/airground-${role} COMPONENT ${role})
  # The binaries are static by design (DESIGN.md: one static binary per role, runs on the Jetson's Ubuntu as is).
  file(WRITE ${_dir}/lintian-overrides "# static by design: one binary per role that runs on any Linux of its architecture (DESIGN.md)\n"
                                       "airground-${role}: statically-linked-binary [usr/bin/airground-${role}]\n")
  install(FILES ${_dir}/lintian-overrides DESTINATION ${CMAKE_INSTALL_DATAROOTDIR}/lintian/overrides RENAME airground-${role} COMPONENT ${role})

  # airground-<role>-dbgsym: the symbols, for exactly this version of the role's package.
  set(CPACK_DEBIAN_${ROLE}_DBGSYM_PACKAGE_NAME airground-${role}-dbgsym)
  set(CPACK_DEBIAN_${ROLE}_DBGSYM_PACKAGE_SECTION debug)
  set(CPACK_DEBIAN_${ROLE}_DBGSYM_PACKAGE_DEPENDS "airground-${role} (= ${PROJECT_VERSION})")
  set(CPACK_DEBIAN_${ROLE}_DBGSYM_DESCRIPTION "debug symbols for airground-${role}")
  set(CPACK_COMPONENT_${ROLE}_DBGSYM_DESCRIPTION "debug symbols for airground-${role}")
endforeach()
include(CPack)
