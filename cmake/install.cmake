# Installation: what `cmake --install` puts under a prefix, so that other
# programs can embed clipstream (docs/api.md). LIBDIR is Debian's multiarch
# folder, lib/x86_64-linux-gnu on amd64, under every prefix (see below).
# Two components, one Debian package each (cmake/package.cmake):
#   programs (package clipstream):
#     bin/clipstream-*                  the programs
#     LIBDIR/clipstream/libclipstream_tiler_oiio.so   the image reader modules the tiler loads
#     LIBDIR/clipstream/libclipstream_tiler_gdal.so   (OpenImageIO's, GDAL's) when an input needs one
#     share/man/man1/clipstream-*.1.gz  their manual pages (help2man, from --help)
#     share/bash-completion/completions/clipstream-*  their shell completion
#     share/doc/clipstream/             README, docs, copyright
#   dev (package libclipstream-dev):
#     LIBDIR/libclipstream_<name>.a     the libraries (static), exported as clipstream::<name>
#     include/clipstream/<name>/        their public headers
#     LIBDIR/cmake/clipstream/          clipstreamConfig.cmake, its version file, the exported targets
#     LIBDIR/pkgconfig/clipstream.pc    the same libraries for pkg-config
#
# Each library folder calls clipstream_install_library(); the top level
# includes this file before its subdirectories and calls
# clipstream_install_package() after them. Internal targets
# (clipstream_warnings, clipstream::cli, the evaluation library) are never
# installed: an exported library may link them only as
# $<BUILD_INTERFACE:...>, or CMake stops at generation with "requires target
# ... that is not in any export set".
include_guard(GLOBAL)
# Libraries go to the multiarch folder under any prefix, not only under /usr
# as GNUInstallDirs alone would: one layout for `cmake --install --prefix`
# and the Debian package, which is made from the same install rules.
# find_package and pkg-config (with PKG_CONFIG_PATH) look there.
if(CMAKE_LIBRARY_ARCHITECTURE AND NOT DEFINED CACHE{CMAKE_INSTALL_LIBDIR})
  set(CMAKE_INSTALL_LIBDIR lib/${CMAKE_LIBRARY_ARCHITECTURE}
      CACHE PATH "Object code libraries (LIBDIR); the multiarch folder on Debian")
endif()
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(CLIPSTREAM_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/clipstream)
set(CLIPSTREAM_CMAKE_DIR ${CMAKE_CURRENT_LIST_DIR})
# Named in the Debian packages (cmake/package.cmake) and their changelogs.
set(CLIPSTREAM_PACKAGE_MAINTAINER "clipstream maintainers <maintainers@clipstream.invalid>"
    CACHE STRING "Maintainer field of the Debian packages")
# The tiler's image reader module: a private library of the programs.
set(CLIPSTREAM_INSTALL_MODULEDIR ${CMAKE_INSTALL_LIBDIR}/clipstream)

# Manual pages are made at build time by help2man from each program's
# --help and --version (scripts/deps.sh installs it); without it the build
# goes on and installs none.
find_program(CLIPSTREAM_HELP2MAN help2man)
find_program(CLIPSTREAM_GZIP gzip)
if(NOT CLIPSTREAM_HELP2MAN OR NOT CLIPSTREAM_GZIP)
  message(WARNING "help2man or gzip not found: no manual pages (apt-get install help2man)")
endif()

# `installables`: every target `cmake --install` installs, and nothing else
# (no tests, no benchmarks). scripts/demo.sh builds it, so the README's
# install step works right after the demo; scripts/test.sh installs right
# after building it, before the rest, to keep it so.
add_custom_target(installables)

# clipstream_install_program(<target> SUMMARY "what it does")
# clipstream_install_module(<target>)
#
# Installs a program to bin/ with its manual page (help2man: SUMMARY is the
# NAME line, "clipstream-tile - SUMMARY") and its bash completion, or the
# tiler's module to CLIPSTREAM_INSTALL_MODULEDIR; all in the `programs`
# component, and added to `installables`.
function(clipstream_install_program target)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "SUMMARY" "")
  if(NOT arg_SUMMARY)
    message(FATAL_ERROR "clipstream_install_program(${target}): SUMMARY is required (the manual page's NAME)")
  endif()
  install(TARGETS ${target} RUNTIME COMPONENT programs)
  add_dependencies(installables ${target})
  # Completion: bash-completion loads completions/<command> on first use.
  install(FILES ${CLIPSTREAM_CMAKE_DIR}/bash_completion RENAME ${target}
    DESTINATION ${CMAKE_INSTALL_DATADIR}/bash-completion/completions COMPONENT programs)
  if(CLIPSTREAM_HELP2MAN AND CLIPSTREAM_GZIP)
    set(page ${PROJECT_BINARY_DIR}/man/${target}.1)
    # -N: no pointer to a Texinfo manual; gzip -n: no time stamp, so the
    # page is the same from build to build.
    add_custom_command(OUTPUT ${page}.gz
      COMMAND ${CMAKE_COMMAND} -E make_directory ${PROJECT_BINARY_DIR}/man
      COMMAND ${CLIPSTREAM_HELP2MAN} -N --name=${arg_SUMMARY}
              --section=1 "--source=clipstream ${PROJECT_VERSION}" --manual=clipstream --output=${page}
              $<TARGET_FILE:${target}>
      COMMAND ${CLIPSTREAM_GZIP} -9nf ${page}
      DEPENDS ${target}
      COMMENT "Manual page ${target}.1 (help2man)"
      VERBATIM)
    add_custom_target(${target}_man ALL DEPENDS ${page}.gz)
    add_dependencies(installables ${target}_man)
    install(FILES ${page}.gz DESTINATION ${CMAKE_INSTALL_MANDIR}/man1 COMPONENT programs)
  endif()
endfunction()

function(clipstream_install_module target)
  install(TARGETS ${target} LIBRARY DESTINATION ${CLIPSTREAM_INSTALL_MODULEDIR} COMPONENT programs)
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
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev)
  add_dependencies(installables ${target})
  install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/clipstream/${name}
    DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/clipstream COMPONENT dev
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
    DESTINATION ${CLIPSTREAM_INSTALL_CMAKEDIR} FILE clipstreamTargets.cmake COMPONENT dev)

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
    DESTINATION ${CLIPSTREAM_INSTALL_CMAKEDIR} COMPONENT dev)

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
  install(FILES ${PROJECT_BINARY_DIR}/clipstream.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig
    COMPONENT dev)

  install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT programs)
  # Each Debian package's copyright and changelog (cmake/debian/), in its
  # own share/doc/<package>/; the changelog compressed without a time stamp.
  foreach(pair IN ITEMS "clipstream|programs" "libclipstream-dev|dev")
    string(REPLACE "|" ";" pair "${pair}")
    list(GET pair 0 package)
    list(GET pair 1 component)
    set(folder ${PROJECT_BINARY_DIR}/debian/${package})
    configure_file(${CLIPSTREAM_CMAKE_DIR}/debian/changelog.in ${folder}/changelog @ONLY)
    execute_process(COMMAND gzip -9nf ${folder}/changelog RESULT_VARIABLE gzipped)
    if(NOT gzipped EQUAL 0)
      message(FATAL_ERROR "gzip ${folder}/changelog failed (${gzipped})")
    endif()
    install(FILES ${CLIPSTREAM_CMAKE_DIR}/debian/copyright ${folder}/changelog.gz
      DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/${package} COMPONENT ${component})
  endforeach()
  # The guides and the charts they show; the measurements behind the charts
  # (docs/data) stay in the source tree.
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}
    COMPONENT programs PATTERN "data" EXCLUDE)
endfunction()
