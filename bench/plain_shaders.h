// Private to the benchmarks: the plain-texture baseline's fragment shader,
// embedded at build time from bench/shaders/.
#pragma once

namespace clipstream::shaders {
extern const char* const k_ground_plain_frag;
}  // namespace clipstream::shaders
