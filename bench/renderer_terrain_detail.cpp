// What the terrain's detail beyond the data costs a frame (docs/terrain.md,
// "Detail beyond the data"): the frame lit by vertex (none of it), lit by
// pixel, and lit by vertex with the detail textures, drawn by one renderer
// from the same cameras (TerrainRenderer::setLighting(),
// setDetailTextures()), and the frame over synthesized relief (a second
// renderer over synthesizeRelief() of the DEM: 2 levels, or 1 where a stack
// holding every tile of 2 would pass kMaxReliefStackBytes), the four
// alternated draw by draw so the machine's load falls on all alike. Per DEM
// and method (the clipmap at its default ring, the quadtree at its default
// bound and budget): the triangles, the frame (draws and glFinish; mean over
// the cameras of each one's best of --repeat) of each and its ratio to the
// plain one, and the video memory the height gradients add to the height
// stack.
//
//   bench_renderer_terrain_detail [--size 1280x720] [--cameras 24] [--repeat 3] [--tsv FILE] DEM...
// DEM: an elevation store (clipstream-tile DEM.tif), or a GeoTIFF DEM, tiled
// first into a temporary store. Stretched under a 2048^2 white image, every
// height tile resident.
#include <clipstream/cli/sizes.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/terrain.h>

#include "gl.h"
#include "terrain_scene.h"
#include "tsv_out.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

using namespace clipstream;

namespace {

// The largest height stack (every tile of every level) the relief column
// makes: 2 synthesized levels over a 1201^2 DEM would take 1.2 GiB.
constexpr uint64_t kMaxReliefStackBytes = uint64_t(512) << 20;

double drawMs(TerrainRenderer& terrain, const Camera& camera, const Viewport& vp, const ClipmapRenderer& colour,
              const OffscreenTarget& target) {
  target.bind();
  ClipmapRenderer::clearSky();
  const auto start = std::chrono::steady_clock::now();
  terrain.draw(camera, vp, colour);
  glFinish();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// One DEM, one method: the lighting table's row (see the top).
bool lightingCost(const TerrainLayerConfig& layer, TerrainMethod method, const ClipmapRenderer& colour,
                  const OffscreenTarget& target, const Viewport& vp, int camera_count, int repeat,
                  const std::string& name, bench::TsvOut* table) {
  const PyramidGeometry& g = layer.source->geometry();
  std::shared_ptr<const TerrainBounds> bounds;
  (void)loadTerrainBounds(*layer.source, kTerrainBoundsMaxLevelTiles, &bounds);
  TerrainConfig tc;
  tc.method = method;
  tc.mapping = layer.alignment;
  // The memory at the streamer's window (as a flight's stack); the frames
  // from a stack that holds every tile.
  tc.clip_tiles = TerrainRenderer::windowTiles(tc.ring_cells, g.tile_px);
  std::unique_ptr<TerrainRenderer> terrain;
  Status s = TerrainRenderer::create(g, tc, &terrain);
  const uint64_t vertex_bytes = s ? terrain->textureBytes() : 0;
  if (s) s = terrain->setLighting(TerrainLighting::kPixel);
  const uint64_t pixel_bytes = s ? terrain->textureBytes() : 0;
  tc.clip_tiles = std::max(g.levels[0].tiles_x, g.levels[0].tiles_y);
  tc.lighting = TerrainLighting::kPixel;
  if (s) s = TerrainRenderer::create(g, tc, &terrain);
  if (!s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return false;
  }
  terrain->setBounds(bounds);
  bench::uploadAll(*terrain, *layer.source);
  // The same DEM under synthesized relief, every tile in the stack.
  TerrainLayerConfig relief_layer = layer;
  uint32_t relief_levels = 0;
  for (uint32_t levels : {2u, 1u}) {
    TerrainLayerConfig candidate = layer;
    if (!synthesizeRelief(levels, &candidate).ok()) continue;
    const PyramidGeometry& rg = candidate.source->geometry();
    const uint64_t side = uint64_t(std::max(rg.levels[0].tiles_x, rg.levels[0].tiles_y)) * rg.tile_px;
    if (side * side * 4 * rg.levelCount() > kMaxReliefStackBytes) continue;
    relief_layer = candidate;
    relief_levels = levels;
    break;
  }
  std::unique_ptr<TerrainRenderer> relief;
  if (relief_levels > 0) {
    const PyramidGeometry& rg = relief_layer.source->geometry();
    TerrainConfig rc = tc;
    rc.lighting = TerrainLighting::kVertex;
    rc.mapping = relief_layer.alignment;
    rc.clip_tiles = std::max(rg.levels[0].tiles_x, rg.levels[0].tiles_y);
    if (Status st = TerrainRenderer::create(rg, rc, &relief); !st) {
      std::fprintf(stderr, "%s\n", st.toString().c_str());
      return false;
    }
    std::shared_ptr<const TerrainBounds> relief_bounds;
    (void)loadTerrainBounds(*relief_layer.source, kTerrainBoundsMaxLevelTiles, &relief_bounds);
    relief->setBounds(relief_bounds);
    bench::uploadAll(*relief, *relief_layer.source);
  }
  // Plain (lit by vertex), lit by pixel, lit by vertex with the detail
  // textures, over synthesized relief.
  double ms[4] = {0, 0, 0, 0}, triangles = 0, relief_triangles = 0;
  int counted = 0;
  for (const Camera& camera : bench::cameras(*terrain, layer, camera_count)) {
    double best[4] = {INFINITY, INFINITY, INFINITY, INFINITY};
    for (int r = 0; r < repeat; ++r)
      for (int k = 0; k < (relief ? 4 : 3); ++k) {
        if (k == 3) {
          best[k] = std::min(best[k], drawMs(*relief, camera, vp, colour, target));
          continue;
        }
        (void)terrain->setLighting(k == 1 ? TerrainLighting::kPixel : TerrainLighting::kVertex);
        (void)terrain->setDetailTextures(k == 2);
        best[k] = std::min(best[k], drawMs(*terrain, camera, vp, colour, target));
      }
    if (terrain->lastFrame().triangles == 0) continue;
    for (int k = 0; k < 4; ++k) ms[k] += relief || k < 3 ? best[k] : 0.0;
    triangles += double(terrain->lastFrame().triangles);
    if (relief) relief_triangles += double(relief->lastFrame().triangles);
    ++counted;
  }
  if (counted == 0) return false;
  const double n = counted;
  table->row("%s\t%s\t%d\t%.0f\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%.1f\t%u\t%.0f\t%.2f\t%.2f\n", name.c_str(),
             terrainMethodName(method), counted, triangles / n, ms[0] / n, ms[1] / n, ms[1] / ms[0], ms[2] / n,
             ms[2] / ms[0], double(pixel_bytes - vertex_bytes) / double(1 << 20), relief_levels,
             relief_triangles / n, ms[3] / n, ms[3] / ms[0]);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  Viewport vp{1280, 720};
  int camera_count = 24, repeat = 3;
  std::vector<std::string> dems;
  for (int i = 1; i < argc; ++i) {
    const bool value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--size") && value) {
      if (!cli::parseSize(argv[++i], &vp.width_px, &vp.height_px).ok()) return 2;
    } else if (!std::strcmp(argv[i], "--cameras") && value) {
      camera_count = std::max(1, std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--repeat") && value) {
      repeat = std::max(1, std::atoi(argv[++i]));
    } else if (argv[i][0] == '-') {
      std::fprintf(stderr, "unknown option %s\n", argv[i]);
      return 2;
    } else {
      dems.push_back(argv[i]);
    }
  }
  if (dems.empty()) {
    std::fprintf(stderr, "usage: %s [--size WxH] [--cameras N] [--repeat N] [--tsv FILE] DEM...\n", argv[0]);
    return 2;
  }
  bench::WhiteGround ground;
  if (!ground.create(vp)) return 1;
  std::printf("# %s, %ux%u, %d cameras, best of %d draws each; plain, lit by pixel, with detail textures, alternated\n",
              ground.context->describe().c_str(), vp.width_px, vp.height_px, camera_count, repeat);
  table.row("dem\tmethod\tcameras\ttriangles\tplain_frame_ms\tpixel_lit_frame_ms\tpixel_lit_ratio\t"
            "detail_frame_ms\tdetail_ratio\tgradients_mib\trelief_levels\trelief_triangles\trelief_frame_ms\t"
            "relief_ratio\n");
  int status = 0;
  for (size_t i = 0; i < dems.size(); ++i) {
    const std::string store = bench::storeFor(
        dems[i], "/tmp/bench_terrain_detail." + std::to_string(::getpid()) + "." + std::to_string(i) + ".cst");
    if (store.empty()) return 1;
    TerrainLayerConfig layer;
    std::vector<std::string> notes;
    if (Status s = openTerrainLayer("", ground.source->geometry(), store, 1.0, true,
                                    renderer_config::kTerrainRingCells, &layer, &notes);
        !s) {
      std::fprintf(stderr, "%s: %s\n", dems[i].c_str(), s.toString().c_str());
      status = 1;
    } else {
      const std::string name = dems[i].substr(dems[i].find_last_of('/') + 1);
      for (TerrainMethod m : {TerrainMethod::kClipmap, TerrainMethod::kQuadtree})
        if (!lightingCost(layer, m, *ground.colour, *ground.target, vp, camera_count, repeat, name, &table))
          status = 1;
    }
    if (store != dems[i]) std::remove(store.c_str());
  }
  return table.commit() && status == 0 ? 0 : 1;
}
