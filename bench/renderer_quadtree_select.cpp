// What the quadtree terrain's node selection costs (terrain_quadtree.cpp,
// the reference selection): the former one (depth first, the restriction by a
// full scan of the leaves after each mend; setReferenceSelection()) against
// today's (largest error first, the restriction's worklist), without a
// triangle budget and with the default one, from random cameras over each
// DEM with every height tile resident. Per DEM, bound and selection: the
// leaves drawn, forced splits and triangles (means), the selection's time
// (mean and largest of each camera's best of --repeat draws), the frame's
// (selection, draws and glFinish; mean of the best) and the bound met.
// Then what a frame's draws cost: the quadtree with patches of 8, 16 and 32
// cells (about the same triangles in 4x as many nodes, or a quarter) and
// the clipmap's rings, over the same cameras without a budget; the
// least-squares fit of frame ms = a + b nodes + c kilotriangles says what
// a node (an instance of the patch mesh: the quadtree draws one call per
// edge pattern) and a thousand triangles cost on this GL.
//
//   bench_renderer_quadtree_select [--size 1280x720] [--cameras 24] [--repeat 3]
//                                  [--errors 4,10] [--tsv FILE] DEM...
// DEM: an elevation store (clipstream-tile DEM.tif), or a GeoTIFF DEM, tiled
// first into a temporary store. Stretched under a 2048^2 white image.
#include <clipstream/cli/sizes.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/terrain.h>
#include <clipstream/tiler/tiler.h>

#include "gl.h"
#include "terrain_impl.h"
#include "terrain_scene.h"
#include "tsv_out.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace clipstream;
using clipstream::bench::cameras;
using clipstream::bench::storeFor;
using clipstream::bench::uploadAll;

namespace {

// The selections compared.
struct Mode {
  const char* name;
  bool reference;
  uint64_t budget;
};
const Mode kModes[] = {{"before (rescan)", true, 0},
                       {"worklist", false, 0},
                       {"worklist + budget", false, renderer_config::kTerrainTriangleBudget}};

struct Row {
  double leaves = 0, forced = 0, triangles = 0, select_ms = 0, select_max_ms = 0, frame_ms = 0, bound_px = 0;
};

// One DEM at one bound: every mode over the same cameras, alternated.
void measure(const TerrainLayerConfig& layer, const ClipmapRenderer& colour, const OffscreenTarget& target,
             const Viewport& vp, double error_px, int camera_count, int repeat, Row rows[3]) {
  std::shared_ptr<const TerrainBounds> bounds;
  (void)loadTerrainBounds(*layer.source, kTerrainBoundsMaxLevelTiles, &bounds);
  std::unique_ptr<TerrainRenderer> terrain[3];
  for (int m = 0; m < 3; ++m) {
    TerrainConfig tc;
    tc.method = TerrainMethod::kQuadtree;
    tc.mapping = layer.alignment;
    tc.error_px = error_px;
    tc.triangle_budget = kModes[m].budget;
    const PyramidGeometry& g = layer.source->geometry();
    tc.clip_tiles = std::max(g.levels[0].tiles_x, g.levels[0].tiles_y);
    if (Status s = TerrainRenderer::create(g, tc, &terrain[m]); !s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return;
    }
    terrain[m]->setBounds(bounds);
    terrain[m]->impl().setReferenceSelection(kModes[m].reference);
    uploadAll(*terrain[m], *layer.source);
  }
  const std::vector<Camera> views = cameras(*terrain[1], layer, camera_count);
  for (const Camera& camera : views) {
    for (int m = 0; m < 3; ++m) {
      double select = INFINITY, frame = INFINITY;
      for (int r = 0; r < repeat; ++r) {
        target.bind();
        ClipmapRenderer::clearSky();
        const auto start = std::chrono::steady_clock::now();
        terrain[m]->draw(camera, vp, colour);
        glFinish();
        frame = std::min(frame, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
        select = std::min(select, terrain[m]->lastFrame().select_ms);
      }
      const TerrainFrame& f = terrain[m]->lastFrame();
      Row& row = rows[m];
      row.leaves += f.nodes;
      row.forced += f.forced_splits;
      row.triangles += double(f.triangles);
      row.select_ms += select;
      row.select_max_ms = std::max(row.select_max_ms, select);
      row.frame_ms += frame;
      row.bound_px += f.achieved_error_px > 0 ? f.achieved_error_px : error_px;
    }
  }
  for (int m = 0; m < 3; ++m) {
    const double n = double(views.size());
    rows[m].leaves /= n, rows[m].forced /= n, rows[m].triangles /= n;
    rows[m].select_ms /= n, rows[m].frame_ms /= n, rows[m].bound_px /= n;
  }
}

// The frame (draws and glFinish; best of `repeat`) of `terrain` from each
// camera, summed into *ms, *draws and *triangles.
void frameCost(TerrainRenderer& terrain, const ClipmapRenderer& colour, const OffscreenTarget& target,
               const Viewport& vp, const std::vector<Camera>& views, int repeat, double* ms, double* draws,
               double* triangles, std::vector<std::array<double, 3>>* samples) {
  for (const Camera& camera : views) {
    double best = INFINITY;
    for (int r = 0; r < repeat; ++r) {
      target.bind();
      ClipmapRenderer::clearSky();
      const auto start = std::chrono::steady_clock::now();
      terrain.draw(camera, vp, colour);
      glFinish();
      best = std::min(best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    }
    const TerrainFrame& f = terrain.lastFrame();
    *ms += best;
    *draws += f.blocks;
    *triangles += double(f.triangles);
    samples->push_back({best, double(f.blocks), double(f.triangles) / 1000.0});
  }
}

// Least squares of y = a + b x1 + c x2 over `samples` (y, x1, x2).
std::array<double, 3> fit(const std::vector<std::array<double, 3>>& samples) {
  double m[3][4] = {};
  for (const auto& s : samples) {
    const double x[3] = {1.0, s[1], s[2]};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) m[i][j] += x[i] * x[j];
      m[i][3] += x[i] * s[0];
    }
  }
  for (int i = 0; i < 3; ++i)  // Gauss-Jordan, partial pivoting
    for (int p = i + 1; p < 3; ++p)
      if (std::abs(m[p][i]) > std::abs(m[i][i]))
        for (int j = 0; j < 4; ++j) std::swap(m[i][j], m[p][j]);
  for (int i = 0; i < 3; ++i) {
    if (std::abs(m[i][i]) < 1e-12) return {NAN, NAN, NAN};
    for (int r = 0; r < 3; ++r) {
      if (r == i) continue;
      const double f = m[r][i] / m[i][i];
      for (int j = 0; j < 4; ++j) m[r][j] -= f * m[i][j];
    }
  }
  return {m[0][3] / m[0][0], m[1][3] / m[1][1], m[2][3] / m[2][2]};
}

// The draw-cost table of one DEM (see the top).
void drawCost(const TerrainLayerConfig& layer, const ClipmapRenderer& colour, const OffscreenTarget& target,
              const Viewport& vp, int camera_count, int repeat, const std::string& name, bench::TsvOut* table) {
  std::shared_ptr<const TerrainBounds> bounds;
  (void)loadTerrainBounds(*layer.source, kTerrainBoundsMaxLevelTiles, &bounds);
  const PyramidGeometry& g = layer.source->geometry();
  struct Setting {
    const char* name;
    TerrainMethod method;
    uint32_t patch, ring;
  };
  const Setting settings[] = {{"quadtree, 8-cell patches", TerrainMethod::kQuadtree, 8, 128},
                              {"quadtree, 16-cell patches", TerrainMethod::kQuadtree, 16, 128},
                              {"quadtree, 32-cell patches", TerrainMethod::kQuadtree, 32, 128},
                              {"clipmap, ring 128", TerrainMethod::kClipmap, 16, 128}};
  std::vector<Camera> views;
  std::vector<std::array<double, 3>> quadtree_samples;
  for (const Setting& st : settings) {
    TerrainConfig tc;
    tc.method = st.method;
    tc.patch_cells = st.patch;
    tc.ring_cells = st.ring;
    tc.mapping = layer.alignment;
    tc.triangle_budget = 0;
    tc.clip_tiles = std::max(g.levels[0].tiles_x, g.levels[0].tiles_y);
    std::unique_ptr<TerrainRenderer> terrain;
    if (!TerrainRenderer::create(g, tc, &terrain).ok()) return;
    terrain->setBounds(bounds);
    uploadAll(*terrain, *layer.source);
    if (views.empty()) views = cameras(*terrain, layer, camera_count);
    double ms = 0, draws = 0, triangles = 0;
    std::vector<std::array<double, 3>> samples;
    frameCost(*terrain, colour, target, vp, views, repeat, &ms, &draws, &triangles, &samples);
    if (st.method == TerrainMethod::kQuadtree)
      quadtree_samples.insert(quadtree_samples.end(), samples.begin(), samples.end());
    const double n = double(views.size());
    table->row("%s\t%s\t%.0f\t%.0f\t%.1f\n", name.c_str(), st.name, draws / n, triangles / n, ms / n);
  }
  const std::array<double, 3> c = fit(quadtree_samples);
  table->row("%s\tquadtree fit: ms = a + b nodes + c ktriangles\ta=%.2f\tb=%.4f\tc=%.3f\n", name.c_str(), c[0], c[1], c[2]);
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  Viewport vp{1280, 720};
  int camera_count = 24, repeat = 3;
  std::vector<double> errors = {4.0, 10.0};
  std::vector<std::string> dems;
  for (int i = 1; i < argc; ++i) {
    const bool value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--size") && value) {
      if (!cli::parseSize(argv[++i], &vp.width_px, &vp.height_px).ok()) return 2;
    } else if (!std::strcmp(argv[i], "--cameras") && value) {
      camera_count = std::max(1, std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--repeat") && value) {
      repeat = std::max(1, std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--errors") && value) {
      errors.clear();
      std::stringstream list(argv[++i]);
      for (std::string e; std::getline(list, e, ',');) errors.push_back(std::atof(e.c_str()));
    } else if (argv[i][0] == '-') {
      std::fprintf(stderr, "unknown option %s\n", argv[i]);
      return 2;
    } else {
      dems.push_back(argv[i]);
    }
  }
  if (dems.empty()) {
    std::fprintf(stderr, "usage: %s [--size WxH] [--cameras N] [--repeat N] [--errors A,B] [--tsv FILE] DEM...\n", argv[0]);
    return 2;
  }
  bench::WhiteGround ground;
  if (!ground.create(vp)) return 1;
  const auto& colour_source = ground.source;
  const auto& colour = ground.colour;
  const auto& target = ground.target;
  std::printf("# %s, %ux%u, %d cameras, best of %d draws each\n", ground.context->describe().c_str(), vp.width_px,
              vp.height_px, camera_count, repeat);
  table.row("dem\terror_px\tselection\tleaves\tforced_splits\ttriangles\tselect_ms_mean\tselect_ms_max\t"
            "frame_ms_mean\tbound_px_mean\n");
  std::vector<TerrainLayerConfig> layers;
  std::vector<std::string> names, temporaries;
  for (const std::string& dem : dems) {
    const std::string store = storeFor(
        dem, "/tmp/bench_quadtree_select." + std::to_string(::getpid()) + "." + std::to_string(names.size()) + ".cst");
    if (store.empty()) return 1;
    TerrainLayerConfig layer;
    std::vector<std::string> notes;
    const Status s = openTerrainLayer("", colour_source->geometry(), store, 1.0, true, renderer_config::kTerrainRingCells,
                                      &layer, &notes);
    if (!s) {
      std::fprintf(stderr, "%s: %s\n", dem.c_str(), s.toString().c_str());
      return 1;
    }
    const std::string name = dem.substr(dem.find_last_of('/') + 1);
    for (double e : errors) {
      Row rows[3];
      measure(layer, *colour, *target, vp, e, camera_count, repeat, rows);
      for (int m = 0; m < 3; ++m)
        table.row("%s\t%.1f\t%s\t%.0f\t%.1f\t%.0f\t%.3f\t%.3f\t%.1f\t%.2f\n", name.c_str(), e, kModes[m].name,
                  rows[m].leaves, rows[m].forced, rows[m].triangles, rows[m].select_ms, rows[m].select_max_ms,
                  rows[m].frame_ms, rows[m].bound_px);
    }
    layers.push_back(layer);
    names.push_back(name);
    if (store != dem) temporaries.push_back(store);
  }
  table.row("dem\tdraws of\tblocks or nodes\ttriangles\tframe_ms_mean\n");
  for (size_t i = 0; i < layers.size(); ++i)
    drawCost(layers[i], *colour, *target, vp, camera_count, repeat, names[i], &table);
  for (const std::string& t : temporaries) std::remove(t.c_str());
  return table.commit() ? 0 : 1;
}
