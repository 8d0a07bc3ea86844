// Private GL helpers: program building and camera uniforms shared by the
// clipmap and the baseline ground shaders. GL thread only.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <string>
#include <vector>

namespace clipstream::gl_util {

// Links fullscreen.vert with ground_ray.glsl + `fragment_body` (the
// "#version" line, renderer_config defines and `extra_defines`, e.g.
// "#define OVERLAY\n", are prepended here).
// kUnavailable with the compiler log on failure.
Status buildGroundProgram(const char* fragment_body, uint32_t* program,
                          const std::string& extra_defines = {});

// Links a vertex and a fragment shader, each given as the list of sources
// concatenated after the same header as buildGroundProgram().
// `feedback`: vertex outputs captured by transform feedback (interleaved);
// empty for none.
Status buildProgram(const std::string& vertex, const std::string& fragment, uint32_t* program,
                    const std::string& extra_defines = {},
                    const std::vector<const char*>& feedback = {});

// The "#version" line and renderer_config's #defines every program starts with.
std::string shaderHeader(const std::string& extra_defines);

// Sets the uniforms declared in ground_ray.glsl for this camera, image size
// (level-0 texels) and viewport. The program must be in use.
void setRayUniforms(uint32_t program, const Camera& camera, const Viewport& viewport,
                    double image_width_px, double image_height_px);

}  // namespace clipstream::gl_util
