// GPU tests of the clipmap renderer against the CPU reference. Headless
// llvmpipe; each skips when no EGL context can be created. Metric: PSNR over
// RGB; thresholds: >= 35 dB "matches", >= 50 dB "same frame".
#include "test_helpers.h"
#include "../../renderer/src/clipmap_renderer_impl.h"  // private: the slot bias

#include <clipstream/renderer/config.h>
#include <clipstream/eval/frame_writer.h>
#include <clipstream/eval/metrics.h>
#include <clipstream/streamer/bc1.h>
#include <clipstream/streamer/tile_source.h>

#include <gtest/gtest.h>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>  // GL_MAX_TEXTURE_SIZE, for a stack at the driver's limit

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace clipstream {
namespace {

constexpr double kMatchDb = 35.0;
constexpr double kSameDb = 50.0;
const Viewport kViewport{256, 192};

struct Scene {
  std::shared_ptr<TileSource> source;
  ClipmapPlan plan;
  std::unique_ptr<ClipmapRenderer> renderer;
  std::unique_ptr<OffscreenTarget> target;
};

Scene makeScene(std::shared_ptr<TileSource> source, const Camera& camera,
                Buffering buffering = Buffering::kDoubleUploadTwice) {
  Scene s;
  s.source = std::move(source);
  s.plan = planClipmap(s.source->geometry(), kViewport, camera, {});
  RendererConfig config{s.plan.clip_tiles, s.plan.pyramid_level, buffering, s.source->content()};
  Status st = ClipmapRenderer::create(s.source->geometry(), config, &s.renderer);
  EXPECT_TRUE(st.ok()) << st.toString();
  st = OffscreenTarget::create(kViewport, &s.target);
  EXPECT_TRUE(st.ok()) << st.toString();
  return s;
}

std::shared_ptr<TileSource> patternSource() {
  return makeImageSource(test::patternImage(2048, 2048), 2048, 2048, 128);
}

std::vector<uint8_t> reference(const TileSource& source, std::shared_ptr<TileSource> shared,
                               const Camera& camera, uint32_t min_level = 0) {
  std::vector<uint8_t> ref;
  ReferenceOptions options;
  options.min_level = min_level;
  renderReference(source.geometry(), texelsFromSource(std::move(shared)), camera, kViewport,
                  options, &ref);
  return ref;
}

// PSNR, printed so the margin to the threshold shows in the test log.
double psnrLogged(const char* what, const std::vector<uint8_t>& a, const std::vector<uint8_t>& b,
                  const std::vector<uint8_t>* mask = nullptr) {
  const double db = psnrRgb(a, b, mask);
  std::printf("  PSNR %s: %.2f dB\n", what, db);
  return db;
}

size_t groundPixels(const std::vector<uint8_t>& rgba) {
  size_t n = 0;
  for (size_t i = 0; i < rgba.size(); i += 4)
    if (!std::equal(rgba.begin() + long(i), rgba.begin() + long(i) + 4, renderer_config::kSkyRgba)) ++n;
  return n;
}

TEST(ClipmapRender, MatchesCpuReferenceWhenResident) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  Scene s = makeScene(patternSource(), cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  const auto ref = reference(*s.source, s.source, cam);
  test::dumpPpm("match_gpu", gpu, kViewport);
  test::dumpPpm("match_ref", ref, kViewport);
  EXPECT_GT(groundPixels(ref), ref.size() / 16) << "a quarter of the view must be ground";
  EXPECT_GE(psnrLogged("gpu vs reference", gpu, ref), kMatchDb);
}

// A colour store with no-data (black under alpha 0: the tiler's
// transparency) shows the sky colour there, on the GPU as in the
// reference, and the covered ground is drawn as before.
TEST(ClipmapRender, NoDataShowsTheSkyColour) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  std::vector<uint8_t> image = test::patternImage(2048, 2048);
  for (size_t y = 0; y < 2048; ++y) std::fill_n(image.begin() + long(y * 2048 * 4), 1024 * 4, uint8_t(0));
  std::shared_ptr<TileSource> holed = makeImageSource(image, 2048, 2048, 128);
  Scene s = makeScene(holed, cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  const auto ref = reference(*s.source, s.source, cam);
  test::dumpPpm("nodata_gpu", gpu, kViewport);
  EXPECT_GE(psnrLogged("no-data gpu vs reference", gpu, ref), kMatchDb);
  // Against the same view of the whole pattern: the holed half turned to sky.
  Scene whole = makeScene(patternSource(), cam);
  test::loadPlan(*whole.renderer, *whole.source, whole.plan);
  const auto opaque = test::renderFrame(*whole.renderer, *whole.target, cam);
  const size_t pixels = gpu.size() / 4;
  ASSERT_GT(groundPixels(opaque), pixels / 4);
  EXPECT_LT(groundPixels(gpu), groundPixels(opaque) - pixels / 8) << "the no-data half is not sky";
  size_t same = 0, ground = 0;
  for (size_t i = 0; i < gpu.size(); i += 4) {
    if (groundPixels({gpu.begin() + long(i), gpu.begin() + long(i) + 4}) == 0) continue;
    ++ground;
    same += std::equal(gpu.begin() + long(i), gpu.begin() + long(i) + 3, opaque.begin() + long(i));
  }
  EXPECT_GT(same, ground * 9 / 10) << "covered ground drawn as with no hole";
}

// After a refused allocation the context still draws a renderer that fits:
// the pattern at the oblique view matches its reference.
void expectTheContextStillRenders(const char* label) {
  const Camera cam = test::obliqueCamera();
  Scene ok = makeScene(patternSource(), cam);
  ASSERT_TRUE(ok.renderer);
  test::loadPlan(*ok.renderer, *ok.source, ok.plan);
  const auto gpu = test::renderFrame(*ok.renderer, *ok.target, cam);
  EXPECT_GE(psnrLogged(label, gpu, reference(*ok.source, ok.source, cam)), kMatchDb);
}

// A clip stack no driver can hold (the largest texture the driver allows,
// a layer for each of 25 levels, two sets: over 100 GiB on any GPU) is
// refused with an error naming it, not drawn black; the context still
// works for the next renderer.
TEST(ClipmapRender, AStackTheDriverCannotAllocateIsAnError) {
  CLIPSTREAM_REQUIRE_GL();
  std::shared_ptr<TileSource> planet = makeProceduralSource({kMaxProceduralSidePx, kMaxProceduralSidePx, 128, 1});
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  const uint32_t clip_tiles = uint32_t(max_size) / 128 - 2;  // slots = clip + 2
  const uint32_t pyramid_level = planet->geometry().levelCount() - 1;
  RendererConfig config{clip_tiles, pyramid_level, Buffering::kDoubleUploadTwice, planet->content()};
  std::unique_ptr<ClipmapRenderer> renderer;
  const Status s = ClipmapRenderer::create(planet->geometry(), config, &renderer);
  ASSERT_FALSE(s.ok()) << "a " << max_size << "^2 x " << pyramid_level + 1 << " RGBA8 stack was allocated";
  EXPECT_FALSE(renderer);
  EXPECT_TRUE(s.code == ErrorCode::kOutOfMemory || s.code == ErrorCode::kUnavailable) << s.toString();
  EXPECT_NE(s.message.find("the clip stack (2 sets of "), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("--tile-format bc1"), std::string::npos) << s.message;
  expectTheContextStillRenders("after a refused stack");
}

// The paged mode's pool likewise: pages of tiles as wide as the driver's
// largest texture make a layer (2 x 2 pages) no driver creates. The error
// names the pool and its size; the context still works.
TEST(ClipmapRender, APoolTheDriverCannotAllocateIsAnError) {
  CLIPSTREAM_REQUIRE_GL();
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  const uint32_t tile = uint32_t(max_size);
  std::shared_ptr<TileSource> one = makeProceduralSource({tile, tile, tile, 1});
  RendererConfig config{1, 0, Buffering::kStaged, one->content()};
  config.texture_memory = TextureMemory::kPaged;
  config.pool_bytes = uint64_t(1) << 40;
  std::unique_ptr<ClipmapRenderer> renderer;
  const Status s = ClipmapRenderer::create(one->geometry(), config, &renderer);
  ASSERT_FALSE(s.ok()) << "a pool of " << tile << "-px pages was allocated";
  std::printf("  %s\n", s.message.c_str());
  EXPECT_FALSE(renderer);
  EXPECT_TRUE(s.code == ErrorCode::kOutOfMemory || s.code == ErrorCode::kUnavailable) << s.toString();
  EXPECT_NE(s.message.find("the page pool ("), std::string::npos) << s.message;
  EXPECT_NE(s.message.find(" MiB of RGBA8)"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("--pool-mb"), std::string::npos) << s.message;
  expectTheContextStillRenders("after a refused pool");
}

// A pool too small for the pinned pyramid and one page of each parity
// class more is refused up front, naming what takes the pages.
TEST(ClipmapRender, APoolThePyramidFillsIsRefused) {
  CLIPSTREAM_REQUIRE_GL();
  std::shared_ptr<TileSource> big = makeProceduralSource({uint64_t(1) << 20, uint64_t(1) << 20, 128, 1});
  uint32_t pyramid = 0;
  while (big->geometry().levels[pyramid].tiles_x > 4) ++pyramid;
  RendererConfig config{16, pyramid, Buffering::kStaged, big->content()};
  config.texture_memory = TextureMemory::kPaged;
  // 4 x 4 tiles at the pyramid level: 4 layers after the black page's, and
  // 2 x 2 + 1 coarser: 7 pages of class 0 pinned, so 8 a class are needed.
  const uint64_t page = pageBytes(128, big->content());
  for (uint64_t pages : {28u, 32u}) {
    config.pool_bytes = pages * page;
    std::unique_ptr<ClipmapRenderer> renderer;
    const Status s = ClipmapRenderer::create(big->geometry(), config, &renderer);
    if (pages == 28) {
      EXPECT_EQ(s.code, ErrorCode::kInvalidArgument) << s.toString();
      EXPECT_NE(s.message.find("take 7 of one quarter and leave none: give a larger pool"), std::string::npos)
          << s.message;
    } else {
      EXPECT_TRUE(s.ok()) << s.toString();
    }
  }
}

TEST(ClipmapRender, WrongToroidalOffsetFailsTheReference) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  Scene s = makeScene(patternSource(), cam);
  ASSERT_TRUE(s.renderer);
  s.renderer->impl().setSlotBias(1);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  const auto ref = reference(*s.source, s.source, cam);
  EXPECT_LT(psnrLogged("wrong offset vs reference", gpu, ref), kMatchDb);
}

TEST(ClipmapRender, FallsBackToThePyramidWhenNoStackTileIsResident) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  Scene s = makeScene(patternSource(), cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan, /*finest_loaded=*/s.plan.pyramid_level);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  const auto ref = reference(*s.source, s.source, cam, s.plan.pyramid_level);
  EXPECT_EQ(groundPixels(gpu), groundPixels(ref)) << "a missing tile must never leave a hole";
  EXPECT_GE(psnrLogged("pyramid fallback vs reference", gpu, ref), kMatchDb);
}

TEST(ClipmapRender, MaxTextureLodClampsTheFinestLevel) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  Scene s = makeScene(patternSource(), cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  s.renderer->setMaxTextureLod(1);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  EXPECT_GE(psnrLogged("lod>=1 vs reference(min 1)", gpu, reference(*s.source, s.source, cam, 1)), kMatchDb);
  EXPECT_LT(psnrRgb(gpu, reference(*s.source, s.source, cam, 0)),
            psnrRgb(gpu, reference(*s.source, s.source, cam, 1)));
}

class ToroidalUpdate : public ::testing::TestWithParam<Buffering> {};

TEST_P(ToroidalUpdate, EqualsAFreshRenderAfterTheCameraMoves) {
  CLIPSTREAM_REQUIRE_GL();
  Camera a = test::obliqueCamera();
  Camera b = a;
  b.position += glm::dvec3(300.0, 0.0, -260.0);  // several tiles on levels 0 and 1
  Scene moved = makeScene(patternSource(), a, GetParam());
  ASSERT_TRUE(moved.renderer);
  test::loadPlan(*moved.renderer, *moved.source, moved.plan);
  const ClipmapPlan plan_b = planClipmap(moved.source->geometry(), kViewport, b, {});
  ASSERT_NE(plan_b.stack[0].window, moved.plan.stack[0].window) << "camera must move the window";
  // Only the tiles entering each window are uploaded: the toroidal update.
  moved.renderer->beginFrame();
  size_t entered = 0;
  for (size_t l = 0; l < plan_b.stack.size(); ++l) {
    const TileRect& w = plan_b.stack[l].window;
    for (int64_t y = w.y0; y < w.y1; ++y)
      for (int64_t x = w.x0; x < w.x1; ++x) {
        if (moved.plan.stack[l].window.contains(x, y)) continue;
        auto px = std::make_shared<std::vector<uint8_t>>();
        const TileKey key{uint32_t(l), uint32_t(x), uint32_t(y)};
        ASSERT_TRUE(moved.source->fetch(key, px.get()).ok());
        moved.renderer->uploadTile(key, px);
        ++entered;
      }
  }
  EXPECT_GT(entered, 0u);
  EXPECT_LT(entered, size_t(plan_b.clip_tiles) * plan_b.clip_tiles * plan_b.stack.size());
  moved.renderer->setResidency(test::fullResidency(plan_b));
  moved.renderer->endUploads();
  const auto updated = test::renderFrame(*moved.renderer, *moved.target, b);

  Scene fresh = makeScene(moved.source, b, GetParam());
  ASSERT_TRUE(fresh.renderer);
  test::loadPlan(*fresh.renderer, *fresh.source, plan_b);
  const auto clean = test::renderFrame(*fresh.renderer, *fresh.target, b);
  EXPECT_GE(psnrLogged("toroidal update vs fresh", updated, clean), kSameDb);
  EXPECT_GE(psnrLogged("toroidal update vs reference", updated, reference(*moved.source, moved.source, b)), kMatchDb);
}

INSTANTIATE_TEST_SUITE_P(AllBufferings, ToroidalUpdate,
                         ::testing::Values(Buffering::kSingle, Buffering::kDoubleUploadTwice,
                                           Buffering::kDoubleCopy, Buffering::kStaged),
                         [](const auto& param_info) {
                           std::string n = bufferingName(param_info.param);
                           for (char& c : n)
                             if (c == '-') c = '_';
                           return n;
                         });

TEST(ClipmapRender, StagedUploadsGoThroughTheRingAndDrawAsSingleBuffered) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  Scene staged = makeScene(patternSource(), cam, Buffering::kStaged);
  Scene single = makeScene(staged.source, cam, Buffering::kSingle);
  ASSERT_TRUE(staged.renderer && single.renderer);
  // The stack of `single`, plus the ring: kStagingFrames regions of the
  // default upload budget.
  EXPECT_EQ(staged.renderer->textureBytes().stack, single.renderer->textureBytes().stack);
  EXPECT_EQ(staged.renderer->textureBytes().staging,
            uint64_t(renderer_config::kStagingFrames) * renderer_config::kDefaultUploadTilesPerFrame * 128 * 128 * 4);
  EXPECT_EQ(single.renderer->textureBytes().staging, 0u);
  // The pyramid at once (past the ring: sent directly), then the windows a
  // budget's worth of tiles a frame, as a flight uploads them.
  std::vector<TileKey> stack;
  for (const ClipLevelPlan& l : staged.plan.stack)
    for (int64_t y = l.window.y0; y < l.window.y1; ++y)
      for (int64_t x = l.window.x0; x < l.window.x1; ++x) stack.push_back({l.level, uint32_t(x), uint32_t(y)});
  for (Scene* s : {&staged, &single}) {
    test::loadPlan(*s->renderer, *s->source, s->plan, /*finest_loaded=*/s->plan.pyramid_level);
    for (size_t first = 0; first < stack.size(); first += renderer_config::kDefaultUploadTilesPerFrame) {
      s->renderer->beginFrame();
      for (size_t i = first; i < std::min(stack.size(), first + renderer_config::kDefaultUploadTilesPerFrame); ++i) {
        auto px = std::make_shared<std::vector<uint8_t>>();
        ASSERT_TRUE(s->source->fetch(stack[i], px.get()).ok());
        s->renderer->uploadTile(stack[i], px);
      }
      s->renderer->setResidency(test::fullResidency(s->plan));
      s->renderer->endUploads();
      EXPECT_EQ(s->renderer->lastUploads().unstaged, 0u);
      (void)test::renderFrame(*s->renderer, *s->target, cam);  // the frame that reads the previous tiles
    }
  }
  const auto a = test::renderFrame(*staged.renderer, *staged.target, cam);
  const auto b = test::renderFrame(*single.renderer, *single.target, cam);
  EXPECT_EQ(compareFrames(a, b).max_abs_error, 0);
  EXPECT_GE(psnrLogged("staged vs reference", a, reference(*staged.source, staged.source, cam)), kMatchDb);
}

// Pixels whose ground point lies within `texels` of a tile border of level
// 0 or 1, or of the level-0 window edge: where a seam would show.
std::vector<uint8_t> borderMask(const Camera& cam, uint32_t tile_px, double texels) {
  std::vector<uint8_t> mask(size_t(kViewport.width_px) * kViewport.height_px, 0);
  for (uint32_t y = 0; y < kViewport.height_px; ++y)
    for (uint32_t x = 0; x < kViewport.width_px; ++x) {
      glm::dvec2 hit;
      if (!groundHit(cam, kViewport, x + 0.5, y + 0.5, &hit)) continue;
      for (double period : {double(tile_px), 2.0 * tile_px}) {
        const double dx = std::abs(hit.x - std::round(hit.x / period) * period);
        const double dy = std::abs(hit.y - std::round(hit.y / period) * period);
        if (dx < texels || dy < texels) mask[size_t(y) * kViewport.width_px + x] = 1;
      }
    }
  return mask;
}

TEST(ClipmapRender, NoSeamAtTileAndLevelBorders) {
  CLIPSTREAM_REQUIRE_GL();
  ProceduralSpec spec;  // dark grid lines on every tile border: seams would break them
  spec.width_px = spec.height_px = 4096;
  auto source = makeProceduralSource(spec);
  ASSERT_TRUE(source);
  Camera cam;
  // Over a corner shared by four level-0 tiles and four level-1 tiles, high
  // enough that levels 0, 1 and 2 all appear.
  cam.position = {2048.0 + 3.3, 150.0, 2048.0 + 40.7};
  cam.heading_rad = 0.2;
  cam.pitch_rad = -0.9;
  Scene s = makeScene(source, cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  const auto ref = reference(*s.source, s.source, cam);
  const auto mask = borderMask(cam, spec.tile_px, 3.0);
  size_t masked = 0;
  for (uint8_t m : mask) masked += m;
  ASSERT_GT(masked, mask.size() / 50) << "the view must straddle tile borders";
  EXPECT_GE(psnrLogged("borders vs reference", gpu, ref, &mask), kMatchDb);
  EXPECT_GE(psnrLogged("whole seam view vs reference", gpu, ref), kMatchDb);
}

TEST(ClipmapRender, KeepsTexelPrecisionNearTheFarCornerOfA2To26Texture) {
  CLIPSTREAM_REQUIRE_GL();
  ProceduralSpec spec;  // 2^26 x 2^26
  auto source = makeProceduralSource(spec);
  ASSERT_TRUE(source);
  Camera cam;
  const double side = double(spec.width_px);
  cam.position = {side - 3000.3, 40.0, side - 2500.7};
  cam.heading_rad = 0.4;
  cam.pitch_rad = -0.7;
  Scene s = makeScene(source, cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  const auto ref = reference(*s.source, s.source, cam);
  EXPECT_GT(groundPixels(ref), ref.size() / 16) << "a quarter of the view must be ground";
  EXPECT_GE(psnrLogged("2^26 far corner vs reference", gpu, ref), kMatchDb);
}

// Every slot period: over tiles whose period index (tile / slots) is 3 mod 4
// on both axes, whose usable-map code (1 + 3 + 4 * 3 = 16) is the largest.
TEST(ClipmapRender, DrawsTilesOfEverySlotPeriodAtTheirLevel) {
  CLIPSTREAM_REQUIRE_GL();
  ProceduralSpec spec;
  spec.width_px = spec.height_px = 8192;
  auto source = makeProceduralSource(spec);
  ASSERT_TRUE(source);
  const ClipmapPlan probe = planClipmap(source->geometry(), kViewport, test::obliqueCamera(), {});
  const uint32_t slots = (probe.clip_tiles / 2) * 2 + 2;
  for (int64_t period : {0, 1, 2, 3}) {
    Camera cam = test::obliqueCamera();
    const double centre = (double(period * slots) + slots / 2.0) * spec.tile_px + 0.3;
    cam.position = {centre, 30.0, centre + 60.0};
    cam.heading_rad = 0.0;  // north, over the tiles of this period
    Scene s = makeScene(source, cam);
    ASSERT_TRUE(s.renderer);
    test::loadPlan(*s.renderer, *s.source, s.plan);
    const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
    const auto ref = reference(*s.source, s.source, cam);
    glm::dvec2 hit;
    ASSERT_TRUE(groundHit(cam, kViewport, kViewport.width_px / 2.0, kViewport.height_px - 1.0, &hit));
    EXPECT_EQ(int64_t(hit.x / spec.tile_px) / slots, period) << "the view must be over this period";
    EXPECT_EQ(int64_t(hit.y / spec.tile_px) / slots, period);
    char what[64];
    std::snprintf(what, sizeof what, "slot period %lld vs reference", (long long)period);
    EXPECT_GE(psnrLogged(what, gpu, ref), kMatchDb);
  }
}

// Real imagery: a 2048 x 2048 crop of the Autzen orthophoto the repository
// ships in data/.
TEST(ClipmapRender, MatchesCpuReferenceOnRealImagery) {
  CLIPSTREAM_REQUIRE_GL();
  const std::string path = test::bundledDataPath("autzen.jpg");
  std::vector<uint8_t> full;
  uint32_t w = 0, h = 0;
  ASSERT_TRUE(readImageRgba(path, &full, &w, &h).ok()) << path;
  ASSERT_GE(w, 2048u);
  ASSERT_GE(h, 2048u);
  std::vector<uint8_t> crop(size_t(2048) * 2048 * 4);
  for (uint32_t y = 0; y < 2048; ++y)
    std::copy_n(full.data() + (size_t(y) * w) * 4, size_t(2048) * 4, crop.data() + size_t(y) * 2048 * 4);
  const Camera cam = test::obliqueCamera();
  Scene s = makeScene(makeImageSource(std::move(crop), 2048, 2048, 128), cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  EXPECT_GE(psnrLogged("autzen vs reference", gpu, reference(*s.source, s.source, cam)), kMatchDb);
}

TEST(ClipmapRender, OverlayTintsByLevelWithoutHoles) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  Scene s = makeScene(patternSource(), cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto plain = test::renderFrame(*s.renderer, *s.target, cam);
  s.renderer->setOverlay(Overlay::kLevels);
  const auto tinted = test::renderFrame(*s.renderer, *s.target, cam);
  test::dumpPpm("overlay", tinted, kViewport);
  EXPECT_EQ(groundPixels(plain), groundPixels(tinted));
  EXPECT_LT(psnrLogged("overlay vs plain", plain, tinted), 25.0);
}

// BC1 tiles as another source hands them out, rewritten on the way: decoded
// to RGBA8 (the texels a GPU samples from those blocks), or with the blocks
// of every row mirrored (a misplaced-block bug on purpose).
class Bc1Rewrite final : public TileSource {
 public:
  enum class Mode { kDecode, kMirrorBlocks };
  Bc1Rewrite(std::shared_ptr<TileSource> bc1, Mode mode) : m_bc1(std::move(bc1)), m_mode(mode) {}
  const PyramidGeometry& geometry() const override { return m_bc1->geometry(); }
  TileContent content() const override {
    return m_mode == Mode::kDecode ? TileContent::kRgba8 : TileContent::kBc1;
  }
  Status fetch(const TileKey& key, std::vector<uint8_t>* out) override {
    std::vector<uint8_t> blocks;
    if (Status s = m_bc1->fetch(key, &blocks); !s) return s;
    const uint32_t tp = geometry().tile_px, n = tp / kBc1BlockPx;
    if (m_mode == Mode::kDecode) return decodeBc1Tile(blocks, tp, out);
    *out = blocks;
    for (uint32_t by = 0; by < n; ++by)
      for (uint32_t bx = 0; bx < n; ++bx)
        std::copy_n(blocks.data() + (size_t(by) * n + bx) * kBc1BlockBytes, kBc1BlockBytes,
                    out->data() + (size_t(by) * n + (n - 1 - bx)) * kBc1BlockBytes);
    return okStatus();
  }
  std::string describe() const override { return "bc1-rewrite"; }

 private:
  std::shared_ptr<TileSource> m_bc1;
  Mode m_mode;
};

std::shared_ptr<TileSource> bc1Of(std::shared_ptr<TileSource> rgba8) {
  Status s;
  auto bc1 = makeBc1Source(std::move(rgba8), &s);
  EXPECT_TRUE(bc1) << s.toString();
  return bc1;
}

// Filtering tolerance between the two GPU paths: llvmpipe samples a BC1
// texture through its own decode and filter code, so a texel blend may
// round differently from the RGBA8 path by a step or two.
constexpr int kBc1FilterTolerance = 3;

TEST(ClipmapRender, Bc1FrameMatchesItsBlocksDecodedOnTheCpu) {
  CLIPSTREAM_REQUIRE_GL();
  for (const Camera& cam : {test::obliqueCamera(), test::lookingDown(1024.0, 1024.0, 900.0)}) {
    const auto bc1 = bc1Of(patternSource());
    Scene s = makeScene(bc1, cam);
    ASSERT_TRUE(s.renderer);
    ASSERT_EQ(s.renderer->tileContent(), TileContent::kBc1);
    test::loadPlan(*s.renderer, *s.source, s.plan);
    const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
    // The same blocks decoded on the CPU, drawn by the CPU reference and by
    // the RGBA8 renderer.
    const auto cpu = reference(*bc1, bc1, cam);
    Scene d = makeScene(std::make_shared<Bc1Rewrite>(bc1, Bc1Rewrite::Mode::kDecode), cam);
    ASSERT_TRUE(d.renderer);
    test::loadPlan(*d.renderer, *d.source, d.plan);
    const auto decoded = test::renderFrame(*d.renderer, *d.target, cam);
    test::dumpPpm("bc1_gpu", gpu, kViewport);
    test::dumpPpm("bc1_decoded", decoded, kViewport);
    EXPECT_GT(groundPixels(gpu), gpu.size() / 16) << "a quarter of the view must be ground";
    EXPECT_EQ(groundPixels(gpu), groundPixels(decoded));
    const double db_blocks = psnrLogged("bc1 gpu vs cpu reference of its blocks", gpu, cpu);
    EXPECT_GE(db_blocks, kMatchDb);
    const FrameError e = compareFrames(gpu, decoded);
    std::printf("  bc1 gpu vs the decoded blocks on the rgba8 path: %.2f dB, max abs error %d\n",
                e.psnr_db, e.max_abs_error);
    EXPECT_LE(e.max_abs_error, kBc1FilterTolerance);
    EXPECT_GE(e.psnr_db, kSameDb);
    // Against the original RGBA8 tiles the compression shows: the frame is
    // nearer its blocks than the original, yet no garbage (the pattern's
    // one-texel blue checker at the coarser levels is hard on BC1: 26-30
    // dB here, against 10 dB for misplaced blocks).
    const auto original = reference(*s.source, patternSource(), cam);
    const double db_original = psnrLogged("bc1 gpu vs the rgba8 cpu reference", gpu, original);
    EXPECT_LT(db_original, db_blocks);
    EXPECT_GE(db_original, 24.0);
  }
}

TEST(ClipmapRender, Bc1WithMisplacedBlocksFailsTheReference) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera cam = test::obliqueCamera();
  const auto bc1 = bc1Of(patternSource());
  Scene s = makeScene(std::make_shared<Bc1Rewrite>(bc1, Bc1Rewrite::Mode::kMirrorBlocks), cam);
  ASSERT_TRUE(s.renderer);
  test::loadPlan(*s.renderer, *s.source, s.plan);
  const auto gpu = test::renderFrame(*s.renderer, *s.target, cam);
  Scene d = makeScene(std::make_shared<Bc1Rewrite>(bc1, Bc1Rewrite::Mode::kDecode), cam);
  ASSERT_TRUE(d.renderer);
  test::loadPlan(*d.renderer, *d.source, d.plan);
  const auto decoded = test::renderFrame(*d.renderer, *d.target, cam);
  const FrameError e = compareFrames(gpu, decoded);
  std::printf("  misplaced blocks vs the decoded blocks: %.2f dB, max abs error %d\n", e.psnr_db,
              e.max_abs_error);
  EXPECT_GT(e.max_abs_error, kBc1FilterTolerance);
  EXPECT_LT(psnrLogged("misplaced blocks vs cpu reference", gpu, reference(*bc1, bc1, cam)), kMatchDb);
}

TEST(ClipmapRender, Bc1PyramidTileThatCannotBeReadIsFilledFromItsParent) {
  CLIPSTREAM_REQUIRE_GL();
  // High above the middle: the whole view is drawn from the pyramid.
  const Camera cam = test::lookingDown(1024.0, 1024.0, 600.0);
  const auto bc1 = bc1Of(patternSource());
  auto draw = [&](std::shared_ptr<TileSource> source, const TileKey& missing) {
    Scene s = makeScene(source, cam);
    EXPECT_TRUE(s.renderer);
    if (!s.renderer) return std::vector<uint8_t>{};
    s.renderer->beginFrame();
    s.renderer->loadPyramid([&](const TileKey& key) -> std::shared_ptr<const std::vector<uint8_t>> {
      if (key == missing) return nullptr;
      auto px = std::make_shared<std::vector<uint8_t>>();
      if (!source->fetch(key, px.get())) return nullptr;
      return px;
    });
    s.renderer->setResidency(test::fullResidency(s.plan, s.plan.pyramid_level));
    s.renderer->endUploads();
    s.renderer->beginFrame();
    s.renderer->endUploads();
    return test::renderFrame(*s.renderer, *s.target, cam);
  };
  const ClipmapPlan plan = planClipmap(bc1->geometry(), kViewport, cam, {});
  const TileKey missing{plan.pyramid_level, 1, 1};
  const TileKey none{~0u, 0, 0};
  const auto decoded_source = std::make_shared<Bc1Rewrite>(bc1, Bc1Rewrite::Mode::kDecode);
  const auto whole = draw(bc1, none);
  const auto filled = draw(bc1, missing);
  const auto filled_rgba8 = draw(decoded_source, missing);
  ASSERT_FALSE(filled.empty());
  EXPECT_GT(compareFrames(filled, whole).max_abs_error, 20) << "the missing tile must be in view";
  EXPECT_EQ(countHolePixels(filled, whole), 0u);
  // The RGBA8 renderer fills the same hole with a GPU blit of the parent;
  // the BC1 one filters on the CPU and encodes again.
  EXPECT_GE(psnrLogged("bc1 fill vs rgba8 fill", filled, filled_rgba8), kMatchDb);
}

}  // namespace
}  // namespace clipstream

namespace clipstream {
namespace {

// On Mesa's software rasterizer the heap keeps what a frame freed: 8 MiB
// of 64 KiB blocks (llvmpipe's bin size) freed at the top of the heap do
// not shrink it. On any other renderer the call must leave glibc alone.
TEST(SoftwareGlHeap, FreedFrameMemoryStaysInTheHeap) {
  CLIPSTREAM_REQUIRE_GL();
  const std::string renderer = currentGlDescription();
  const bool software = renderer.find("llvmpipe") != std::string::npos || renderer.find("softpipe") != std::string::npos;
  EXPECT_EQ(keepHeapForSoftwareGl(), software) << renderer;
  if (!software) GTEST_SKIP() << "not a software rasterizer: " << renderer;
  std::vector<void*> blocks;
  for (int i = 0; i < 128; ++i) {
    blocks.push_back(std::malloc(65536));
    std::memset(blocks.back(), 1, 65536);  // touched, as bins are
  }
  const char* top = static_cast<const char*>(sbrk(0));
  for (auto it = blocks.rbegin(); it != blocks.rend(); ++it) std::free(*it);
  EXPECT_EQ(static_cast<const char*>(sbrk(0)), top) << "the heap shrank after the blocks were freed";
}

}  // namespace
}  // namespace clipstream
