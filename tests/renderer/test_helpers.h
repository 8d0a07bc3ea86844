// Shared helpers for the renderer tests: a headless context kept for the
// whole binary, synthetic images and "load everything" uploads.
#pragma once

#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/reference.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/planner.h>

#include <memory>
#include <string>
#include <vector>

namespace clipstream::test {

// The process-wide headless context, or null (with the reason in *why).
HeadlessContext* sharedContext(std::string* why);

// Skips the calling test (GTEST_SKIP) when no headless GL context exists.
#define CLIPSTREAM_REQUIRE_GL()                                               \
  do {                                                                        \
    std::string require_gl_why;                                               \
    if (::clipstream::test::sharedContext(&require_gl_why) == nullptr)        \
      GTEST_SKIP() << require_gl_why;                                         \
  } while (0)

// A w x h RGBA image whose texels encode their position: smooth waves plus
// an 8-texel checker, so any misplaced tile or texel shows.
std::vector<uint8_t> patternImage(uint32_t width_px, uint32_t height_px);

// Uploads, synchronously, every tile of every level >= pyramid_level and the
// whole window of every stack level in `plan`, and marks them resident.
// Stack levels finer than `finest_loaded` are left out (not resident).
void loadPlan(ClipmapRenderer& renderer, TileSource& source, const ClipmapPlan& plan,
              uint32_t finest_loaded = 0);

// Residency of `plan` as the streamer would report it with every window tile
// of levels >= finest_loaded resident.
std::vector<LevelResidency> fullResidency(const ClipmapPlan& plan, uint32_t finest_loaded = 0);

// Clears, draws and reads back one frame.
std::vector<uint8_t> renderFrame(ClipmapRenderer& renderer, OffscreenTarget& target,
                                 const Camera& camera);

// Writes a PPM to $CLIPSTREAM_TEST_DUMP/<name>.ppm when that variable is set
// (for looking at a failing comparison); does nothing otherwise.
void dumpPpm(const std::string& name, const std::vector<uint8_t>& rgba, const Viewport& vp);

}  // namespace clipstream::test
