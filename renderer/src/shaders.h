// Private: GLSL sources embedded at build time from renderer/shaders/.
#pragma once

namespace clipstream::shaders {
extern const char* const k_fullscreen_vert;
extern const char* const k_ground_ray_glsl;
extern const char* const k_ground_clipmap_frag;
extern const char* const k_terrain_heights_glsl;
extern const char* const k_terrain_vert;
extern const char* const k_terrain_ground_glsl;
extern const char* const k_terrain_position_frag;
extern const char* const k_hud_vert;
extern const char* const k_hud_frag;
}  // namespace clipstream::shaders
