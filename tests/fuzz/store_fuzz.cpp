// libFuzzer driver for TileStoreReader: opens a mutated store and reads,
// locates, verifies and decodes every tile. Built only with
// -DCLIPSTREAM_FUZZ=ON (clang); scripts/test.sh runs it for a fixed time as
// a regression guard (docs/cli.md, "Fuzzing"); see docs/tile-store.md for
// the format.
//
// Input: one control byte, then the store bytes (store_seeds.h: bit 0 of
// the control byte re-seals the mutated bytes).
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./store_fuzz -runs=0   # write seed stores
//   ./store_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"
#include "store_seeds.h"

#include <clipstream/store/tile_store.h>

#include <cstdint>
#include <string>
#include <vector>

using namespace clipstream;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = fuzz::seedDir()) fuzz::writeSeeds(dir);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  std::vector<uint8_t> bytes(data + 1, data + size);
  if (data[0] & 1) fuzz::reseal(bytes);
  static const std::string path = fuzz::scratchPath("store.cst");
  fuzz::writeFile(path, bytes.data(), bytes.size());

  std::unique_ptr<TileStoreReader> reader;
  if (!TileStoreReader::open(path, &reader)) return 0;
  const PyramidGeometry& g = reader->geometry();
  // Keep each run short: skip pathological tile sizes' pixel work.
  if (g.tileBytes() > (size_t(4) << 20)) return 0;
  std::vector<LevelStats> stats;
  (void)reader->levelStats(&stats);
  std::vector<uint8_t> pixels;
  uint64_t budget = 4096;  // tile reads per input
  for (uint32_t l = 0; l < g.levelCount() && budget > 0; ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y && budget > 0; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x && budget > 0; ++x, --budget) {
        TileLocation location;
        (void)reader->locate({l, x, y}, &location);
        (void)reader->readTile({l, x, y}, &pixels);
      }
    }
  }
  uint64_t tiles = 0;
  for (const LevelInfo& level : g.levels) tiles += uint64_t(level.tiles_x) * level.tiles_y;
  if (tiles <= 4096) {
    std::vector<TileStoreReader::Problem> problems;
    (void)reader->verifyAll(&problems, 10, {}, 1);
  }
  return 0;
}
