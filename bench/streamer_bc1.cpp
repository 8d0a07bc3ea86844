// BC1 encoding: stb_dxt's CPU time per tile (what a loader thread spends in
// makeBc1Source) and the error it leaves, in its normal and high-quality
// modes, over procedural tiles of every level of a 2^26 texture and, when
// given, the tiles of a store.
//
//   bench_streamer_bc1 [STORE] [--repeats 5] [--tsv FILE]
// Prints a tab-separated table; --tsv FILE also writes it into FILE
// (docs/data/streamer_bc1.tsv).
#include <clipstream/streamer/bc1.h>
#include <clipstream/streamer/tile_source.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "tsv_out.h"

using namespace clipstream;

namespace {

double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

// Up to `count` tiles spread over every level of the source.
[[noreturn]] void fail(const Status& s) {
  std::fprintf(stderr, "bench_streamer_bc1: %s\n", s.toString().c_str());
  std::exit(1);
}

std::vector<std::vector<uint8_t>> sampleTiles(TileSource& source, size_t count) {
  const PyramidGeometry& g = source.geometry();
  std::vector<std::vector<uint8_t>> tiles;
  const size_t per_level = std::max<size_t>(1, count / g.levelCount());
  for (uint32_t l = 0; l < g.levelCount() && tiles.size() < count; ++l) {
    const LevelInfo& info = g.levels[l];
    for (size_t i = 0; i < per_level && tiles.size() < count; ++i) {
      const TileKey key{l, uint32_t((i * 7919 + l) % info.tiles_x), uint32_t((i * 104729 + 3 * l) % info.tiles_y)};
      std::vector<uint8_t> rgba;
      if (source.fetch(key, &rgba).ok()) tiles.push_back(std::move(rgba));
    }
  }
  return tiles;
}

void run(const char* name, TileSource& source, int repeats, bench::TsvOut& table) {
  const uint32_t tp = source.geometry().tile_px;
  const auto tiles = sampleTiles(source, 96);
  for (bool hq : {false, true}) {
    double best = 1e30, se = 0.0;
    size_t n = 0;
    int max_err = 0;
    std::vector<uint8_t> blocks, decoded;
    for (int r = 0; r < repeats; ++r) {
      const double t0 = threadCpuMs();
      for (const auto& t : tiles) {
        if (Status s = encodeBc1Tile(t, tp, &blocks, hq); !s.ok()) fail(s);
      }
      best = std::min(best, (threadCpuMs() - t0) / double(tiles.size()));
    }
    for (const auto& t : tiles) {
      if (Status s = encodeBc1Tile(t, tp, &blocks, hq); !s.ok()) fail(s);
      if (Status s = decodeBc1Tile(blocks, tp, &decoded); !s.ok()) fail(s);
      for (size_t i = 0; i < t.size(); ++i) {
        if (i % 4 == 3) continue;
        const int d = int(t[i]) - int(decoded[i]);
        se += double(d) * d;
        max_err = std::max(max_err, std::abs(d));
        ++n;
      }
    }
    const double psnr = se == 0.0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 * double(n) / se);
    table.row("%s\t%s\t%zu\t%.3f\t%.2f\t%d\n", name, hq ? "high-quality" : "normal", tiles.size(), best, psnr,
                max_err);
  }
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  std::string store;
  int repeats = 5;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--repeats") && i + 1 < argc) repeats = std::max(1, std::atoi(argv[++i]));
    else store = argv[i];
  }
  std::printf("# stb_dxt BC1, thread CPU time per tile (best of %d passes), PSNR over RGB of the decoded tiles\n",
              repeats);
  table.row("source\tmode\ttiles\tencode_ms_per_tile\tpsnr_db\tmax_abs_error\n");
  ProceduralSpec spec;
  auto procedural = makeProceduralSource(spec);
  run("procedural 2^26", *procedural, repeats, table);
  if (!store.empty()) {
    Status s;
    auto source = openStoreSource(store, &s);
    if (!source) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return 1;
    }
    run(store.c_str(), *source, repeats, table);
  }
  return table.commit() ? 0 : 1;
}
