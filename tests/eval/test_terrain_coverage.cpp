// The geometric error counts coverage: a pixel that shows terrain in one
// frame and sky in the other (at silhouettes and the DEM's edges) is an
// error the per-pixel projection alone cannot see, since ground jutting
// past the DEM's edge still lies on the (clamped) surface. No GL: the
// frames' positions come from rays marched to the surface on the CPU.
#include "test_helpers.h"

#include <clipstream/eval/terrain_accuracy.h>
#include <clipstream/testing/synthetic_store.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>

namespace clipstream {
namespace {

constexpr uint64_t kSide = 256;
constexpr double kSpacing = 4.0;  // world units a sample; sample 0 at 2

float hills(uint64_t x, uint64_t y) {
  return float(100.0 + 50.0 * std::sin(double(x) * 0.05) * std::cos(double(y) * 0.04));
}

class TerrainCoverage : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(test::writeElevationStore(m_dir.file("dem.cst"), kSide, kSide, hills).ok());
    Status s;
    auto heights = openElevationSource(m_dir.file("dem.cst"), &s);
    ASSERT_TRUE(heights) << s.toString();
    LayerAlignment a;
    a.world_per_sample = {kSpacing, kSpacing};
    a.sample0_world = {2.0, 2.0};
    a.world_per_height = 1.0;
    ASSERT_TRUE(ReferenceSurface::load(*heights, a, &m_surface).ok());
    // Above the DEM's middle, looking along -z at its far edge (z = 2)
    // with the sky beyond it.
    m_camera.position = {512.0, 300.0, 300.0};
    m_camera.heading_rad = 0.0;
    m_camera.pitch_rad = -0.4;
  }

  // Each pixel's ray marched to the surface where `inside(x, z)` holds (the
  // ground drawn there; elsewhere none, as clip planes leave it), as a
  // renderer of that ground would read its positions back; with `lift`, to
  // the surface raised by as much.
  std::vector<float> positions(const std::function<bool(double, double)>& inside, double lift = 0.0) const {
    std::vector<float> xyzw(size_t(m_vp.width_px) * m_vp.height_px * 4, 0.0f);
    const double tan_half = std::tan(m_camera.vfov_rad * 0.5);
    const double aspect = double(m_vp.width_px) / m_vp.height_px;
    for (uint32_t py = 0; py < m_vp.height_px; ++py)
      for (uint32_t px = 0; px < m_vp.width_px; ++px) {
        const double nx = 2.0 * (px + 0.5) / m_vp.width_px - 1.0, ny = 1.0 - 2.0 * (py + 0.5) / m_vp.height_px;
        const glm::dvec3 d = glm::normalize(m_camera.forward() + m_camera.right() * (nx * tan_half * aspect) +
                                            m_camera.up() * (ny * tan_half));
        auto below = [&](double t) {
          const glm::dvec3 p = m_camera.position + d * t;
          return inside(p.x, p.z) && p.y <= m_surface->heightAt(p.x, p.z) + lift;
        };
        double t0 = 0.0, t1 = 0.0;
        for (double t = 1.0; t < 4000.0; t += 0.5) {  // march, then bisect
          if (below(t)) {
            t0 = t - 0.5, t1 = t;
            break;
          }
        }
        if (t1 == 0.0) continue;
        for (int k = 0; k < 60; ++k) {
          const double t = 0.5 * (t0 + t1);
          (below(t) ? t1 : t0) = t;
        }
        const glm::dvec3 rel = d * t1;
        float* o = xyzw.data() + (size_t(py) * m_vp.width_px + px) * 4;
        o[0] = float(rel.x), o[1] = float(rel.y), o[2] = float(rel.z), o[3] = 1.0f;
      }
    return xyzw;
  }

  // The DEM's extent with its far edge (z = 2) moved to z = far_z.
  static bool within(double x, double z, double far_z) {
    const double hi = 2.0 + kSpacing * double(kSide - 1);
    return x >= 2.0 && x <= hi && z >= far_z && z <= hi;
  }
  static bool onDem(double x, double z) { return within(x, z, 2.0); }
  // A saw-tooth of `amplitude` world units and a 64-unit period.
  static double tooth(double x, double amplitude) {
    const double u = std::fmod(x, 64.0) / 64.0;
    return amplitude * (u < 0.5 ? 2.0 * u : 2.0 - 2.0 * u);
  }

  test::TempDir m_dir;
  std::unique_ptr<ReferenceSurface> m_surface;
  Camera m_camera;
  Viewport m_vp{160, 96};
};

TEST_F(TerrainCoverage, TheSameOutlineHasNoCoverageError) {
  const std::vector<float> frame = positions(onDem);
  const GeometryError e = geometricError(frame, m_camera, m_vp, *m_surface, &frame);
  ASSERT_TRUE(e.measured && e.coverage);
  ASSERT_GT(e.silhouette_pixels, m_vp.width_px);  // the far edge is on screen, against the sky
  EXPECT_EQ(e.coverage_pixels, 0u);
  EXPECT_EQ(e.silhouette_max_px, 0.0);
  EXPECT_LT(e.max_px, 0.05);
}

TEST_F(TerrainCoverage, ASawToothedEdgeFailsTheMeasure) {
  const std::vector<float> reference = positions(onDem);
  // Ground jutting up to 6 samples past the far edge in teeth: every
  // point of it lies on the surface clamped to the edge.
  const std::vector<float> sawtooth =
      positions([](double x, double z) { return within(x, z, 2.0 - tooth(x, 6.0 * kSpacing)); });
  const GeometryError alone = geometricError(sawtooth, m_camera, m_vp, *m_surface);
  EXPECT_FALSE(alone.coverage);
  EXPECT_LT(alone.max_px, 0.05) << "the projection alone sees no error";
  const GeometryError e = geometricError(sawtooth, m_camera, m_vp, *m_surface, &reference);
  ASSERT_TRUE(e.coverage);
  EXPECT_GT(e.coverage_pixels, m_vp.width_px / 2);
  // The teeth are a few percent of the ground pixels: the frame's p95
  // barely moves, its mean and max do, and the silhouette figure fails.
  EXPECT_GT(e.mean_px, alone.mean_px + 0.02);
  EXPECT_GT(e.max_px, 2.0);
  EXPECT_GT(e.silhouette_mean_px, 1.0);
  EXPECT_GT(e.silhouette_p95_px, 2.0);
  EXPECT_GE(e.silhouette_max_px, e.silhouette_p95_px);
  EXPECT_GE(e.pixels, alone.pixels);
}

TEST_F(TerrainCoverage, MissingGroundCountsToo) {
  const std::vector<float> reference = positions(onDem);
  // The far edge eaten in teeth up to 6 samples deep: pixels that are
  // ground in the reference alone.
  const std::vector<float> eaten =
      positions([](double x, double z) { return within(x, z, 2.0 + tooth(x, 6.0 * kSpacing)); });
  const GeometryError alone = geometricError(eaten, m_camera, m_vp, *m_surface);
  EXPECT_LT(alone.max_px, 0.05);
  const GeometryError e = geometricError(eaten, m_camera, m_vp, *m_surface, &reference);
  EXPECT_GT(e.coverage_pixels, m_vp.width_px / 2);
  EXPECT_EQ(e.pixels, alone.pixels + e.coverage_pixels);
  EXPECT_GT(e.max_px, 2.0);
  EXPECT_GT(e.silhouette_mean_px, 1.0);
  EXPECT_GT(e.silhouette_p95_px, 2.0);
}

// The geometry-only change: none between a frame and itself, some where
// the surface drawn rises (a level switching under a camera at rest).
TEST_F(TerrainCoverage, DisplacementChangeSeesTheSurfaceMove) {
  const std::vector<float> on = positions(onDem);
  const std::vector<float> lifted = positions(onDem, 5.0);  // the surface drawn 5 units higher
  std::vector<glm::vec2> a, a2, b;
  const GeometryError ea = geometricError(on, m_camera, m_vp, *m_surface, nullptr, &a);
  geometricError(on, m_camera, m_vp, *m_surface, nullptr, &a2);
  const GeometryError eb = geometricError(lifted, m_camera, m_vp, *m_surface, nullptr, &b);
  ASSERT_EQ(a.size(), size_t(m_vp.width_px) * m_vp.height_px);
  size_t shown = 0;
  for (const glm::vec2& d : a) shown += !std::isnan(d.x);
  EXPECT_EQ(shown, ea.pixels);
  EXPECT_EQ(displacementChange(a, a2), 0.0);
  const double moved = displacementChange(a, b);
  EXPECT_GT(moved, 0.5);
  EXPECT_NEAR(moved, eb.mean_px, 0.05 + 0.05 * eb.mean_px);  // from ~0 to the lifted frame's error
  EXPECT_EQ(displacementChange(a, {}), 0.0);
}

// The silhouette figure against a brute-force search, on random blobs (the
// distances are exact: the transform is).
TEST_F(TerrainCoverage, SilhouetteDistancesAreExact) {
  const Viewport vp{41, 29};
  const size_t pixels = size_t(vp.width_px) * vp.height_px;
  uint32_t seed = 12345;
  auto next = [&seed](uint32_t n) {
    seed = seed * 1664525u + 1013904223u;
    return (seed >> 8) % n;
  };
  for (int round = 0; round < 20; ++round) {
    std::vector<uint8_t> mask[2];
    std::vector<float> xyzw[2];
    for (int k = 0; k < 2; ++k) {
      mask[k].assign(pixels, 0);
      for (int r = 0; r < 3; ++r) {  // a union of rectangles
        const uint32_t x0 = next(vp.width_px), y0 = next(vp.height_px);
        const uint32_t x1 = std::min(vp.width_px, x0 + 1 + next(20)), y1 = std::min(vp.height_px, y0 + 1 + next(15));
        for (uint32_t y = y0; y < y1; ++y)
          for (uint32_t x = x0; x < x1; ++x) mask[k][size_t(y) * vp.width_px + x] = 1;
      }
      xyzw[k].assign(pixels * 4, 0.0f);
      for (size_t p = 0; p < pixels; ++p)
        if (mask[k][p]) xyzw[k][p * 4 + 1] = -100.0f, xyzw[k][p * 4 + 3] = 1.0f;
    }
    auto outline = [&](int k, uint32_t x, uint32_t y) {
      auto at = [&](int64_t i, int64_t j) {
        return i < 0 || j < 0 || i >= int64_t(vp.width_px) || j >= int64_t(vp.height_px) ||
               mask[k][size_t(j) * vp.width_px + size_t(i)];
      };
      return mask[k][size_t(y) * vp.width_px + x] && !(at(x - 1, y) && at(x + 1, y) && at(x, y - 1) && at(x, y + 1));
    };
    double sum = 0.0, max = 0.0;
    uint32_t count = 0;
    for (int k = 0; k < 2; ++k)
      for (uint32_t y = 0; y < vp.height_px; ++y)
        for (uint32_t x = 0; x < vp.width_px; ++x) {
          if (!outline(k, x, y)) continue;
          double best = 1e30;
          for (uint32_t j = 0; j < vp.height_px; ++j)
            for (uint32_t i = 0; i < vp.width_px; ++i)
              if (outline(1 - k, i, j)) best = std::min(best, std::hypot(double(i) - x, double(j) - y));
          if (best > 1e29) best = std::hypot(double(vp.width_px), double(vp.height_px));
          sum += best, max = std::max(max, best), ++count;
        }
    const GeometryError e = geometricError(xyzw[0], m_camera, vp, *m_surface, &xyzw[1]);
    ASSERT_EQ(e.silhouette_pixels, count) << round;
    if (count == 0) continue;
    EXPECT_NEAR(e.silhouette_mean_px, sum / count, 1e-9) << round;
    EXPECT_NEAR(e.silhouette_max_px, max, 1e-9) << round;
  }
}

}  // namespace
}  // namespace clipstream
