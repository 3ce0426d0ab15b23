# Finds the C++ Actor Framework 0.17.6 and defines the imported targets
# CAF::core and CAF::io.
#
# Debian's libcaf-dev ships no CMake package config, so this finds it by hand
# and says clearly what is missing. Used by HERM's own build (included from the
# root CMakeLists.txt) and by the installed package (hermConfig.cmake includes
# this file), so a user's module process finds CAF the same way HERM did.
#
# Contract: CAF::core carries CAF_ENABLE_TYPE_ID_CHECKS, because every message
# type must carry a type ID from HERM's single block; code that includes HERM's
# headers must compile with the same definition. Safe to include twice.

if(TARGET CAF::core AND TARGET CAF::io)
  return()
endif()

# HERM_CAF_ROOT: a CAF installed elsewhere, searched before (and instead of)
# the system's; tests/tsan/build-caf.sh installs one built with
# ThreadSanitizer there.
set(HERM_CAF_ROOT "" CACHE PATH "Prefix of a CAF 0.17.6 to use instead of the system's")
if(HERM_CAF_ROOT)
  find_path(CAF_INCLUDE_DIR caf/all.hpp PATHS "${HERM_CAF_ROOT}/include"
            NO_DEFAULT_PATH)
  find_library(CAF_CORE_LIBRARY caf_core PATHS "${HERM_CAF_ROOT}/lib"
               NO_DEFAULT_PATH)
  find_library(CAF_IO_LIBRARY caf_io PATHS "${HERM_CAF_ROOT}/lib"
               NO_DEFAULT_PATH)
else()
  find_path(CAF_INCLUDE_DIR caf/all.hpp)
  find_library(CAF_CORE_LIBRARY caf_core)
  find_library(CAF_IO_LIBRARY caf_io)
endif()
if(HERM_CAF_ROOT)
  set(HERM_CAF_ROOT_HINT
      "; HERM_CAF_ROOT='${HERM_CAF_ROOT}' was searched only (tests/tsan/build-caf.sh fills it)")
endif()
if(NOT CAF_INCLUDE_DIR OR NOT CAF_CORE_LIBRARY OR NOT CAF_IO_LIBRARY)
  message(FATAL_ERROR
    "HERM needs the C++ Actor Framework 0.17.6 (headers caf/all.hpp, libraries "
    "caf_core and caf_io). Found: headers='${CAF_INCLUDE_DIR}' "
    "core='${CAF_CORE_LIBRARY}' io='${CAF_IO_LIBRARY}'. "
    "Install it with: sudo apt-get install libcaf-dev   (or run .ci/setup)"
    "${HERM_CAF_ROOT_HINT}")
endif()
file(STRINGS "${CAF_INCLUDE_DIR}/caf/config.hpp" caf_version_line
     REGEX "^#define CAF_VERSION [0-9]+")
string(REGEX REPLACE "^#define CAF_VERSION ([0-9]+).*" "\\1" CAF_VERSION_NUM
       "${caf_version_line}")
if(NOT CAF_VERSION_NUM EQUAL 1706)
  message(FATAL_ERROR "HERM is written against CAF 0.17.6 (CAF_VERSION 1706); "
                      "found CAF_VERSION '${CAF_VERSION_NUM}' in ${CAF_INCLUDE_DIR}")
endif()

# Imported (not plain) targets: an exported HERM library that links CAF::core
# names it as "CAF::core" in hermTargets.cmake, which this file defines again
# on the user's side. Imported include directories are SYSTEM by default.
add_library(CAF::core UNKNOWN IMPORTED)
set_target_properties(CAF::core PROPERTIES
  IMPORTED_LOCATION "${CAF_CORE_LIBRARY}"
  INTERFACE_INCLUDE_DIRECTORIES "${CAF_INCLUDE_DIR}"
  INTERFACE_COMPILE_DEFINITIONS CAF_ENABLE_TYPE_ID_CHECKS)
add_library(CAF::io UNKNOWN IMPORTED)
set_target_properties(CAF::io PROPERTIES
  IMPORTED_LOCATION "${CAF_IO_LIBRARY}"
  INTERFACE_LINK_LIBRARIES CAF::core)
