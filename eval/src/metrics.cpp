// Image error and run summaries. See metrics.h and docs/accuracy.md.
#include <clipstream/eval/metrics.h>

#include <clipstream/renderer/config.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>

namespace clipstream {

FrameError compareFrames(const std::vector<uint8_t>& streamed, const std::vector<uint8_t>& reference) {
  FrameError e;
  if (streamed.size() != reference.size() || streamed.empty()) {
    e.psnr_db = 0.0;
    e.max_abs_error = 255;
    return e;
  }
  double sum = 0.0;
  int worst = 0;
  const size_t pixels = streamed.size() / 4;
  for (size_t i = 0; i < pixels; ++i)
    for (int c = 0; c < 3; ++c) {
      const int d = int(streamed[i * 4 + c]) - int(reference[i * 4 + c]);
      sum += double(d) * double(d);
      worst = std::max(worst, std::abs(d));
    }
  e.max_abs_error = worst;
  if (sum == 0.0) {
    e.psnr_db = kIdenticalPsnrDb;
  } else {
    const double mse = sum / double(pixels * 3);
    e.psnr_db = std::min(kIdenticalPsnrDb, 10.0 * std::log10(255.0 * 255.0 / mse));
  }
  return e;
}

double percentileOf(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t i = size_t(std::clamp(p, 0.0, 1.0) * double(values.size() - 1) + 0.5);
  return values[std::min(i, values.size() - 1)];
}

RunSummary summarizeRun(const std::vector<FrameRecord>& frames, uint64_t tiles_sampled,
                        uint64_t peak_rss_bytes) {
  RunSummary s;
  s.frames = uint32_t(frames.size());
  s.peak_rss_bytes = peak_rss_bytes;
  s.tiles_sampled = tiles_sampled;
  std::vector<double> ms;
  ms.reserve(frames.size());
  double psnr_sum = 0.0;
  uint64_t ram_hits = 0, ram_misses = 0, gpu_hits = 0, gpu_misses = 0;
  // Time to sharp: an open cut waits for the first sharp frame.
  bool cut_open = false;
  uint32_t cut_frame = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameRecord& f = frames[i];
    ms.push_back(f.frame_ms);
    s.bytes_read += f.bytes_read;
    s.tiles_uploaded += f.tiles_uploaded;
    s.tiles_loaded += f.tiles_loaded;
    ram_hits += f.ram_hits;
    ram_misses += f.ram_misses;
    gpu_hits += f.gpu_hits;
    gpu_misses += f.gpu_misses;
    const bool cut = f.cut;
    if (cut) {
      if (cut_open) s.time_to_sharp_frames.push_back(-1);
      cut_open = true;
      cut_frame = uint32_t(i);
    }
    if (!f.has_error) continue;
    ++s.measured_frames;
    psnr_sum += f.psnr_db;
    s.psnr_min_db = std::min(s.psnr_min_db, f.psnr_db);
    if (f.psnr_db < kDegradedPsnrDb) ++s.frames_below_30db;
    if (f.max_abs_error == 0) ++s.identical_frames;
    if (cut_open && f.psnr_db >= kSharpPsnrDb) {
      s.time_to_sharp_frames.push_back(int32_t(i - cut_frame));
      cut_open = false;
    }
  }
  if (cut_open) s.time_to_sharp_frames.push_back(-1);
  if (s.measured_frames > 0) s.psnr_mean_db = psnr_sum / double(s.measured_frames);
  uint32_t sharp = 0;
  double sharp_sum = 0.0;
  for (int32_t t : s.time_to_sharp_frames) {
    if (t < 0) {
      s.time_to_sharp_max = -1;
      continue;
    }
    ++sharp;
    sharp_sum += t;
    if (s.time_to_sharp_max >= 0) s.time_to_sharp_max = std::max(s.time_to_sharp_max, t);
  }
  if (sharp > 0) s.time_to_sharp_mean = sharp_sum / double(sharp);
  s.frame_ms_p50 = percentileOf(ms, 0.5);
  s.frame_ms_p99 = percentileOf(ms, 0.99);
  s.frame_ms_max = percentileOf(ms, 1.0);
  for (double v : ms) s.frame_ms_mean += v / double(ms.size());
  if (ram_hits + ram_misses > 0) s.ram_hit_rate = double(ram_hits) / double(ram_hits + ram_misses);
  if (gpu_hits + gpu_misses > 0) s.gpu_hit_rate = double(gpu_hits) / double(gpu_hits + gpu_misses);
  if (tiles_sampled > 0) s.over_fetch_ratio = double(s.tiles_loaded) / double(tiles_sampled);
  return s;
}

std::string RunSummary::toJson() const {
  auto finite = [](double v) { return std::isfinite(v) ? v : 0.0; };
  nlohmann::json j = {
      {"frames", frames},
      {"measured_frames", measured_frames},
      {"psnr_mean_db", finite(psnr_mean_db)},
      {"psnr_min_db", finite(psnr_min_db)},
      {"frames_below_30db", frames_below_30db},
      {"identical_frames", identical_frames},
      {"time_to_sharp_frames", time_to_sharp_frames},
      {"time_to_sharp_mean", finite(time_to_sharp_mean)},
      {"time_to_sharp_max", time_to_sharp_max},
      {"frame_ms_mean", finite(frame_ms_mean)},
      {"frame_ms_p50", finite(frame_ms_p50)},
      {"frame_ms_p99", finite(frame_ms_p99)},
      {"frame_ms_max", finite(frame_ms_max)},
      {"bytes_read", bytes_read},
      {"tiles_uploaded", tiles_uploaded},
      {"tiles_loaded", tiles_loaded},
      {"ram_hit_rate", finite(ram_hit_rate)},
      {"gpu_hit_rate", finite(gpu_hit_rate)},
      {"peak_rss_bytes", peak_rss_bytes},
      {"tiles_sampled", tiles_sampled},
      {"over_fetch_ratio", finite(over_fetch_ratio)},
      {"tiles_loaded_stack", tiles_loaded_stack},
      {"tiles_sampled_stack", tiles_sampled_stack},
      {"over_fetch_stack_ratio", finite(over_fetch_stack_ratio)},
      {"height_tiles_loaded_stack", height_tiles_loaded_stack},
      {"height_tiles_sampled_stack", height_tiles_sampled_stack},
      {"height_over_fetch_stack_ratio", finite(height_over_fetch_stack_ratio)}};
  return j.dump();
}

void sampledTiles(const PyramidGeometry& geometry, const Camera& camera, const Viewport& viewport,
                  std::unordered_set<uint64_t>* out) {
  const uint32_t tp = geometry.tile_px;
  // Consecutive texel reads mostly hit the same tile or two: remember the
  // last few so the set sees one insert per run of reads.
  uint64_t last[2] = {~uint64_t(0), ~uint64_t(0)};
  TexelFunction record = [&](uint32_t level, uint64_t x, uint64_t y, uint8_t rgba[4]) {
    const uint64_t key = packTileKey({level, uint32_t(x / tp), uint32_t(y / tp)});
    if (key != last[0] && key != last[1]) {
      out->insert(key);
      last[1] = last[0];
      last[0] = key;
    }
    rgba[0] = rgba[1] = rgba[2] = 128;
    rgba[3] = 255;
  };
  std::vector<uint8_t> ignored;
  renderReference(geometry, record, camera, viewport, ReferenceOptions{}, &ignored);
}

void sampledTilesOfPositions(const PyramidGeometry& geometry, const std::vector<float>& xyzw,
                             const Camera& camera, const Viewport& viewport,
                             std::unordered_set<uint64_t>* out) {
  const int64_t W = viewport.width_px, H = viewport.height_px;
  if (geometry.levelCount() == 0 || W == 0 || H == 0 || xyzw.size() != size_t(W * H) * 4) return;
  auto on = [&](int64_t px, int64_t py) {
    return px >= 0 && py >= 0 && px < W && py < H && xyzw[size_t(py * W + px) * 4 + 3] > 0.5f;
  };
  auto at = [&](int64_t px, int64_t py) {
    const float* p = &xyzw[size_t(py * W + px) * 4];
    return glm::dvec2(p[0], p[2]);
  };
  // The difference along one axis: the quad's pair if both are terrain,
  // else the pixel and its other neighbour; false when neither is.
  auto derivative = [&](int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t px, int64_t py,
                        int64_t sx, int64_t sy, glm::dvec2* d) {
    if (on(ax, ay) && on(bx, by)) {
      *d = at(bx, by) - at(ax, ay);
      return true;
    }
    for (int s : {-1, 1}) {
      if (on(px + s * sx, py + s * sy)) {
        *d = at(px + s * sx, py + s * sy) - at(px, py);
        return true;
      }
    }
    return false;
  };
  const uint32_t tp = geometry.tile_px;
  const double max_lod = double(geometry.levelCount() - 1);
  uint64_t last[2] = {~uint64_t(0), ~uint64_t(0)};
  auto record = [&](uint32_t level, double u0, double v0) {
    // The bilinear taps of renderReference(), clamped to the level's tiles.
    const double scale = std::ldexp(1.0, -int(level));
    const double cx = std::floor(u0 * scale - 0.5), cy = std::floor(v0 * scale - 0.5);
    const int64_t max_x = int64_t(geometry.levels[level].tiles_x) * tp - 1;
    const int64_t max_y = int64_t(geometry.levels[level].tiles_y) * tp - 1;
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const int64_t x = std::clamp<int64_t>(int64_t(cx) + i, 0, max_x);
        const int64_t y = std::clamp<int64_t>(int64_t(cy) + j, 0, max_y);
        const uint64_t key = packTileKey({level, uint32_t(x / tp), uint32_t(y / tp)});
        if (key != last[0] && key != last[1]) {
          out->insert(key);
          last[1] = last[0];
          last[0] = key;
        }
      }
  };
  for (int64_t py = 0; py < H; ++py) {
    // Quads as the GPU forms them: GL rows count from the bottom.
    const int64_t gl_row = H - 1 - py;
    const int64_t top_py = H - 1 - (gl_row & ~int64_t(1));  // the quad's first GL row
    for (int64_t px = 0; px < W; ++px) {
      if (!on(px, py)) continue;
      const int64_t qx = px & ~int64_t(1);
      glm::dvec2 gx, gy;
      const bool hx = derivative(qx, py, qx + 1, py, px, py, 1, 0, &gx);
      const bool hy = derivative(px, top_py, px, top_py - 1, px, py, 0, 1, &gy);
      if (!hx && !hy) continue;
      const double rho = std::max(hx ? glm::length(gx) : 0.0, hy ? glm::length(gy) : 0.0);
      const double lod = std::clamp(std::log2(std::max(rho, 1e-30)), 0.0, max_lod);
      const uint32_t level = uint32_t(std::floor(lod));
      const float* p = &xyzw[size_t(py * W + px) * 4];
      const double u0 = camera.position.x + double(p[0]), v0 = camera.position.z + double(p[2]);
      if (u0 < 0 || v0 < 0 || u0 >= double(geometry.width_px) || v0 >= double(geometry.height_px)) continue;
      record(level, u0, v0);
      if (lod > double(level) && level + 1 < geometry.levelCount()) record(level + 1, u0, v0);
    }
  }
}

double nearestPositionDistance(const std::vector<float>& xyzw) {
  double best = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i + 3 < xyzw.size(); i += 4) {
    if (xyzw[i + 3] <= 0.5f) continue;
    const glm::dvec3 p{xyzw[i], xyzw[i + 1], xyzw[i + 2]};
    best = std::min(best, glm::length(p));
  }
  return best;
}

uint32_t countHolePixels(const std::vector<uint8_t>& streamed, const std::vector<uint8_t>& reference) {
  static constexpr uint8_t kBlack[4] = {0, 0, 0, 255};
  auto same = [](const uint8_t* p, const uint8_t* q) { return p[0] == q[0] && p[1] == q[1] && p[2] == q[2]; };
  if (streamed.size() != reference.size()) return uint32_t(reference.size() / 4);
  uint32_t holes = 0;
  for (size_t p = 0; p + 3 < reference.size(); p += 4) {
    if (same(&reference[p], renderer_config::kSkyRgba)) continue;
    if (same(&streamed[p], renderer_config::kSkyRgba) ||
        (same(&streamed[p], kBlack) && !same(&reference[p], kBlack)))
      ++holes;
  }
  return holes;
}

uint32_t countGarbagePixels(const std::vector<uint8_t>& streamed, const PyramidGeometry& geometry,
                            const TexelFunction& texel, const Camera& camera,
                            const Viewport& viewport, int tolerance) {
  const size_t pixels = size_t(viewport.width_px) * viewport.height_px;
  if (streamed.size() != pixels * 4) return uint32_t(pixels);
  std::vector<int> best(pixels, 256);
  std::vector<uint8_t> ref;
  for (uint32_t level = 0; level < geometry.levelCount(); ++level) {
    ReferenceOptions options;
    options.min_level = level;
    renderReference(geometry, texel, camera, viewport, options, &ref);
    for (size_t p = 0; p < pixels; ++p) {
      int worst = 0;
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(int(streamed[p * 4 + c]) - int(ref[p * 4 + c])));
      best[p] = std::min(best[p], worst);
    }
  }
  uint32_t garbage = 0;
  for (int b : best)
    if (b > tolerance) ++garbage;
  return garbage;
}

double psnrRgb(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b,
               const std::vector<uint8_t>* mask) {
  if (a.size() != b.size() || a.empty()) return 0.0;
  double sum = 0.0;
  size_t count = 0;
  for (size_t i = 0; i < a.size() / 4; ++i) {
    if (mask != nullptr && (*mask)[i] == 0) continue;
    for (int c = 0; c < 3; ++c) {
      const double d = double(a[i * 4 + c]) - double(b[i * 4 + c]);
      sum += d * d;
    }
    count += 3;
  }
  if (count == 0 || sum == 0.0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(255.0 * 255.0 / (sum / double(count)));
}

}  // namespace clipstream
