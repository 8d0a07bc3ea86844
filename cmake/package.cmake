# The Debian packages: `cpack -G DEB` in the build folder (or the `package`
# target) turns the two install components (cmake/install.cmake) into two
# packages, installed under /usr in Debian's layout:
#   clipstream_<version>_<arch>.deb          the programs, the tiler's module,
#       manual pages, bash completion, README and docs;
#   libclipstream-dev_<version>_<arch>.deb   the static libraries in the
#       multiarch folder, their headers, the CMake package and clipstream.pc.
# The -dev package depends on the programs' package of the same version:
# a host's tiler loads the image reader module that package ships.
#
# The programs' Depends is computed by dpkg-shlibdeps from the programs and
# the module (libopenimageio2.4, libzstd1, libglfw3, libegl1, ...), so it
# follows what they really link. The -dev package depends on the -dev
# packages its headers and clipstream.pc name.
#
# Each package carries a copyright file and a changelog in
# /usr/share/doc/<package>/ (lintian, docs/deployment.md "Debian packages").
set(CPACK_PACKAGE_NAME clipstream)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "clipstream")
set(CPACK_PACKAGE_CONTACT "${CLIPSTREAM_PACKAGE_MAINTAINER}")
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)  # programs and module only: CMake never strips static libraries

set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_ALL programs dev)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${CLIPSTREAM_PACKAGE_MAINTAINER}")
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)

set(CPACK_DEBIAN_PROGRAMS_PACKAGE_NAME clipstream)
set(CPACK_DEBIAN_PROGRAMS_PACKAGE_SECTION graphics)
set(CPACK_DEBIAN_PROGRAMS_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PROGRAMS_PACKAGE_SUGGESTS "libclipstream-dev")
# The first line is the synopsis; CPack indents the rest and marks the blank line.
set(CPACK_DEBIAN_PROGRAMS_DESCRIPTION
"out-of-core megatexture streaming: tiler, streamer and clipmap viewer
clipstream shows textures and terrain far larger than RAM or GPU memory
through a clipmap. clipstream-tile cuts an image, a mosaic of sheets or a
DEM into a tile store (a checksummed, compressed mip pyramid), or one band
of it for a sharded run that clipstream-merge joins; clipstream-info
inspects and verifies stores; clipstream-fly and clipstream-view fly over
them (headless EGL, or a GLFW window); clipstream-trace replays request
traces against the cache policies.")

set(CPACK_DEBIAN_DEV_PACKAGE_NAME libclipstream-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS
    "clipstream (= ${PROJECT_VERSION}), libzstd-dev, libxxhash-dev, libglm-dev, nlohmann-json3-dev, libcurl4-openssl-dev | libcurl-dev, libtiff-dev, libjpeg-dev, libpng-dev, libxml2-dev, libproj-dev, libegl-dev, libopengl-dev, pkg-config")
set(CPACK_DEBIAN_DEV_DESCRIPTION
"out-of-core megatexture streaming: development files
The static libraries clipstream::store, ::tiler, ::streamer and ::renderer,
their C++20 headers, a CMake package (find_package(clipstream)) and
clipstream.pc, to embed the tile store, the streamer and the clipmap
renderer in another program; see /usr/share/doc/clipstream/api.md.")

include(CPack)
