// Shared helpers for the renderer tests: a headless context kept for the
// whole binary, synthetic images and "load everything" uploads.
#pragma once

#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/reference.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/tile_source.h>

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

// A fresh directory in the temp directory, removed with its contents by the
// destructor.
struct TempDir {
  std::string path;
  explicit TempDir(const std::string& name);
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
};

// Writes every tile of `source` (RGBA8) into a new tile store at `path` with
// the store writer's default encoding (zstd, left-delta predictor), no fsync.
Status writeStoreFromSource(TileSource& source, const std::string& path);

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
