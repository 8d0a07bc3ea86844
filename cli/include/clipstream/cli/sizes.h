// Option values of the rendering programs: viewport sizes ("1280x720") and
// a resize at a frame ("120:640x360").
//
// Thread-safe: pure functions.
#pragma once

#include <clipstream/store/types.h>

#include <cstdint>
#include <string>

namespace clipstream::cli {

// Largest side parseSize() accepts: GL_MAX_RENDERBUFFER_SIZE of common drivers.
inline constexpr uint32_t kMaxSizeSidePx = 16384;

// "WIDTHxHEIGHT", decimal digits only, each side 1..kMaxSizeSidePx.
// kInvalidArgument with the text and the rule otherwise.
Status parseSize(const std::string& text, uint32_t* width_px, uint32_t* height_px);

// "FRAME:WIDTHxHEIGHT" with FRAME from 1 to max_frame (--resize-at).
Status parseResize(const std::string& text, uint32_t max_frame, uint32_t* frame, uint32_t* width_px,
                   uint32_t* height_px);

}  // namespace clipstream::cli
