# The Debian package: `cpack -G DEB` in the build folder (or the `package`
# target) turns what `cmake --install` puts under a prefix into
# clipstream_<version>_<arch>.deb, installed under /usr: the programs, the
# static libraries with their headers, CMake package and clipstream.pc, and
# the documentation.
#
# Depends is computed by dpkg-shlibdeps from the programs and the tiler's
# OpenImageIO module (libopenimageio2.4, libzstd1, libxxhash0, libglfw3,
# libegl1, libopengl0, ...), so it follows what they really link. What a host
# needs to build against the libraries (the -dev packages) is suggested, not
# required: a user of the programs alone does not need compilers' headers.
set(CPACK_PACKAGE_NAME clipstream)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "clipstream")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "out-of-core megatexture streaming: tiler, streamer and clipmap renderer")
set(CLIPSTREAM_PACKAGE_MAINTAINER "clipstream maintainers <maintainers@clipstream.invalid>"
    CACHE STRING "Maintainer field of the Debian package")
set(CPACK_PACKAGE_CONTACT "${CLIPSTREAM_PACKAGE_MAINTAINER}")
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)  # programs and module only: CMake never strips static libraries

set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${CLIPSTREAM_PACKAGE_MAINTAINER}")
set(CPACK_DEBIAN_PACKAGE_SECTION graphics)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SUGGESTS
    "libzstd-dev, libxxhash-dev, libglm-dev, nlohmann-json3-dev, libegl-dev, libopengl-dev, pkg-config")
# The body under the summary line; CPack indents it and marks the blank line.
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
"clipstream shows textures far larger than RAM or GPU memory as a clipmap.
clipstream-tile cuts an image or a mosaic of sheets into a tile store (a
checksummed, compressed mip pyramid), or one band of it for a sharded run
that clipstream-merge joins; clipstream-info inspects and verifies stores, clipstream-fly
and clipstream-view fly over them (headless EGL / GLFW window), and
clipstream-trace replays request traces against the cache policies.

The static libraries (clipstream::store, ::tiler, ::streamer, ::renderer),
their headers, a CMake package and clipstream.pc let other engines embed
the streamer and the renderer; see /usr/share/doc/clipstream/api.md.")

include(CPack)
