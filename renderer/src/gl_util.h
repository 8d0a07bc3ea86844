// Private GL helpers: program building and camera uniforms shared by the
// clipmap and the baseline ground shaders. GL thread only.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace clipstream::gl_util {

// Milliseconds from `start` to now, for the frame's timings.
inline double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

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

// Clears GL's error flags: call before creating resources that
// checkCreated() then checks, so an earlier, unrelated error is not blamed
// on them.
void clearErrors();

// Whether the resources created since clearErrors() were made: kOk, or
// kOutOfMemory (GL_OUT_OF_MEMORY) / kUnavailable (any other GL error)
// naming `what` (e.g. "the clip stack, 2207.6 MiB of RGBA8") and the error.
// Every GL resource creation is checked by one of these: a texture the
// driver cannot allocate would otherwise draw as black with exit 0.
// `hint`, if any, follows: what the user can change.
Status checkCreated(const std::string& what, const std::string& hint = {});

// The "#version" line and renderer_config's #defines every program starts with.
std::string shaderHeader(const std::string& extra_defines);

// Sets the uniforms declared in ground_ray.glsl for this camera, image size
// (level-0 texels) and viewport. The program must be in use.
void setRayUniforms(uint32_t program, const Camera& camera, const Viewport& viewport,
                    double image_width_px, double image_height_px);

}  // namespace clipstream::gl_util
