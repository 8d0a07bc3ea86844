// Private GL helpers: program building and camera uniforms shared by the
// clipmap and the baseline ground shaders. GL thread only.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <string>

namespace clipstream::gl_util {

// Links fullscreen.vert with ground_ray.glsl + `fragment_body` (the
// "#version" line, renderer_config defines and `extra_defines`, e.g.
// "#define OVERLAY\n", are prepended here).
// kUnavailable with the compiler log on failure.
Status buildGroundProgram(const char* fragment_body, uint32_t* program,
                          const std::string& extra_defines = {});

// Sets the uniforms declared in ground_ray.glsl for this camera, image size
// (level-0 texels) and viewport. The program must be in use.
void setRayUniforms(uint32_t program, const Camera& camera, const Viewport& viewport,
                    double image_width_px, double image_height_px);

}  // namespace clipstream::gl_util
