// Clip windows along a hinted camera path; see lookahead.h.
#include "lookahead.h"

#include <algorithm>
#include <cmath>

namespace clipstream {
namespace {

// Tiles without a predicted return are scored above every return time
// (seconds) and below kPyramidFirstScore.
constexpr double kNoReturnBase = 1e9;

bool neededContains(const PlanWindows& w, const TileKey& k) {
  return k.level < w.rects.size() && w.kinds[k.level] == PlanWindows::kNeeded &&
         w.rects[k.level].contains(k.x, k.y);
}

}  // namespace

bool finiteCamera(const Camera& c) {
  return std::isfinite(c.position.x) && std::isfinite(c.position.y) && std::isfinite(c.position.z) &&
         std::isfinite(c.heading_rad) && std::isfinite(c.pitch_rad) && std::isfinite(c.vfov_rad) &&
         std::isfinite(c.near_dist);
}

void PathLookahead::reset() {
  m_steps.clear();
  m_windows.clear();
  m_sampled.clear();
}

void PathLookahead::advance(const PyramidGeometry& geometry, const Viewport& viewport,
                            const PlannerConfig& planner, const PathHint& hint, double time_s) {
  if (viewport.width_px != m_viewport.width_px || viewport.height_px != m_viewport.height_px) {
    reset();
    m_viewport = viewport;
  }
  m_now_s = time_s;
  // Absurd settings fall back to the defaults instead of planning forever.
  const double step = std::isfinite(hint.step_s) && hint.step_s >= 1e-3 ? hint.step_s : PathHint{}.step_s;
  const double horizon =
      std::isfinite(hint.horizon_s) ? std::clamp(hint.horizon_s, 0.0, 3600.0) : PathHint{}.horizon_s;
  if (step != m_step_s) {
    reset();
    m_step_s = step;
  }
  // Grid indices must fit comfortably in int64 (times up to ~10^12 s).
  if (!std::isfinite(time_s) || std::abs(time_s / step) > 1e15) {
    reset();
    return;
  }
  // At most this many samples, whatever the horizon: bounds the planning
  // and the per-tile scan.
  constexpr int64_t kMaxSamples = 1024;
  const int64_t first = int64_t(std::floor(time_s / step)) + 1;
  const int64_t last = std::min(first + kMaxSamples - 1, int64_t(std::floor((time_s + horizon) / step)));
  // Drop samples now in the past; keep the rest (same grid, same poses).
  size_t keep_from = 0;
  while (keep_from < m_steps.size() && m_steps[keep_from] < first) ++keep_from;
  m_steps.erase(m_steps.begin(), m_steps.begin() + ptrdiff_t(keep_from));
  m_windows.erase(m_windows.begin(), m_windows.begin() + ptrdiff_t(keep_from));
  m_sampled.erase(m_sampled.begin(), m_sampled.begin() + ptrdiff_t(keep_from));
  if (!m_steps.empty() && m_steps.front() != first) reset();  // time went backwards or jumped
  while (!m_steps.empty() && m_steps.back() > last) {
    m_steps.pop_back();
    m_windows.pop_back();
    m_sampled.pop_back();
  }
  // The streamer's own planner settings, scope included: a return is the
  // next time the plan wants the tile, which with PlanScope::kSampled is
  // when a frame samples it, not when its window comes back over it.
  // A call plans at most this many new samples: the sampled planner takes
  // 0.2-0.4 ms a call (docs/benchmarks.md, "The planner's cost"), so a fresh
  // horizon (75 samples at the defaults) fills over five frames instead of
  // stalling one by 20-30 ms; the steady state needs a quarter of a sample a
  // frame at 60 fps.
  constexpr int64_t kMaxNewSamples = 16;
  const int64_t from = m_steps.empty() ? first : m_steps.back() + 1;
  for (int64_t k = from; k <= last && k < from + kMaxNewSamples; ++k) {
    const Camera camera = hint.camera_at(double(k) * step);
    if (!finiteCamera(camera)) break;  // the hinted path ends here for now
    ClipmapPlan plan = planClipmap(geometry, viewport, camera, planner);
    std::vector<SampledMask> masks(plan.stack.size());
    for (size_t l = 0; l < plan.stack.size(); ++l)
      if (!plan.stack[l].sampled.empty())
        masks[l] = std::make_shared<const std::vector<uint8_t>>(std::move(plan.stack[l].sampled));
    m_steps.push_back(k);
    m_windows.push_back(planWindows(plan));
    m_sampled.push_back(std::move(masks));
    ++m_planner_calls;
  }
}

std::shared_ptr<const LookaheadSnapshot> PathLookahead::snapshot() const {
  auto s = std::make_shared<LookaheadSnapshot>();
  s->now_s = m_now_s;
  s->times_s.reserve(m_steps.size());
  for (int64_t k : m_steps) s->times_s.push_back(double(k) * m_step_s);
  s->index(m_windows, m_sampled);
  return s;
}

void LookaheadSnapshot::index(const std::vector<PlanWindows>& windows,
                              const std::vector<std::vector<SampledMask>>& sampled) {
  runs.clear();
  auto sameMask = [](const SampledMask& a, const SampledMask& b) {
    return a == b || (a && b && *a == *b);
  };
  for (size_t j = 0; j < windows.size(); ++j) {
    const PlanWindows& w = windows[j];
    if (runs.size() < w.rects.size()) runs.resize(w.rects.size());
    for (size_t l = 0; l < runs.size(); ++l) {
      const bool needed = l < w.rects.size() && w.kinds[l] == PlanWindows::kNeeded;
      const TileRect rect = needed ? w.rects[l] : TileRect{};
      const bool has_mask = needed && j < sampled.size() && l < sampled[j].size();
      const SampledMask mask = has_mask ? sampled[j][l] : nullptr;
      if (runs[l].empty() || runs[l].back().rect != rect || !sameMask(runs[l].back().sampled, mask))
        runs[l].push_back({times_s[j], rect, mask});
    }
  }
}

double predictedReturnS(const TileKey& key, const PlanWindows& current, bool on_gpu,
                        const LookaheadSnapshot& ahead) {
  if (key.level >= ahead.runs.size()) return kNoReturn;
  const std::vector<LookaheadSnapshot::Run>& runs = ahead.runs[key.level];
  const size_t n = runs.size();
  size_t j = 0;
  if (on_gpu && neededContains(current, key))
    while (j < n && runs[j].rect.contains(key.x, key.y)) ++j;  // the GPU keeps it until it leaves
  for (; j < n; ++j)
    if (runs[j].wants(key.x, key.y)) return runs[j].t_s - ahead.now_s;
  return kNoReturn;
}

double evictionScoreAhead(const TileKey& key, const PlanWindows& current, const PlanWindows& predicted,
                          EvictionMode mode, bool on_gpu, const LookaheadSnapshot* ahead) {
  const double score = evictionScore(key, current, predicted, mode, on_gpu);
  if (!ahead || ahead->times_s.empty() || mode != EvictionMode::kGpuFirst || score >= kPyramidFirstScore)
    return score;
  const double back = predictedReturnS(key, current, on_gpu, *ahead);
  return back == kNoReturn ? kNoReturnBase + score : back;
}

}  // namespace clipstream
