// Geometric error of the terrain against its full-resolution surface: per
// pixel, how far on screen the streamed geometry shows a piece of ground
// from where the full-resolution mesh (one vertex per DEM sample) would
// show it (docs/terrain.md, "Accuracy").
//
// Thread rule: ReferenceSurface is immutable after load() and may be read
// from any thread; geometricError() is a pure function.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

// Largest DEM (level-0 samples) a ReferenceSurface holds: 64 Mi samples,
// 256 MiB of floats. Larger elevation stores are not measured.
inline constexpr uint64_t kMaxReferenceSamples = uint64_t(1) << 26;

// Level 0 of an elevation layer, whole, in memory.
class ReferenceSurface {
 public:
  // Reads every level-0 tile of `heights` (a kHeightF32 source) on the
  // calling thread. kInvalidArgument for a colour source or more than
  // kMaxReferenceSamples samples; a tile that cannot be read fails the load.
  static Status load(TileSource& heights, const LayerAlignment& alignment,
                     std::unique_ptr<ReferenceSurface>* out);

  // World height at world (x, z) on the full-resolution mesh, its cells cut
  // along the diagonal (i, j)-(i+1, j+1) as the rings cut theirs; clamped
  // to the DEM's extent.
  double heightAt(double x, double z) const;

 private:
  ReferenceSurface() = default;
  uint64_t m_width = 0, m_height = 0;
  std::vector<float> m_samples;
  LayerAlignment m_alignment;
};

struct GeometryError {
  bool measured = false;
  uint32_t pixels = 0;  // pixels showing terrain
  double mean_px = 0.0, p95_px = 0.0, max_px = 0.0;
};

// For every pixel showing terrain in `xyzw` (TerrainRenderer::
// readPositions(): camera-relative x, y, z and w = 1), the distance in
// pixels between the pixel's centre and where the ground point (x, z) at
// the full-resolution surface's height projects for this camera. A point
// behind the camera counts as the viewport's width.
GeometryError geometricError(const std::vector<float>& xyzw, const Camera& camera,
                             const Viewport& viewport, const ReferenceSurface& surface);

}  // namespace clipstream
