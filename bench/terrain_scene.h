// Terrain scenes for the renderer's terrain benchmarks: a DEM given as a
// store or a GeoTIFF, every height tile resident, random cameras over it.
// GL thread (WhiteGround, uploadAll(), cameras()); storeFor() runs the tiler.
#pragma once

#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/terrain.h>
#include <clipstream/tiler/tiler.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

namespace clipstream::bench {

// An elevation store for `path`: itself, or a GeoTIFF tiled into `temporary`.
inline std::string storeFor(const std::string& path, const std::string& temporary) {
  if (path.size() < 4 || (path.compare(path.size() - 4, 4, ".tif") != 0 && path.compare(path.size() - 5, 5, ".tiff") != 0))
    return path;
  TilerOptions t;
  t.input_path = path;
  t.output_path = temporary;
  t.fsync = false;
  TilerSummary summary;
  if (Status s = tileImage(t, &summary); !s) {
    std::fprintf(stderr, "%s: %s\n", path.c_str(), s.toString().c_str());
    return "";
  }
  return temporary;
}

// Every tile of every level of `heights` into `terrain`.
inline void uploadAll(TerrainRenderer& terrain, TileSource& heights) {
  const PyramidGeometry& g = heights.geometry();
  std::vector<uint8_t> bytes;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x)
        if (heights.fetch({l, x, y}, &bytes).ok()) terrain.uploadTile({l, x, y}, reinterpret_cast<const float*>(bytes.data()));
}

// Random cameras over the DEM, 20 to 1000 world units above its ground,
// looking 10 to 70 degrees down.
inline std::vector<Camera> cameras(const TerrainRenderer& t, const TerrainLayerConfig& layer, int count) {
  std::mt19937 rng(20261207);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const PyramidGeometry& g = layer.source->geometry();
  const glm::dvec2 lo = layer.alignment.sample0_world;
  const glm::dvec2 hi = lo + glm::dvec2(double(g.width_px), double(g.height_px)) * layer.alignment.world_per_sample;
  std::vector<Camera> out;
  for (int i = 0; i < count; ++i) {
    Camera c;
    const glm::dvec2 at = lo + (hi - lo) * glm::dvec2(u(rng), u(rng));
    double ground = 0.0;
    if (!t.groundHeight(at, &ground)) ground = 0.0;
    c.position = {at.x, ground + 20.0 * std::pow(50.0, u(rng)), at.y};
    c.heading_rad = 6.2831853 * u(rng);
    c.pitch_rad = -0.17 - 1.05 * u(rng);
    out.push_back(c);
  }
  return out;
}

// A headless GL context, the colour the terrain is drawn under (a 2048^2
// white image in a clipmap renderer) and an offscreen target of the
// viewport's size.
struct WhiteGround {
  std::unique_ptr<HeadlessContext> context;
  std::shared_ptr<TileSource> source;
  std::unique_ptr<ClipmapRenderer> colour;
  std::unique_ptr<OffscreenTarget> target;

  // False, the error printed, when GL cannot make them.
  bool create(const Viewport& vp) {
    if (Status s = HeadlessContext::create(&context); !s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return false;
    }
    keepHeapForSoftwareGl();
    source = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
    uint32_t failures = 0;
    Camera first;
    first.position = {1024.0, 500.0, 1024.0};
    if (Status s = createClipmapRenderer(*source, vp, first, {}, Buffering::kSingle, &colour, &failures); !s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return false;
    }
    if (Status s = OffscreenTarget::create(vp, &target); !s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return false;
    }
    return true;
  }
};

}  // namespace clipstream::bench
