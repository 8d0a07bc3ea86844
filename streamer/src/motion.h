// The camera's motion for prefetch: its velocity from the last half second
// of positions, and where it will be a moment ahead at that velocity, unless
// the last move was a jump (a teleport), which is not motion.
//
// Render thread only (the streamer's update()); no lock, no I/O.
#pragma once

#include <clipstream/streamer/camera.h>

#include <glm/glm.hpp>

#include <deque>
#include <optional>
#include <utility>
#include <vector>

namespace clipstream {

class MotionPredictor {
 public:
  // How far a move may go, in one layer's texels, before it is a teleport:
  // `limit_texels` along the ground in that layer, whose texels per world
  // unit are `texels_per_unit`.
  struct JumpLimit {
    glm::dvec2 texels_per_unit{1.0, 1.0};
    double limit_texels = 0.0;
  };

  // Records the camera position at time_s (every frame, prefetch or not).
  void record(double time_s, const glm::dvec3& position);
  // The camera ahead_s from now at the recorded velocity, keeping its
  // orientation and staying above its near plane; nullopt when the history
  // spans too short a time, or when the last move exceeds a JumpLimit of any
  // layer (the history is then forgotten, so no path nobody flies is
  // prefetched).
  std::optional<Camera> predict(const Camera& camera, double ahead_s, const std::vector<JumpLimit>& limits);
  // The threshold of a JumpLimit: this many windows of the finest needed level.
  static double teleportTexels(double window_texels);

  size_t historySize() const { return m_history.size(); }

 private:
  std::deque<std::pair<double, glm::dvec3>> m_history;  // (time_s, position), oldest first
};

}  // namespace clipstream
