// The GL test helpers the renderer and evaluation suites share: a headless
// context kept for the whole binary, "load everything" uploads, frame
// readback and dumps, and damaged stores. Temporary directories, synthetic
// images and stores, cameras and data paths come from the test support
// library (tests/support, clipstream/testing/).
//
// Thread rule: the test's main thread (the one whose GL context is current).
#pragma once

#include <clipstream/renderer/gl_context.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/temp_dir.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/eval/reference.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/tile_source.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

namespace clipstream::test {

// The process-wide headless context, or null (with the reason in *why).
HeadlessContext* sharedContext(std::string* why);

// Whether a missing GL context fails a GL test instead of skipping it: the
// environment's CLIPSTREAM_REQUIRE_GL set and not "0" (the test command sets
// it, so a CI machine that lost its context cannot pass by skipping).
bool glRequired();

// Skips the calling test (GTEST_SKIP) when no headless GL context exists,
// or fails it when glRequired().
#define CLIPSTREAM_REQUIRE_GL()                                                             \
  do {                                                                                      \
    std::string require_gl_why;                                                             \
    if (::clipstream::test::sharedContext(&require_gl_why) == nullptr) {                    \
      if (::clipstream::test::glRequired())                                                 \
        GTEST_FAIL() << "no GL context, and CLIPSTREAM_REQUIRE_GL is set: " << require_gl_why; \
      GTEST_SKIP() << require_gl_why;                                                       \
    }                                                                                       \
  } while (0)


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

// The crack test of a terrain frame: pixels whose ray meets the plane
// y = `lowest` (world units, below every ground of the scene) with its
// (x, z) inside [lo, hi]^2, yet show the background colour. Terrain is
// above that plane everywhere, so such a ray met it first: each is a crack
// or a hole. *ground (optional) receives the pixels that show anything
// but the background; *marked (optional) a copy of the frame with the
// cracks painted red, for dumpPpm(). With `highest` (above every ground),
// only rays that also cross y = highest inside the square count: a camera
// outside the square sees under its edge, where no ground is drawn.
size_t terrainCracks(const std::vector<uint8_t>& rgba, const Camera& camera, const Viewport& viewport,
                     double lowest, double lo, double hi, size_t* ground = nullptr,
                     std::vector<uint8_t>* marked = nullptr, double highest = NAN);

// Writes a PPM to $CLIPSTREAM_TEST_DUMP/<name>.ppm when that variable is set
// (for looking at a failing comparison); does nothing otherwise.
void dumpPpm(const std::string& name, const std::vector<uint8_t>& rgba, const Viewport& vp);

// How damageTilePayload() spoils a tile's payload on disk. Either way the
// payload checksum in the index no longer matches, which is what a reader
// must notice; the two kinds differ in what a reader that skipped the
// checksum would see.
enum class PayloadDamage {
  kBreakFrame,    // the zstd frame header is overwritten: nothing decodes
  kStillDecodes,  // one byte flipped where the frame still decodes, to wrong pixels
};

// Damages tile `key`'s payload inside the store file at `path` in place (the
// file keeps its size and every other byte). Checks that the damage is of
// the asked kind by decoding the damaged bytes without the checksum.
// kInvalidArgument for a constant tile (it has no payload) or when no byte
// of the payload can be flipped that way.
Status damageTilePayload(const std::string& path, const TileKey& key, PayloadDamage damage);

}  // namespace clipstream::test
