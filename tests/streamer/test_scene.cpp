// A scene of layers: elevation stores as tile sources (heights as float32),
// and one streamer serving a colour and an elevation layer of different
// geometries through one RAM cache, one budget and one load order.
#include "streamer_test_util.h"

#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>
#include <clipstream/streamer/testing/faulty_source.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <atomic>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <set>
#include <unordered_set>

namespace clipstream {
namespace {

using test::expectCountersAddUp;
using test::procedural;
using test::TempDir;
using test::waitIdle;

// Stored sample (i, j) of elevation tile `k`: distinct per tile and sample.
int16_t sampleOf(const TileKey& k, uint32_t i, uint32_t j) {
  return int16_t(int(k.level) * 1000 + int(k.x) * 100 + int(k.y) * 10 - 500 + int((i * 7 + j * 3) % 50));
}

constexpr double kScale = 0.5;
constexpr double kOffset = 100.0;

// Writes a width x height elevation store of tile_px tiles whose samples are
// sampleOf(): I16 with height = kOffset + kScale * sample, or F32 holding
// that same height directly.
std::string writeElevationStore(const TempDir& dir, const std::string& name, uint64_t width,
                                uint64_t height, uint32_t tile_px, PixelFormat format) {
  PyramidGeometry g;
  EXPECT_TRUE(makePyramidGeometry(width, height, tile_px, format, &g));
  WriterOptions options;
  options.fsync = false;
  options.encoding.filter = DownsampleFilter::kDecimate;
  options.elevation.present = true;
  if (format == PixelFormat::kI16) {
    options.elevation.scale = kScale;
    options.elevation.offset = kOffset;
  }
  const std::string path = dir.file(name);
  const Status s = test::writeStore(path, g, options, [&](const TileKey& key, std::vector<uint8_t>* px) {
    px->resize(g.tileBytes());
    for (uint32_t j = 0; j < g.tile_px; ++j)
      for (uint32_t i = 0; i < g.tile_px; ++i) {
        uint8_t* p = px->data() + (size_t(j) * g.tile_px + i) * bytesPerPixel(format);
        const int16_t v = sampleOf(key, i, j);
        if (format == PixelFormat::kI16) {
          std::memcpy(p, &v, 2);
        } else {
          const float h = float(kOffset + kScale * v);
          std::memcpy(p, &h, 4);
        }
      }
    return okStatus();
  });
  EXPECT_TRUE(s.ok()) << s.toString();
  return path;
}

std::vector<float> asFloats(const std::vector<uint8_t>& bytes) {
  std::vector<float> out(bytes.size() / 4);
  std::memcpy(out.data(), bytes.data(), out.size() * 4);
  return out;
}

// ---------------------------------------------------------------------------
// Elevation sources

TEST(ElevationSource, HandsOutTheStoresHeightsAsFloat32) {
  TempDir dir("scene");
  for (PixelFormat format : {PixelFormat::kI16, PixelFormat::kF32}) {
    SCOPED_TRACE(pixelFormatName(format));
    const std::string path = writeElevationStore(dir, std::string("e_") + pixelFormatName(format) + ".cst",
                                                 200, 150, 32, format);
    Status status;
    auto source = openElevationSource(path, &status);
    ASSERT_NE(source, nullptr) << status.toString();
    EXPECT_EQ(source->content(), TileContent::kHeightF32);
    EXPECT_TRUE(source->elevationInfo().present);
    EXPECT_EQ(source->elevationInfo().scale, format == PixelFormat::kI16 ? kScale : 1.0);
    EXPECT_EQ(source->geometry().format, format);
    // A wrapper says what its inner source holds.
    EXPECT_EQ(makeFaultySource(source, {})->content(), TileContent::kHeightF32);

    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
    const PyramidGeometry& g = source->geometry();
    std::vector<float> decoded(size_t(g.tile_px) * g.tile_px);
    uint64_t tiles = 0;
    for (uint32_t l = 0; l < g.levelCount(); ++l)
      for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
        for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x, ++tiles) {
          const TileKey key{l, x, y};
          std::vector<uint8_t> bytes;
          FetchInfo info;
          ASSERT_TRUE(source->fetchWithInfo(key, &bytes, &info).ok());
          ASSERT_EQ(bytes.size(), size_t(g.tile_px) * g.tile_px * 4);
          const std::vector<float> heights = asFloats(bytes);
          // What was written, computed here...
          for (uint32_t j = 0; j < g.tile_px; ++j)
            for (uint32_t i = 0; i < g.tile_px; ++i)
              ASSERT_EQ(heights[size_t(j) * g.tile_px + i], float(kOffset + kScale * sampleOf(key, i, j)))
                  << "level " << l << " tile (" << x << ", " << y << ") sample (" << i << ", " << j << ")";
          // ... and what the store's own decoder gives, bit for bit.
          RawTile raw;
          ASSERT_TRUE(reader->readRaw(key, &raw).ok());
          ASSERT_TRUE(decodeTileHeights(g, reader->info().encoding, reader->info().elevation, raw, decoded).ok());
          EXPECT_EQ(std::memcmp(decoded.data(), bytes.data(), bytes.size()), 0);
        }
    EXPECT_GT(tiles, 20u);
  }
}

TEST(ElevationSource, ColourAndElevationStoresOpenOnlyAsWhatTheyAre) {
  TempDir dir("scene");
  const std::string colour = dir.file("c.cst");
  ASSERT_TRUE(test::writeSyntheticStore(colour, test::SyntheticStoreSpec{}).ok());
  const std::string elevation = writeElevationStore(dir, "e.cst", 100, 100, 32, PixelFormat::kI16);

  Status status;
  EXPECT_EQ(openElevationSource(colour, &status), nullptr);
  EXPECT_EQ(status.code, ErrorCode::kUnsupported);
  EXPECT_NE(status.message.find(colour), std::string::npos) << status.message;
  EXPECT_NE(status.message.find("colour store"), std::string::npos) << status.message;

  EXPECT_EQ(openStoreSource(elevation, &status), nullptr);
  EXPECT_EQ(status.code, ErrorCode::kUnsupported);
  EXPECT_NE(status.message.find(elevation), std::string::npos) << status.message;

  auto c = openStoreSource(colour, &status);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->content(), TileContent::kRgba8);
  EXPECT_FALSE(c->elevationInfo().present);
  EXPECT_EQ(openElevationSource(dir.file("missing.cst"), &status), nullptr);
  EXPECT_EQ(status.code, ErrorCode::kNotFound);
}

// ---------------------------------------------------------------------------
// Layers

TEST(SceneLayers, LayerCameraSeesTheSameGroundInTheLayersTexels) {
  const Viewport vp{640, 480};
  Camera world = test::obliqueCamera();
  StreamLayer identity;
  const Camera same = layerCamera(identity, world);
  EXPECT_EQ(same.position, world.position);
  EXPECT_EQ(same.near_dist, world.near_dist);

  StreamLayer dem;
  dem.texels_per_unit = {0.25, 0.25};
  dem.origin_texel = {100.0, -60.0};
  const Camera mapped = layerCamera(dem, world);
  EXPECT_EQ(mapped.heading_rad, world.heading_rad);
  EXPECT_EQ(mapped.pitch_rad, world.pitch_rad);
  // Every pixel's ground point is the world one, mapped.
  for (double py : {240.0, 400.0, 479.5})
    for (double px : {0.5, 320.0, 639.5}) {
      glm::dvec2 w, l;
      ASSERT_TRUE(groundHit(world, vp, px, py, &w));
      ASSERT_TRUE(groundHit(mapped, vp, px, py, &l));
      const glm::dvec2 expect = dem.origin_texel + dem.texels_per_unit * w;
      EXPECT_NEAR(l.x, expect.x, 1e-9 * std::abs(expect.x) + 1e-9);
      EXPECT_NEAR(l.y, expect.y, 1e-9 * std::abs(expect.y) + 1e-9);
    }
}

TEST(SceneLayers, CheckNamesTheBadLayerAndTheStreamerLeavesItEmpty) {
  TempDir dir("scene");
  Status status;
  auto dem = openElevationSource(writeElevationStore(dir, "e.cst", 256, 256, 32, PixelFormat::kI16), &status);
  ASSERT_NE(dem, nullptr);
  auto colour = procedural(4096);

  EXPECT_TRUE(checkStreamLayers({{colour}, {dem, LayerRole::kElevation, {0.5, 0.5}}}).ok());
  const Status no_source = checkStreamLayers({{colour}, {nullptr}});
  EXPECT_EQ(no_source.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(no_source.message.find("layer 1"), std::string::npos) << no_source.message;
  EXPECT_FALSE(checkStreamLayers({{colour, LayerRole::kColour, {0.0, 1.0}}}).ok());
  EXPECT_FALSE(checkStreamLayers({{colour, LayerRole::kColour, {1.0, NAN}}}).ok());
  EXPECT_FALSE(checkStreamLayers({{colour, LayerRole::kColour, {1.0, 1.0}, {INFINITY, 0.0}}}).ok());
  const Status wrong_role = checkStreamLayers({{colour}, {dem, LayerRole::kColour}});
  EXPECT_FALSE(wrong_role.ok());
  EXPECT_NE(wrong_role.message.find("heights"), std::string::npos) << wrong_role.message;
  EXPECT_FALSE(checkStreamLayers({{colour, LayerRole::kElevation}}).ok());

  // The bad layer streams nothing; the good one streams as usual.
  StreamerConfig cfg;
  cfg.io_threads = 2;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = 8;
  Streamer s({{colour}, {dem, LayerRole::kColour}}, cfg);
  ASSERT_EQ(s.layerCount(), 2u);
  EXPECT_EQ(s.layer(1).source, nullptr);
  EXPECT_EQ(s.geometry(1).levelCount(), 0u);
  s.update(test::lookingDown(2000.0, 2000.0, 50.0), Viewport{640, 480}, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const std::vector<FrameHandoff> h = s.takeReadyAll(1000);
  ASSERT_EQ(h.size(), 2u);
  EXPECT_FALSE(h[0].tiles.empty());
  EXPECT_TRUE(h[1].tiles.empty());
  EXPECT_EQ(s.stats().layers[1].total.requests, 0u);
}

// The scene most tests fly: procedural colour (8192^2, 128-texel tiles) as
// layer 0, and an I16 DEM (1024^2, 32-sample tiles) as layer 1 with a
// texel per 4 world units, its sample (100, 60) at the world's origin.
struct Scene {
  TempDir dir{"scene"};
  std::shared_ptr<TileSource> colour = procedural(8192);
  std::shared_ptr<TileSource> dem;
  StreamLayer dem_layer;

  Scene() {
    Status status;
    dem = openElevationSource(writeElevationStore(dir, "dem.cst", 1024, 1024, 32, PixelFormat::kI16),
                              &status);
    EXPECT_NE(dem, nullptr) << status.toString();
    dem_layer = {dem, LayerRole::kElevation, {0.25, 0.25}, {100.0, 60.0}};
  }
  std::vector<StreamLayer> layers(std::shared_ptr<TileSource> c, std::shared_ptr<TileSource> e) const {
    StreamLayer d = dem_layer;
    d.source = std::move(e);
    return {{std::move(c)}, d};
  }
};

StreamerConfig sceneConfig(unsigned threads) {
  StreamerConfig cfg;
  cfg.io_threads = threads;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = 8;
  cfg.planner.scope = PlanScope::kWindow;  // whole windows: each layer's are checked
  // The tests wait for the loaders between hand-offs (waitIdle()): every
  // window's tiles may wait in RAM for the GPU, as the default's 64 may not.
  cfg.throttle_read_ahead_min_tiles = 4096;
  return cfg;
}

Camera sceneCamera() {
  Camera c;
  c.position = {2000.0, 60.0, 1800.0};
  c.heading_rad = 0.4;
  c.pitch_rad = -0.8;
  return c;
}

bool samePlan(const ClipmapPlan& a, const ClipmapPlan& b) {
  if (a.clip_tiles != b.clip_tiles || a.pyramid_level != b.pyramid_level ||
      a.finest_level != b.finest_level || a.pyramid != b.pyramid || a.focus_texel != b.focus_texel ||
      a.ground_visible != b.ground_visible || a.stack.size() != b.stack.size())
    return false;
  for (size_t i = 0; i < a.stack.size(); ++i) {
    const ClipLevelPlan &x = a.stack[i], &y = b.stack[i];
    if (x.level != y.level || x.needed != y.needed || x.window != y.window || x.visible != y.visible ||
        x.origin_tx != y.origin_tx || x.origin_ty != y.origin_ty)
      return false;
  }
  return true;
}

TEST(SceneStreamer, PlansEachLayerInItsTexelsAndHandsOffBothLayersTiles) {
  Scene scene;
  Streamer s(scene.layers(scene.colour, scene.dem), sceneConfig(2));
  const Viewport vp{640, 480};
  const Camera cam = sceneCamera();
  s.update(cam, vp, 0.0);
  ASSERT_EQ(s.layerCount(), 2u);
  EXPECT_EQ(s.geometry(1).tile_px, 32u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_TRUE(samePlan(s.plan(i), planClipmap(s.geometry(i), vp, layerCamera(s.layer(i), cam),
                                                sceneConfig(2).planner)))
        << "layer " << i;
    EXPECT_TRUE(s.plan(i).ground_visible);
    EXPECT_FALSE(s.plan(i).stack.empty());
  }
  EXPECT_FALSE(samePlan(s.plan(0), s.plan(1)));

  // Hand off until settled; every layer gets every tile its plan wants.
  std::vector<std::set<std::tuple<uint32_t, uint32_t, uint32_t>>> handed(2);
  std::vector<FrameHandoff> last;
  for (int frame = 1; frame < 50 && !s.settled(); ++frame) {
    ASSERT_TRUE(waitIdle(s));
    last = s.takeReadyAll(64);
    ASSERT_EQ(last.size(), 2u);
    for (uint32_t i = 0; i < 2; ++i) {
      EXPECT_EQ(last[i].layer, i);
      for (const ReadyTile& t : last[i].tiles) {
        EXPECT_TRUE(handed[i].insert({t.key.level, t.key.x, t.key.y}).second) << "handed off twice";
        ASSERT_EQ(t.rgba->size(), size_t(s.geometry(i).tile_px) * s.geometry(i).tile_px * 4);
        // The pixels are this layer's: DEM tiles hold that tile's heights,
        // colour tiles the procedural texels.
        if (i == 1) {
          const std::vector<float> h = asFloats(*t.rgba);
          ASSERT_EQ(h[0], float(kOffset + kScale * sampleOf(t.key, 0, 0)));
          ASSERT_EQ(h[33], float(kOffset + kScale * sampleOf(t.key, 1, 1)));
        } else {
          std::vector<uint8_t> expect;
          ASSERT_TRUE(scene.colour->fetch(t.key, &expect).ok());
          ASSERT_EQ(*t.rgba, expect);
        }
      }
    }
    s.update(cam, vp, frame / 60.0);
  }
  ASSERT_TRUE(s.settled());
  last = s.takeReadyAll(64);
  for (uint32_t i = 0; i < 2; ++i) {
    SCOPED_TRACE("layer " + std::to_string(i));
    const std::vector<TileKey> wanted = rankPlanTiles(s.geometry(i), s.plan(i));
    EXPECT_GT(wanted.size(), 40u);
    for (const TileKey& k : wanted) EXPECT_TRUE(handed[i].count({k.level, k.x, k.y}));
    ASSERT_EQ(last[i].residency.size(), s.plan(i).stack.size());
    for (const LevelResidency& r : last[i].residency) {
      if (!s.plan(i).stack[r.level].needed) continue;
      for (uint8_t v : r.resident) EXPECT_EQ(v, 1) << "level " << r.level;
    }
    EXPECT_EQ(last[i].max_texture_lod, s.plan(i).finest_level);
  }
  // takeReady() is layer 0's view of the same state.
  EXPECT_EQ(s.takeReady(64).max_texture_lod, last[0].max_texture_lod);
  const StreamerStats st = s.stats();
  ASSERT_EQ(st.layers.size(), 2u);
  EXPECT_EQ(st.layers[0].total.gpu_handoffs, handed[0].size());
  EXPECT_EQ(st.layers[1].total.gpu_handoffs, handed[1].size());
  EXPECT_EQ(st.total.loads, st.layers[0].total.loads + st.layers[1].total.loads);
  EXPECT_EQ(st.ram_bytes, st.layers[0].ram_bytes + st.layers[1].ram_bytes);
  EXPECT_EQ(st.layers[1].ram_bytes, st.layers[1].ram_entries * (32 * 32 * 4 + kCacheEntryOverheadBytes));
  EXPECT_EQ(st.layers[0].ram_bytes, st.layers[0].ram_entries * (128 * 128 * 4 + kCacheEntryOverheadBytes));
  expectCountersAddUp(st);
  const nlohmann::json j = nlohmann::json::parse(st.toJson());
  ASSERT_EQ(j["layers"].size(), 2u);
  EXPECT_EQ(j["layers"][1]["total"]["loads"], st.layers[1].total.loads);
  EXPECT_EQ(j["layers"][1]["levels"].size(), s.geometry(1).levelCount());
  EXPECT_EQ(j["layers"][0]["ram_bytes"], st.layers[0].ram_bytes);
}

TEST(SceneStreamer, OneHardBudgetHoldsForBothLayersTogether) {
  Scene scene;
  StreamerConfig cfg = sceneConfig(3);
  cfg.prefetch = true;
  cfg.ram_budget_bytes = 6u << 20;  // well below what the flight wants
  Streamer s(scene.layers(scene.colour, scene.dem), cfg);
  const Viewport vp{640, 480};
  Camera cam = sceneCamera();
  for (int frame = 0; frame < 60; ++frame) {
    cam.position.x = 1000.0 + 90.0 * frame;
    s.update(cam, vp, frame / 60.0);
    if (frame % 4 == 0) {
      ASSERT_TRUE(waitIdle(s));
    }
    (void)s.takeReadyAll(16);
  }
  ASSERT_TRUE(waitIdle(s));
  const StreamerStats st = s.stats();
  // The peak is taken at every insert (the placeholder's, before the read).
  EXPECT_LE(st.ram_peak_bytes, cfg.ram_budget_bytes);
  EXPECT_GT(st.total.loads + st.total.failures, 100u);
  EXPECT_GT(st.ram_peak_bytes, cfg.ram_budget_bytes - 2 * (128 * 128 * 4 + kCacheEntryOverheadBytes))
      << "the budget never filled: the test does not test it";
  EXPECT_GT(st.total.evictions, 0u);
  EXPECT_GT(st.layers[0].total.loads, 0u);
  EXPECT_GT(st.layers[1].total.loads, 0u);
  EXPECT_EQ(st.ram_bytes, st.layers[0].ram_bytes + st.layers[1].ram_bytes);
  expectCountersAddUp(st);
}

TEST(SceneStreamer, PathHintServesTheSceneAndIsIgnoredWhenWrong) {
  Scene scene;
  StreamerConfig cfg = sceneConfig(2);
  cfg.prefetch = true;
  cfg.ram_budget_bytes = 6u << 20;  // eviction by the hinted return runs too
  auto cameraAt = [](double t_s) {
    Camera c = sceneCamera();
    c.position.x = 1000.0 + 5400.0 * t_s;
    return c;
  };
  Streamer s(scene.layers(scene.colour, scene.dem), cfg);
  PathHint hint;
  hint.camera_at = cameraAt;
  s.setPathHint(hint);
  const Viewport vp{640, 480};
  for (int frame = 0; frame < 40; ++frame) {
    s.update(cameraAt(frame / 60.0), vp, frame / 60.0);
    (void)s.takeReadyAll(16);
  }
  ASSERT_TRUE(waitIdle(s));
  StreamerStats st = s.stats();
  EXPECT_EQ(st.path_hint_frames, 40u);
  EXPECT_EQ(st.path_hint_ignored_frames, 0u);
  EXPECT_GT(st.layers[1].total.loads, 0u);
  expectCountersAddUp(st);

  // A hint 3000 world units off (windows of both layers elsewhere) is ignored.
  hint.camera_at = [&](double t_s) {
    Camera c = cameraAt(t_s);
    c.position.z += 3000.0;
    return c;
  };
  s.setPathHint(hint);
  for (int frame = 40; frame < 50; ++frame) s.update(cameraAt(frame / 60.0), vp, frame / 60.0);
  st = s.stats();
  EXPECT_EQ(st.path_hint_frames, 40u);
  EXPECT_EQ(st.path_hint_ignored_frames, 10u);
}

// Records every fetch of every layer in one list, in call order.
struct FetchLog {
  std::mutex mutex;
  std::vector<LayerTile> fetched;  // guarded by mutex
};

class LoggingSource final : public TileSource {
 public:
  LoggingSource(std::shared_ptr<TileSource> inner, uint32_t layer, std::shared_ptr<FetchLog> log)
      : m_inner(std::move(inner)), m_layer(layer), m_log(std::move(log)) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return m_inner->content(); }
  ElevationInfo elevationInfo() const override { return m_inner->elevationInfo(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* out) override {
    {
      std::lock_guard<std::mutex> lock(m_log->mutex);
      m_log->fetched.push_back({m_layer, key});
    }
    return m_inner->fetch(key, out);
  }
  std::string describe() const override { return "logging:" + m_inner->describe(); }

 private:
  std::shared_ptr<TileSource> m_inner;
  uint32_t m_layer;
  std::shared_ptr<FetchLog> m_log;
};

// The documented order, built level by level (not by sorting): every
// layer's pyramid, then the stack; in each, coarsest world texel first
// (log2 of world units per texel, rounded), elevation before colour at
// equal coarseness, then layer order; in a level, rankPlanTiles()'s order.
std::vector<LayerTile> documentedOrder(const Streamer& s) {
  std::vector<std::vector<TileKey>> ranked(s.layerCount());
  for (size_t i = 0; i < s.layerCount(); ++i) ranked[i] = rankPlanTiles(s.geometry(i), s.plan(i));
  auto coarseness = [&](size_t i, uint32_t level) {
    return std::lround(double(level) - std::log2(s.layer(i).texels_per_unit.x));
  };
  std::vector<LayerTile> out;
  for (int stack = 0; stack < 2; ++stack)
    for (long c = 40; c >= -40; --c)
      for (LayerRole role : {LayerRole::kElevation, LayerRole::kColour})
        for (uint32_t i = 0; i < s.layerCount(); ++i) {
          if (s.layer(i).role != role) continue;
          for (const TileKey& k : ranked[i])
            if (coarseness(i, k.level) == c && (k.level < s.plan(i).pyramid_level) == (stack == 1))
              out.push_back({i, k});
        }
  return out;
}

TEST(SceneStreamer, LoadsAndHandsOffInOneOrderInterleavingLayersByWorldCoarseness) {
  Scene scene;
  auto log = std::make_shared<FetchLog>();
  Streamer s(scene.layers(std::make_shared<LoggingSource>(scene.colour, 0, log),
                          std::make_shared<LoggingSource>(scene.dem, 1, log)),
             sceneConfig(1));
  s.update(sceneCamera(), Viewport{640, 480}, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const std::vector<LayerTile> expected = documentedOrder(s);
  std::vector<LayerTile> fetched;
  {
    std::lock_guard<std::mutex> lock(log->mutex);
    fetched = log->fetched;
  }
  ASSERT_EQ(fetched.size(), expected.size());
  size_t switches = 0;
  for (size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(fetched[i], expected[i]) << "fetch " << i << ": got layer " << fetched[i].layer << " level "
                                       << fetched[i].key.level << ", want layer " << expected[i].layer
                                       << " level " << expected[i].key.level;
    switches += i > 0 && fetched[i].layer != fetched[i - 1].layer;
  }
  // The layers really interleave (DEM level l is as coarse as colour level
  // l + 2, so the pyramids alternate level by level), and at equal
  // coarseness elevation comes first: DEM level 0 before colour level 2.
  EXPECT_GE(switches, 6u);
  auto firstOf = [&](uint32_t layer, uint32_t level) {
    for (size_t i = 0; i < fetched.size(); ++i)
      if (fetched[i].layer == layer && fetched[i].key.level == level) return i;
    return fetched.size();
  };
  ASSERT_LT(firstOf(0, 2), fetched.size());
  ASSERT_LT(firstOf(1, 0), fetched.size());
  EXPECT_LT(firstOf(1, 0), firstOf(0, 2));

  // Hand-offs share one per-frame budget and follow the same order: each
  // takeReadyAll(5) gives the next five tiles of that order, whichever
  // layers they belong to.
  for (size_t start = 0; start < expected.size(); start += 5) {
    const std::vector<FrameHandoff> h = s.takeReadyAll(5);
    std::vector<LayerTile> got;
    for (const FrameHandoff& f : h)
      for (const ReadyTile& t : f.tiles) got.push_back({f.layer, t.key});
    std::vector<LayerTile> want(expected.begin() + ptrdiff_t(start),
                                expected.begin() + ptrdiff_t(std::min(start + 5, expected.size())));
    auto less = [](const LayerTile& a, const LayerTile& b) {
      return std::tie(a.layer, a.key.level, a.key.y, a.key.x) < std::tie(b.layer, b.key.level, b.key.y, b.key.x);
    };
    std::sort(got.begin(), got.end(), less);
    std::sort(want.begin(), want.end(), less);
    ASSERT_EQ(got, want) << "hand-off starting at " << start;
  }
  EXPECT_TRUE(s.settled());
}

TEST(SceneStreamer, BudgetBelowTheSceneLoadsWhatFitsInTheOneOrder) {
  // With nothing handed off every loaded tile stays wanted and pinned, so a
  // budget below the scene's needed set keeps the head of the one order:
  // walking it, each tile is loaded if its layer's entry still fits, else
  // skipped (a later, smaller DEM tile may still fit after a colour tile
  // did not).
  Scene scene;
  auto log = std::make_shared<FetchLog>();
  StreamerConfig cfg = sceneConfig(1);
  // Runs out inside colour level 3 (the last pyramid level) with room left
  // for a few of the DEM stack tiles that follow.
  cfg.ram_budget_bytes = 3765000;
  Streamer s(scene.layers(std::make_shared<LoggingSource>(scene.colour, 0, log),
                          std::make_shared<LoggingSource>(scene.dem, 1, log)),
             cfg);
  s.update(sceneCamera(), Viewport{640, 480}, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const std::vector<LayerTile> order = documentedOrder(s);
  std::vector<LayerTile> expected;
  uint64_t bytes = 0;
  bool skipped_colour = false, dem_after_skip = false;
  for (const LayerTile& t : order) {
    const uint64_t entry = uint64_t(s.geometry(t.layer).tile_px) * s.geometry(t.layer).tile_px * 4 +
                           kCacheEntryOverheadBytes;
    if (bytes + entry > cfg.ram_budget_bytes) {
      skipped_colour = skipped_colour || t.layer == 0;
      continue;
    }
    dem_after_skip = dem_after_skip || (skipped_colour && t.layer == 1);
    bytes += entry;
    expected.push_back(t);
  }
  ASSERT_LT(expected.size(), order.size()) << "the budget holds the whole scene: no test";
  std::vector<LayerTile> fetched;
  {
    std::lock_guard<std::mutex> lock(log->mutex);
    fetched = log->fetched;
  }
  EXPECT_EQ(fetched, expected);
  EXPECT_TRUE(dem_after_skip) << "no DEM tile after the first colour tile that did not fit";
  const StreamerStats st = s.stats();
  EXPECT_EQ(st.ram_bytes, bytes);
  EXPECT_EQ(st.total.budget_skips, order.size() - expected.size());
  expectCountersAddUp(st);
}

TEST(SceneStreamer, ResetGpuResidencyHandsEveryLayerOffAgain) {
  Scene scene;
  Streamer s(scene.layers(scene.colour, scene.dem), sceneConfig(2));
  const Viewport vp{640, 480};
  auto settle = [&](std::vector<size_t>* counts) {
    counts->assign(2, 0);
    for (int frame = 0; frame < 50 && !s.settled(); ++frame) {
      s.update(sceneCamera(), vp, frame / 60.0);
      EXPECT_TRUE(waitIdle(s));
      for (const FrameHandoff& h : s.takeReadyAll(1000)) (*counts)[h.layer] += h.tiles.size();
    }
    EXPECT_TRUE(s.settled());
  };
  std::vector<size_t> first, again;
  settle(&first);
  s.resetGpuResidency();
  EXPECT_FALSE(s.settled());
  settle(&again);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(again[i], rankPlanTiles(s.geometry(i), s.plan(i)).size()) << "layer " << i;
    EXPECT_EQ(first[i], again[i]) << "layer " << i;
  }
}

void expectSameHandoff(const FrameHandoff& a, const FrameHandoff& b, int frame) {
  ASSERT_EQ(a.tiles.size(), b.tiles.size()) << "frame " << frame;
  for (size_t i = 0; i < a.tiles.size(); ++i) {
    EXPECT_EQ(a.tiles[i].key, b.tiles[i].key) << "frame " << frame << " tile " << i;
    EXPECT_EQ(*a.tiles[i].rgba, *b.tiles[i].rgba);
  }
  EXPECT_EQ(a.max_texture_lod, b.max_texture_lod) << "frame " << frame;
  EXPECT_EQ(a.layer, b.layer);
  ASSERT_EQ(a.residency.size(), b.residency.size());
  for (size_t i = 0; i < a.residency.size(); ++i) {
    EXPECT_EQ(a.residency[i].level, b.residency[i].level);
    EXPECT_EQ(a.residency[i].window, b.residency[i].window);
    EXPECT_EQ(a.residency[i].resident, b.residency[i].resident) << "frame " << frame << " level " << i;
  }
}

TEST(SceneStreamer, OneLayerSceneIsTheOneSourceStreamer) {
  auto source = procedural(1 << 16);
  StreamerConfig cfg = sceneConfig(1);
  cfg.prefetch = true;
  cfg.ram_budget_bytes = 5u << 20;  // evictions and budget skips happen too
  Streamer one(source, cfg);
  Streamer scene({StreamLayer{source}}, cfg);
  Streamer scene_all({StreamLayer{source, LayerRole::kColour, {1.0, 1.0}, {0.0, 0.0}}}, cfg);
  const Viewport vp{640, 480};
  Camera cam = sceneCamera();
  for (int frame = 0; frame < 48; ++frame) {
    cam.position.x = 3000.0 + 70.0 * frame;
    cam.heading_rad = 0.4 + 0.02 * frame;
    if (frame == 30) cam.position = {40000.0, 120.0, 50000.0};  // a teleport
    const double t = frame / 60.0;
    one.update(cam, vp, t);
    scene.update(cam, vp, t);
    scene_all.update(cam, vp, t);
    ASSERT_TRUE(samePlan(one.plan(), scene.plan())) << "frame " << frame;
    ASSERT_TRUE(samePlan(one.plan(), scene_all.plan(0))) << "frame " << frame;
    ASSERT_TRUE(waitIdle(one));
    ASSERT_TRUE(waitIdle(scene));
    ASSERT_TRUE(waitIdle(scene_all));
    const FrameHandoff a = one.takeReady(6);
    const FrameHandoff b = scene.takeReady(6);
    const std::vector<FrameHandoff> c = scene_all.takeReadyAll(6);
    ASSERT_EQ(c.size(), 1u);
    expectSameHandoff(a, b, frame);
    expectSameHandoff(a, c[0], frame);
  }
  const StreamerStats sa = one.stats(), sb = scene.stats(), sc = scene_all.stats();
  EXPECT_GT(sa.total.evictions, 0u);
  for (const StreamerStats* other : {&sb, &sc}) {
    EXPECT_EQ(sa.total.requests, other->total.requests);
    EXPECT_EQ(sa.total.loads, other->total.loads);
    EXPECT_EQ(sa.total.evictions, other->total.evictions);
    EXPECT_EQ(sa.total.budget_skips, other->total.budget_skips);
    EXPECT_EQ(sa.total.cancellations, other->total.cancellations);
    EXPECT_EQ(sa.total.ram_hits, other->total.ram_hits);
    EXPECT_EQ(sa.ram_bytes, other->ram_bytes);
    ASSERT_EQ(sa.levels.size(), other->levels.size());
    for (size_t l = 0; l < sa.levels.size(); ++l) EXPECT_EQ(sa.levels[l].loads, other->levels[l].loads);
  }
  ASSERT_EQ(sa.layers.size(), 1u);
  EXPECT_EQ(sa.layers[0].total.loads, sa.total.loads);
  expectCountersAddUp(sa);
}

}  // namespace
}  // namespace clipstream
