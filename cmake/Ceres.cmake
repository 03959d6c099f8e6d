# Ceres Solver (the aerial pose graph) as one interface target, airground_ceres, that links either way:
#  - into the fully static role binaries (and cross-built static tests): Debian's static archives of
#    Ceres and of everything it pulls in, with reference BLAS/LAPACK (only libgfortran needed), libunwind
#    after libgcc_eh (whose _Unwind_* must win), and -u for the pthread symbols that libgfortran only
#    references weakly (otherwise they stay null in a static link and its exit handler jumps to 0);
#  - into ordinary executables (tests, the simulator): the same Ceres/glog/SuiteSparse archives, with the
#    shared BLAS/LAPACK/gfortran/libunwind (Debian's libunwind.a is not position-independent).
# Debian ships no static METIS; CHOLMOD's partition module references it, so shims/metis_unavailable.c
# answers METIS_ERROR. Ceres is configured for AMD ordering / Eigen sparse, so it is never reached.
# A target becomes fully static by setting its AG_FULLY_STATIC property (airground_role_binary does).
find_package(Eigen3 REQUIRED NO_MODULE)
find_path(AG_CERES_INCLUDE_DIR ceres/ceres.h REQUIRED)
set(_ag_ceres_archives ceres glog gflags spqr cholmod cxsparse ccolamd camd colamd amd suitesparseconfig)
set(_ag_ceres_static_libs)
foreach(_l IN LISTS _ag_ceres_archives)
  find_library(AG_STATIC_${_l} NAMES lib${_l}.a REQUIRED)
  list(APPEND _ag_ceres_static_libs ${AG_STATIC_${_l}})
endforeach()
# The reference archives live in lapack/ and blas/ subfolders (the top-level names are alternatives
# symlinks to shared libraries). In a cross build these absolute PATHS are re-rooted under
# CMAKE_FIND_ROOT_PATH / CMAKE_SYSROOT (the toolchain file's arm64 sysroot), so one spelling serves both.
find_library(AG_STATIC_lapack NAMES liblapack.a PATH_SUFFIXES lapack NO_CMAKE_SYSTEM_PATH REQUIRED
             PATHS /usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/lapack)
find_library(AG_STATIC_blas NAMES libblas.a PATH_SUFFIXES blas NO_CMAKE_SYSTEM_PATH REQUIRED
             PATHS /usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/blas)
find_library(AG_STATIC_unwind NAMES libunwind.a REQUIRED)
find_library(AG_STATIC_lzma NAMES liblzma.a REQUIRED)
# By full path: a cross linker does not search the sysroot folder for -lz (gfortran and gomp come
# with the compiler, natively and in the cross gcc, so -l finds them).
find_library(AG_STATIC_z NAMES libz.a REQUIRED)

add_library(airground_metis_unavailable STATIC ${PROJECT_SOURCE_DIR}/pipeline/aerial_mapping/shims/metis_unavailable.c)

add_library(airground_ceres INTERFACE)
target_include_directories(airground_ceres SYSTEM INTERFACE ${AG_CERES_INCLUDE_DIR})
target_compile_definitions(airground_ceres INTERFACE GLOG_NO_ABBREVIATED_SEVERITIES)
set(_ag_static $<BOOL:$<TARGET_PROPERTY:AG_FULLY_STATIC>>)
target_link_libraries(airground_ceres INTERFACE
  Eigen3::Eigen
  ${_ag_ceres_static_libs}
  airground_metis_unavailable
  $<${_ag_static}:${AG_STATIC_lapack}> $<${_ag_static}:${AG_STATIC_blas}>
  $<$<NOT:${_ag_static}>:lapack> $<$<NOT:${_ag_static}>:blas>
  gfortran
  $<$<STREQUAL:${CMAKE_SYSTEM_PROCESSOR},x86_64>:quadmath>
  gomp
  $<${_ag_static}:gcc_eh> $<${_ag_static}:${AG_STATIC_unwind}> $<$<NOT:${_ag_static}>:unwind>
  $<${_ag_static}:${AG_STATIC_lzma}> $<$<NOT:${_ag_static}>:lzma>
  $<${_ag_static}:${AG_STATIC_z}> $<$<NOT:${_ag_static}>:z>
  Threads::Threads)
target_link_options(airground_ceres INTERFACE
  $<${_ag_static}:LINKER:-u,pthread_mutex_lock,-u,pthread_mutex_unlock,-u,pthread_mutex_trylock,-u,pthread_mutex_init,-u,pthread_mutex_destroy,-u,pthread_key_create,-u,pthread_key_delete,-u,pthread_getspecific,-u,pthread_setspecific,-u,pthread_once,-u,pthread_cond_wait,-u,pthread_cond_broadcast,-u,pthread_cond_signal>)
