# Installation: what `cmake --install` puts under a prefix, so that other
# programs can embed clipstream (docs/api.md):
#   lib/libclipstream_<name>.a        the libraries (static), exported as clipstream::<name>
#   include/clipstream/<name>/        their public headers
#   bin/clipstream-*                  the programs (+ lib/libclipstream_tiler_oiio.so, loaded by the tiler)
#   lib/cmake/clipstream/             clipstreamConfig.cmake, its version file, the exported targets
#   lib/pkgconfig/clipstream.pc       the same libraries for pkg-config
#   share/doc/clipstream/             README and docs
#
# Each library folder calls clipstream_install_library(); the top level
# includes this file before its subdirectories and calls
# clipstream_install_package() after them. Internal targets
# (clipstream_warnings, clipstream::cli, the evaluation library) are never
# installed: an exported library may link them only as
# $<BUILD_INTERFACE:...>, or CMake stops at generation with "requires target
# ... that is not in any export set".
include_guard(GLOBAL)
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(CLIPSTREAM_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/clipstream)
set(CLIPSTREAM_CMAKE_DIR ${CMAKE_CURRENT_LIST_DIR})

# `installables`: every target `cmake --install` installs, and nothing else
# (no tests, no benchmarks). scripts/demo.sh builds it, so the README's
# install step works right after the demo; scripts/test.sh installs right
# after building it, before the rest, to keep it so.
add_custom_target(installables)

# clipstream_install_program(<target> [DESTINATION dir])
#
# Installs a program (to bin/, or DESTINATION for a module the tiler loads)
# and adds it to `installables`.
function(clipstream_install_program target)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "DESTINATION" "")
  if(arg_DESTINATION)
    install(TARGETS ${target} LIBRARY DESTINATION ${arg_DESTINATION})
  else()
    install(TARGETS ${target})
  endif()
  add_dependencies(installables ${target})
endfunction()

# clipstream_install_library(<clipstream_NAME> [PKG_CONFIG module...] [LIBS lib...])
#
# Installs the library and the public headers of the calling folder
# (include/clipstream/NAME/) into the export set as clipstream::NAME: the
# same name as the build's ALIAS, so a host's target_link_libraries() line is
# the same whether it builds clipstream as a subproject or finds it installed.
# PKG_CONFIG names the pkg-config modules the library needs at link time,
# LIBS other libraries (-pthread, or a name such as ${CMAKE_DL_LIBS}):
# clipstream.pc lists both, since the libraries are static and their private
# dependencies reach the host's link line.
function(clipstream_install_library target)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "" "PKG_CONFIG;LIBS")
  if(NOT target MATCHES "^clipstream_([a-z]+)$")
    message(FATAL_ERROR "clipstream_install_library: '${target}' is not named clipstream_<name>")
  endif()
  set(name ${CMAKE_MATCH_1})
  if(NOT TARGET clipstream::${name})
    message(FATAL_ERROR "clipstream_install_library: ${target} has no ALIAS clipstream::${name}")
  endif()
  get_target_property(aliased clipstream::${name} ALIASED_TARGET)
  if(NOT aliased STREQUAL target)
    message(FATAL_ERROR "clipstream_install_library: clipstream::${name} is ${aliased}, not ${target}")
  endif()
  if(NOT IS_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/clipstream/${name})
    message(FATAL_ERROR "clipstream_install_library: no public headers in "
                        "${CMAKE_CURRENT_SOURCE_DIR}/include/clipstream/${name}")
  endif()
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${name})
  # The public headers are C++20: a host compiling with an older default
  # gets the standard raised for its targets that link this one.
  target_compile_features(${target} PUBLIC cxx_std_20)
  install(TARGETS ${target} EXPORT clipstreamTargets
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
  add_dependencies(installables ${target})
  install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/clipstream/${name}
    DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/clipstream
    FILES_MATCHING PATTERN "*.h" PATTERN "*.hpp")
  set_property(GLOBAL APPEND PROPERTY CLIPSTREAM_INSTALLED_LIBRARIES ${name})
  set_property(GLOBAL APPEND PROPERTY CLIPSTREAM_PC_REQUIRES ${arg_PKG_CONFIG})
  foreach(lib IN LISTS arg_LIBS)
    if(NOT lib MATCHES "^-")
      set(lib -l${lib})  # a library name, as in ${CMAKE_DL_LIBS}
    endif()
    set_property(GLOBAL APPEND PROPERTY CLIPSTREAM_PC_LIBS ${lib})
  endforeach()
endfunction()

# Writes the package files for every library installed so far: the exported
# targets, clipstreamConfig.cmake + version file, clipstream.pc, and installs
# the documentation. The Debian package is set up in cmake/package.cmake.
function(clipstream_install_package)
  get_property(libraries GLOBAL PROPERTY CLIPSTREAM_INSTALLED_LIBRARIES)
  get_property(pc_requires GLOBAL PROPERTY CLIPSTREAM_PC_REQUIRES)
  get_property(pc_libs GLOBAL PROPERTY CLIPSTREAM_PC_LIBS)

  install(EXPORT clipstreamTargets NAMESPACE clipstream::
    DESTINATION ${CLIPSTREAM_INSTALL_CMAKEDIR} FILE clipstreamTargets.cmake)

  # clipstreamConfig.cmake finds the renderer's GL dependencies only when
  # the renderer was built.
  if(renderer IN_LIST libraries)
    set(CLIPSTREAM_CONFIG_RENDERER ON)
  else()
    set(CLIPSTREAM_CONFIG_RENDERER OFF)
  endif()
  set(CLIPSTREAM_CONFIG_LIBRARIES "${libraries}")
  configure_package_config_file(${CLIPSTREAM_CMAKE_DIR}/clipstreamConfig.cmake.in
    ${PROJECT_BINARY_DIR}/clipstreamConfig.cmake
    INSTALL_DESTINATION ${CLIPSTREAM_INSTALL_CMAKEDIR})
  # 0.x: a minor version may change the API, so only the same 0.MINOR matches.
  write_basic_package_version_file(${PROJECT_BINARY_DIR}/clipstreamConfigVersion.cmake
    VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
  install(FILES ${PROJECT_BINARY_DIR}/clipstreamConfig.cmake
                ${PROJECT_BINARY_DIR}/clipstreamConfigVersion.cmake
    DESTINATION ${CLIPSTREAM_INSTALL_CMAKEDIR})

  # clipstream.pc: static libraries, so a dependent comes before what it
  # uses (renderer, streamer, tiler, store: the reverse of the order in which
  # the folders, each after its dependencies, installed them)
  # and the dependencies go in Requires and Libs, not their .private forms:
  # plain `pkg-config --libs clipstream` gives a complete link line.
  # ${pcfiledir} keeps the file valid wherever the prefix is moved (a
  # temporary prefix, or /usr in the Debian package).
  set(pc_link "")
  foreach(name IN LISTS libraries)
    set(pc_link "-lclipstream_${name} ${pc_link}")
  endforeach()
  list(REMOVE_DUPLICATES pc_requires)
  list(REMOVE_DUPLICATES pc_libs)
  list(JOIN pc_requires " " CLIPSTREAM_PC_REQUIRES)
  list(JOIN pc_libs " " pc_libs)
  string(STRIP "-L\${libdir} ${pc_link}${pc_libs}" CLIPSTREAM_PC_LIBS)
  file(RELATIVE_PATH CLIPSTREAM_PC_PREFIX_FROM_PCFILEDIR  # "../.." for lib/pkgconfig
    /prefix/${CMAKE_INSTALL_LIBDIR}/pkgconfig /prefix)
  string(REGEX REPLACE "/$" "" CLIPSTREAM_PC_PREFIX_FROM_PCFILEDIR ${CLIPSTREAM_PC_PREFIX_FROM_PCFILEDIR})
  configure_file(${CLIPSTREAM_CMAKE_DIR}/clipstream.pc.in ${PROJECT_BINARY_DIR}/clipstream.pc @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/clipstream.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

  install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
  # The guides and the charts they show; the measurements behind the charts
  # (docs/data) stay in the source tree.
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}
    PATTERN "data" EXCLUDE)
endfunction()
