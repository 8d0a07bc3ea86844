// Geometric error of the terrain against its full-resolution surface: per
// pixel, how far on screen the streamed geometry shows a piece of ground
// from where the full-resolution mesh (one vertex per DEM sample) would
// show it (docs/terrain.md, "Accuracy").
//
// Thread rule: ReferenceSurface is immutable after load() and may be read
// from any thread; geometricError() and compareTerrainFrames() are pure
// functions. TerrainReference is owned by the GL thread, like
// TerrainRenderer.
#pragma once

#include <clipstream/eval/accuracy.h>
#include <clipstream/eval/metrics.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/renderer/terrain.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/tile_source.h>

#include <glm/glm.hpp>

#include <cstdint>
#include <memory>
#include <optional>
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

  uint64_t width() const { return m_width; }
  uint64_t height() const { return m_height; }
  // Level-0 heights in the store's units, row-major.
  const std::vector<float>& samples() const { return m_samples; }
  const LayerAlignment& alignment() const { return m_alignment; }

 private:
  ReferenceSurface() = default;
  uint64_t m_width = 0, m_height = 0;
  std::vector<float> m_samples;
  LayerAlignment m_alignment;
};

struct GeometryError {
  bool measured = false;
  uint32_t pixels = 0;  // pixels measured: terrain in the frame, or in the reference (coverage)
  double mean_px = 0.0, p95_px = 0.0, max_px = 0.0;
  // With the reference's positions (coverage counted):
  bool coverage = false;
  uint32_t coverage_pixels = 0;    // terrain in one of the two frames, sky or background in the other
  uint32_t silhouette_pixels = 0;  // pixels on either frame's terrain outline
  // Distance from each outline pixel to the other frame's outline.
  double silhouette_mean_px = 0.0, silhouette_p95_px = 0.0, silhouette_max_px = 0.0;
};

// For every pixel showing terrain in `xyzw` (TerrainRenderer::
// readPositions(): camera-relative x, y, z and w >= 1), the distance in
// pixels between the pixel's centre and where the ground point (x, z) at
// the full-resolution surface's height projects for this camera. A point
// behind the camera counts as the viewport's width.
//
// With `reference_xyzw` (the full-resolution mesh's positions for the same
// camera, TerrainReference::render()) coverage counts too: a pixel that
// shows terrain in one frame and sky or background in the other is
// measured by its distance to the nearest pixel showing terrain in the
// other frame (how far the outline is displaced there; at least 1; for
// terrain in this frame alone, the larger of that and its projection), and
// joins the mean, p95 and max. The silhouette figure compares the two
// outlines alone: an outline pixel shows terrain and has a 4-neighbour
// that does not (the viewport's border is no outline); each frame's
// outline pixels are measured by their distance to the other's outline.
//
// With `displacement`, also per pixel (top row first) the screen offset
// (x, y; pixels) from the pixel's centre to where its ground point lies on
// the full-resolution surface; NaN where the frame shows no terrain or the
// point is behind the camera.
GeometryError geometricError(const std::vector<float>& xyzw, const Camera& camera, const Viewport& viewport,
                             const ReferenceSurface& surface, const std::vector<float>* reference_xyzw = nullptr,
                             std::vector<glm::vec2>* displacement = nullptr);

// The geometry-only change between two frames (consecutive, from a camera
// that moved a little): the mean length of the change of displacement
// (geometricError()'s) over the pixels with one in both frames; 0 when
// none has. The full-resolution surface's displacement is 0 everywhere, so
// this is the drawn surface moving against it (a level switching pops it),
// whatever the texture does. Pure.
double displacementChange(const std::vector<glm::vec2>& a, const std::vector<glm::vec2>& b);

// The fewest triangles that model a frame's terrain within a geometric
// error target: a quadtree of small patches (kFewestPatchCells cells) whose
// nodes carry their exact error (the largest distance of the level-0
// samples under a node from its surface; both meshes are piecewise linear
// on the level-0 grid, so that is the largest distance anywhere), with no
// restriction between neighbours, every height tile resident; its error
// bound is bisected until the frame's measured p95 geometric error
// (geometricError()) is just within the target. What a method draws at
// the same p95 against this count is what it models beyond the scene's
// need (docs/terrain.md, "The fewest triangles"). Fetches synchronously:
// for measuring only. GL thread, like TerrainRenderer.
inline constexpr uint32_t kFewestPatchCells = 4;
class FewestTriangles {
 public:
  // Reads every height tile of `heights` and works out the exact node
  // errors from `surface` (its level 0).
  static Status create(const ReferenceSurface& surface, TileSource& heights,
                       std::unique_ptr<FewestTriangles>* out);
  // Triangles of the coarsest such quadtree whose frame from `camera` has
  // a p95 geometric error <= p95_px (`colour` gives the image's extent).
  // Into *triangles; kOutOfMemory / kUnavailable if the quadtree's
  // position target cannot be made.
  // With `reference_xyzw` (the reference's positions for `camera`), the
  // p95 counts coverage (geometricError()).
  [[nodiscard]] Status count(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour,
                             const ReferenceSurface& surface, double p95_px, uint64_t* triangles,
                             const std::vector<float>* reference_xyzw = nullptr);

 private:
  FewestTriangles() = default;
  struct Level {
    int64_t nodes_x = 0, nodes_y = 0;
    std::vector<float> error;
  };
  std::vector<Level> m_levels;  // index = level; the last is one node
  std::unique_ptr<TerrainRenderer> m_quadtree;
  // The last count (a camera at rest is counted once).
  std::optional<Camera> m_last_camera;
  Viewport m_last_viewport{0, 0};
  double m_last_p95 = 0.0;
  uint64_t m_last_count = 0;
};

// The reference a terrain frame is judged against: the full-resolution
// mesh (one vertex per DEM sample, TerrainConfig::full_resolution) drawn
// with the ideal texture (IdealReference with every stack level's window
// loaded, MaxTextureLOD 0), lit as the streamed terrain is. The same vertex
// shader as the rings makes every vertex of the finest ring bit-identical
// to the reference's, so at rest, where the geometry agrees, the texture
// must agree to the bit too. Fetches synchronously: for measuring only.
class TerrainReference {
 public:
  // Reads level 0 of `heights` whole (at most kMaxReferenceSamples, else
  // kInvalidArgument) and creates the colour reference for `viewport`.
  // `terrain` is the streamed terrain's configuration (its ring size is the
  // reference's patch size, its mapping the reference's).
  static Status create(std::shared_ptr<TileSource> colour, TileSource& heights,
                       const TerrainConfig& terrain, const Viewport& viewport,
                       const PlannerConfig& planner, std::unique_ptr<TerrainReference>* out);
  // Draws `camera`'s frame into its own target and reads back its colour
  // (RGBA8) and its positions (as TerrainRenderer::readPositions), top row
  // first. Leaves its own framebuffer bound.
  Status render(const Camera& camera, std::vector<uint8_t>* rgba, std::vector<float>* xyzw);
  Status resize(const Viewport& viewport);
  // Triangles the last render() drew.
  uint64_t triangles() const { return m_mesh->lastFrame().triangles; }

 private:
  TerrainReference() = default;
  Viewport m_viewport;
  std::unique_ptr<IdealReference> m_colour;
  std::unique_ptr<TerrainRenderer> m_mesh;
  std::unique_ptr<OffscreenTarget> m_target;
};

// A streamed terrain frame against its TerrainReference.
// The on-screen texel density of a frame's terrain: level-0 colour texels
// across a pixel (world units across it in x and z, the larger of its
// right and lower neighbours' distances: above 1 the colour holds more
// than the pixel shows, below 1 a texel spans several pixels), median and
// 5th percentile (the blurriest twentieth); and the same with the detail
// textures, whose texels are `detail_texels_per_texel` to a colour texel
// where the colour is magnified (below 1). Over pixels whose neighbours
// are terrain too (w >= 1 in `xyzw`, readPositions()' layout).
struct TexelDensity {
  uint32_t pixels = 0;
  double median = 0.0, p5 = 0.0;
  double detail_median = 0.0, detail_p5 = 0.0;
};
TexelDensity texelDensity(const std::vector<float>& xyzw, const Viewport& viewport, double detail_texels_per_texel);

struct TerrainFrameError {
  FrameError error;              // PSNR over the whole frame
  uint32_t agree_pixels = 0;     // pixels where the geometry agrees (compareTerrainFrames())
  uint32_t agree_mismatched = 0; // ... of them, pixels whose colour differs
  uint32_t agree_max_diff = 0;   // ... and their largest difference in a channel (0..255)
};

// Compares colour and positions of a streamed frame with the reference's
// (each `viewport`'s pixels, top row first; a size mismatch leaves the
// agreement counts 0). The geometry agrees at a pixel when all four pixels
// of its 2x2 quad (the GPU's derivative quad, which picks the texture's
// level) show the reference's world positions to the bit, outside the
// streamed rings' transition bands (w = 1: the normals are the ring's own).
TerrainFrameError compareTerrainFrames(const std::vector<uint8_t>& streamed_rgba,
                                       const std::vector<float>& streamed_xyzw,
                                       const std::vector<uint8_t>& reference_rgba,
                                       const std::vector<float>& reference_xyzw, const Viewport& viewport);

}  // namespace clipstream
