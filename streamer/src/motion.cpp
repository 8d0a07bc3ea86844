#include "motion.h"

#include <algorithm>
#include <cmath>

namespace clipstream {
namespace {

// Camera history used to estimate velocity for the prefetch.
constexpr double kHistoryS = 0.5;
constexpr double kMinHistoryS = 0.05;
// Moves since the last frame longer than this many finest-level windows are
// teleports. (Measured on the predicted move instead, the rule took fast
// flight for teleports: x50 moves 2500 texels in prefetch_ahead_s.)
constexpr double kTeleportWindows = 2.0;

}  // namespace

double MotionPredictor::teleportTexels(double window_texels) { return kTeleportWindows * window_texels; }

void MotionPredictor::record(double time_s, const glm::dvec3& position) {
  m_history.emplace_back(time_s, position);
  while (m_history.size() > 2 && time_s - m_history.front().first > kHistoryS) m_history.pop_front();
}

std::optional<Camera> MotionPredictor::predict(const Camera& camera, double ahead_s,
                                               const std::vector<JumpLimit>& limits) {
  if (m_history.size() < 2) return std::nullopt;
  const double dt = m_history.back().first - m_history.front().first;
  if (!(dt >= kMinHistoryS)) return std::nullopt;
  const glm::dvec3 velocity = (m_history.back().second - m_history.front().second) / dt;
  const glm::dvec3 jump = m_history.back().second - m_history[m_history.size() - 2].second;
  for (const JumpLimit& l : limits) {
    const glm::dvec2 k = l.texels_per_unit;
    if (glm::length(glm::dvec2(jump.x * k.x, jump.z * k.y)) > l.limit_texels) {
      const std::pair<double, glm::dvec3> last = m_history.back();
      m_history.clear();
      m_history.push_back(last);
      return std::nullopt;
    }
  }
  Camera ahead = camera;
  ahead.position += velocity * ahead_s;
  ahead.position.y = std::max(ahead.position.y, camera.near_dist);
  return ahead;
}

}  // namespace clipstream
