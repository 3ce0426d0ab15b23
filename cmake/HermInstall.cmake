# Installing HERM on a robot (docs: "Installing on a robot").
#
# `cmake --install build [--prefix P]` puts in place:
#   lib/libherm_*.a               every HERM library (static, as the build makes
#                                 them; shared with -DBUILD_SHARED_LIBS=ON)
#   include/herm/{actors,channels,routing}/...   the public headers, in the
#                                 layout the code includes them with
#   lib/cmake/herm/               hermConfig.cmake, hermConfigVersion.cmake,
#                                 hermTargets*.cmake, HermFindCAF.cmake: a module
#                                 process does find_package(herm) and links
#                                 herm::herm (or herm::herm_asl, ...)
#   bin/hermd, bin/hermctl        when those targets exist
#   lib/systemd/system/hermd@.service   with hermd
#   share/herm/examples/*.yaml    example module configurations
# and `cpack -G DEB` in the build directory packs the same tree as a .deb.
#
# Included last from the root CMakeLists.txt, after every target exists.

include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(HERM_INSTALL_CMAKEDIR "${CMAKE_INSTALL_LIBDIR}/cmake/herm" CACHE STRING
    "Where the CMake package files of HERM are installed (relative to the prefix)")
set(HERM_INSTALL_INCLUDEDIR "${CMAKE_INSTALL_INCLUDEDIR}/herm")

# -- the libraries ----------------------------------------------------------------
# Every library made under actors/, channels/ and routing/ is exported, found by
# walking those directories, so that a library added there later is exported
# without an edit here (a missing one would break generation for everybody:
# "target X requires target Y that is not in any export set").
function(herm_collect_libraries dir out)
  set(found "")
  get_property(targets DIRECTORY "${dir}" PROPERTY BUILDSYSTEM_TARGETS)
  foreach(t IN LISTS targets)
    get_target_property(type ${t} TYPE)
    if(type MATCHES "^(STATIC|SHARED|MODULE|OBJECT|INTERFACE)_LIBRARY$")
      list(APPEND found ${t})
    endif()
  endforeach()
  get_property(subdirs DIRECTORY "${dir}" PROPERTY SUBDIRECTORIES)
  foreach(sub IN LISTS subdirs)
    herm_collect_libraries("${sub}" sub_found)
    list(APPEND found ${sub_found})
  endforeach()
  set(${out} ${found} PARENT_SCOPE)
endfunction()

set(herm_libraries "")
foreach(dir actors channels routing)
  herm_collect_libraries("${PROJECT_SOURCE_DIR}/${dir}" dir_libraries)
  list(APPEND herm_libraries ${dir_libraries})
endforeach()

# herm::herm: the umbrella a module process links.
add_library(herm INTERFACE)
target_link_libraries(herm INTERFACE ${herm_libraries})
add_library(herm::herm ALIAS herm)

# herm_warnings is linked PRIVATE everywhere, but a static library's private
# links still appear in its exported interface ($<LINK_ONLY:herm_warnings>), so
# it has to be in the export set. Its flags are for HERM's own sources only:
# outside the build tree herm::herm_warnings is empty.
get_target_property(herm_warning_flags herm_warnings INTERFACE_COMPILE_OPTIONS)
if(herm_warning_flags)
  set_property(TARGET herm_warnings PROPERTY
               INTERFACE_COMPILE_OPTIONS "$<BUILD_INTERFACE:${herm_warning_flags}>")
endif()

# A robot needs no debug info: `cmake --install` strips as `--strip` does
# (below: programs stripped, static libraries without their debug info),
# unless configured with -DHERM_INSTALL_STRIP=OFF. The .deb strips its files
# too (CPACK_STRIP_FILES). Every install rule of HERM is in this file,
# after this one.
option(HERM_INSTALL_STRIP "cmake --install strips programs and the debug info of libraries" ON)
if(HERM_INSTALL_STRIP)
  install(CODE "set(CMAKE_INSTALL_DO_STRIP TRUE)")
endif()

install(TARGETS ${herm_libraries} herm herm_warnings
  EXPORT hermTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

# `cmake --install --strip` (and the .deb) strips executables and shared
# libraries; static libraries keep their symbols but lose their debug info.
if(CMAKE_STRIP)
  foreach(t IN LISTS herm_libraries)
    get_target_property(type ${t} TYPE)
    if(type STREQUAL "STATIC_LIBRARY")
      install(CODE "
        if(CMAKE_INSTALL_DO_STRIP)
          execute_process(COMMAND \"${CMAKE_STRIP}\" --strip-debug
            \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_LIBDIR}/$<TARGET_FILE_NAME:${t}>\")
        endif()")
    endif()
  endforeach()
endif()

# -- the headers --------------------------------------------------------------------
# Sources include "actors/x.hpp", "channels/x.hpp", "routing/x.hpp" relative to
# the source root, which is include/herm once installed.
foreach(dir actors channels routing)
  install(DIRECTORY "${PROJECT_SOURCE_DIR}/${dir}"
    DESTINATION ${HERM_INSTALL_INCLUDEDIR}
    FILES_MATCHING PATTERN "*.hpp" PATTERN "*.def"
    PATTERN "include" EXCLUDE) # actors/include/herm/herm.hpp: below, once
endforeach()
# The users' one header: <herm/herm.hpp> (include/herm is on the path).
install(FILES "${PROJECT_SOURCE_DIR}/actors/include/herm/herm.hpp"
  DESTINATION ${HERM_INSTALL_INCLUDEDIR}/herm)

# -- the CMake package ------------------------------------------------------------
# Static libraries carry their private dependencies into the user's link
# (zlib, OpenSSL's libcrypto, yaml-cpp; nlohmann_json is an exported target name), so the package
# config must find them too; shared ones do not.
get_target_property(herm_runtime_type herm_runtime TYPE)
if(herm_runtime_type STREQUAL "STATIC_LIBRARY")
  set(HERM_STATIC_LIBRARIES ON)
else()
  set(HERM_STATIC_LIBRARIES OFF)
endif()

install(EXPORT hermTargets
  NAMESPACE herm::
  DESTINATION ${HERM_INSTALL_CMAKEDIR})
configure_package_config_file(
  "${PROJECT_SOURCE_DIR}/cmake/hermConfig.cmake.in"
  "${PROJECT_BINARY_DIR}/hermConfig.cmake"
  INSTALL_DESTINATION ${HERM_INSTALL_CMAKEDIR})
write_basic_package_version_file(
  "${PROJECT_BINARY_DIR}/hermConfigVersion.cmake"
  VERSION ${PROJECT_VERSION}
  COMPATIBILITY SameMajorVersion)
install(FILES
  "${PROJECT_BINARY_DIR}/hermConfig.cmake"
  "${PROJECT_BINARY_DIR}/hermConfigVersion.cmake"
  "${PROJECT_SOURCE_DIR}/cmake/HermFindCAF.cmake"
  DESTINATION ${HERM_INSTALL_CMAKEDIR})

# -- hermd, hermctl and the systemd unit ------------------------------------------
foreach(tool hermd hermctl)
  if(TARGET ${tool})
    install(TARGETS ${tool} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
  endif()
endforeach()

if(TARGET hermd)
  # One service per module configuration: hermd@robot runs /etc/herm/robot.yaml.
  set(herm_unit_dir lib/systemd/system)
  install(FILES "${PROJECT_SOURCE_DIR}/packaging/systemd/hermd@.service"
          DESTINATION ${herm_unit_dir})
  # The unit names /usr/bin/hermd (the .deb's path). Installed under another
  # prefix (/usr/local, a test's temporary directory), it names that prefix's
  # hermd instead. Evaluated at install time, so --prefix is honoured.
  install(CODE "
    set(unit \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${herm_unit_dir}/hermd@.service\")
    set(bin \"\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_BINDIR}/hermd\")
    if(NOT bin STREQUAL \"/usr/bin/hermd\")
      file(READ \"\${unit}\" text)
      string(REPLACE \"/usr/bin/hermd\" \"\${bin}\" text \"\${text}\")
      file(WRITE \"\${unit}\" \"\${text}\")
    endif()
  ")
endif()

# -- example configurations ----------------------------------------------------------
# apps/hermd/examples/*.yaml; none yet (or no folder) installs nothing.
# CONFIGURE_DEPENDS: a new example is picked up by the next build.
file(GLOB herm_example_configs CONFIGURE_DEPENDS
     "${PROJECT_SOURCE_DIR}/apps/hermd/examples/*.yaml")
if(herm_example_configs)
  install(FILES ${herm_example_configs}
          DESTINATION ${CMAKE_INSTALL_DATADIR}/herm/examples)
endif()

# -- the Debian package: cpack -G DEB ---------------------------------------------
set(HERM_PACKAGE_MAINTAINER "HERM developers <dev@herm.invalid>" CACHE STRING
    "Maintainer field of the .deb")
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME herm)
set(CPACK_PACKAGE_VENDOR "HERM")
set(CPACK_PACKAGE_CONTACT "${HERM_PACKAGE_MAINTAINER}")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "Heterogeneous nEtwork-based Robot Middleware (CAF actors over CAN, serial, Ethernet)")
set(CPACK_PACKAGE_DESCRIPTION
    "HERM lets an application on one module of a robot talk to an application "
    "on any other module without knowing which links lie between them. This "
    "package holds the module daemon hermd with its systemd unit hermd@.service, "
    "the control tool hermctl, example configurations, and the static libraries, "
    "headers and CMake package (find_package(herm)) for writing module processes.")
string(JOIN "" CPACK_PACKAGE_DESCRIPTION ${CPACK_PACKAGE_DESCRIPTION})
# The package installs under /usr (CPack's DEB generator stages through
# DESTDIR with CMAKE_INSTALL_PREFIX=/usr, so the unit keeps /usr/bin/hermd).
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON) # a robot needs no debug info (RelWithDebInfo: 140 MB)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${HERM_PACKAGE_MAINTAINER}")
set(CPACK_DEBIAN_PACKAGE_SECTION net)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
# Run-time Depends of hermd and hermctl: derived by dpkg-shlibdeps (libcaf-*,
# libyaml-cpp, libstdc++, ...) where it is installed (dpkg-dev), else CAF's
# run-time libraries by hand.
find_program(HERM_DPKG_SHLIBDEPS dpkg-shlibdeps)
mark_as_advanced(HERM_DPKG_SHLIBDEPS)
if(HERM_DPKG_SHLIBDEPS)
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
else()
  set(CPACK_DEBIAN_PACKAGE_DEPENDS
      "libcaf-core0.17 (>= 0.17.6), libcaf-io0.17 (>= 0.17.6), libstdc++6")
endif()
# What find_package(herm) needs to build a module process against the static
# libraries; recommended, so that a robot that only runs hermd can skip them.
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS
    "libcaf-dev (>= 0.17.6), zlib1g-dev, libssl-dev, libyaml-cpp-dev, nlohmann-json3-dev, cmake")
# `cpack --config CPackSourceConfig.cmake`: sources only, no build trees.
set(CPACK_SOURCE_IGNORE_FILES "/\\.git/" "/build[^/]*/" "/\\.cache/")
include(CPack)
