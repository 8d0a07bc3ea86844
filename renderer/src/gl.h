// Private: the one place GL headers are included. glvnd's libOpenGL exports
// every core entry point, so prototypes are enough (no loader).
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>

namespace clipstream {
// The one GL format of BC1 tiles (stack and pool alike).
constexpr GLenum kBc1Format = GL_COMPRESSED_RGB_S3TC_DXT1_EXT;
}  // namespace clipstream
