// Camera flight paths: JSON keyframes interpolated smoothly, and built-in
// paths scaled to a texture's size.
//
// Thread-safe: plain data; const methods may be called from any thread.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <string>
#include <vector>

namespace clipstream {

struct Keyframe {
  double t_s = 0.0;
  glm::dvec3 position{0.0, 100.0, 0.0};  // level-0 texels (camera.h)
  double heading_deg = 0.0;
  double pitch_deg = -30.0;
};

enum class Interpolation {
  kSmooth,  // Catmull-Rom position (tangents from neighbouring keys, non-uniform
            // times), shortest-arc heading, Hermite pitch
  kStep,    // hold each keyframe until the next one (teleports)
};

class FlightPath {
 public:
  // Parses {"interpolation": "smooth"|"step", "keyframes": [{"t", "x", "y",
  // "z", "heading_deg", "pitch_deg"}, ...]} or a bare keyframe array.
  // kInvalidArgument naming the field for malformed input, unsorted or
  // negative times, or no keyframe.
  static Status fromJson(const std::string& text, FlightPath* out);
  static Status load(const std::string& path, FlightPath* out);
  std::string toJson() const;
  // Writes toJson() to `path` under OutputFile's rule (temporary name, checked,
  // renamed; a regular file there is replaced). kIo / kNoSpace / kInvalidArgument.
  Status save(const std::string& path) const;

  // Built-in paths scaled to the texture: "pass" (low and fast across),
  // "dive" (orbit height down to the ground), "orbit", "teleport" (a jump
  // every `teleport_frames` frames of 1/60 s), "zoom" (straight down, high
  // to low and back). kInvalidArgument for an unknown name.
  static Status builtin(const std::string& name, const PyramidGeometry& geometry,
                        FlightPath* out, uint32_t teleport_frames = 30);
  static std::vector<std::string> builtinNames();

  // Camera at path time t_s (clamped to the path's span). Height is kept
  // above 1 texel. Pure.
  Camera sample(double t_s) const;
  double durationS() const;

  std::vector<Keyframe> keyframes;
  Interpolation interpolation = Interpolation::kSmooth;
};

}  // namespace clipstream
