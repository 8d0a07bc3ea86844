// Tile pipeline throughput: read + verify + decode + convert through the
// store source with 1 and 2 workers, against raw single-thread zstd
// decompression of the same payloads. The separate decode and convert stage
// rows are the unfused path (decodeTile, then convertToRgba8); the store
// source uses decodeTileRgba8 (also timed as a stage). Builds its own store (synthetic
// pixels, store writer) in the temp directory; the file is in the page
// cache, so "read" is a positional copy from memory.
//
// Usage: bench_streamer_throughput [side_px=4096] [repeats=5] [--tsv FILE]
// Prints a tab-separated table; --tsv FILE also writes it into FILE
// (docs/data/streamer_throughput.tsv).
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/tile_source.h>

#include "../streamer/src/convert.h"

#include <zstd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <thread>
#include <vector>

#include "tsv_out.h"

using namespace clipstream;

namespace {

double nowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Photo-like synthetic content: smooth gradients plus mild hashed noise, so
// zstd + left-delta compress it about as well as an orthophoto.
void fillTile(const PyramidGeometry& g, const TileKey& key, std::vector<uint8_t>* pixels) {
  const uint32_t t = g.tile_px;
  pixels->resize(g.tileBytes());
  for (uint32_t y = 0; y < t; ++y)
    for (uint32_t x = 0; x < t; ++x) {
      const uint64_t gx = uint64_t(key.x) * t + x, gy = uint64_t(key.y) * t + y;
      uint32_t h = uint32_t(gx * 2654435761u ^ gy * 2246822519u ^ key.level * 3266489917u);
      h ^= h >> 15;
      uint8_t* p = &(*pixels)[(size_t(y) * t + x) * 3];
      p[0] = uint8_t((gx >> 3) + (h & 7));
      p[1] = uint8_t((gy >> 3) + ((h >> 3) & 7));
      p[2] = uint8_t(((gx + gy) >> 4) + ((h >> 6) & 7));
    }
}

// Writes the bench's store of side x side synthetic pixels to path; false
// after printing why it cannot.
bool writeBenchStore(const std::string& path, const PyramidGeometry& g) {
  WriterOptions options;
  options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  Status s = TileStoreWriter::create(path, g, options, &writer);
  std::vector<uint8_t> pixels;
  for (uint32_t l = 0; l < g.levelCount() && s; ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y && s; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x && s; ++x) {
        fillTile(g, {l, x, y}, &pixels);
        EncodedTile e;
        s = encodeTile(g, options.encoding, {l, x, y}, pixels, &e);
        if (s) s = writer->write(std::move(e));
      }
  if (s) s = writer->finish();
  if (!s) {
    std::fprintf(stderr, "cannot write bench store: %s\n", s.toString().c_str());
    return false;
  }
  return true;
}

// Reads every tile of the store raw: all keys, the non-constant payloads and
// the stored bytes. False when a tile does not read.
bool readAllRaw(const TileStoreReader& reader, std::vector<TileKey>* keys, std::vector<RawTile>* raws,
                uint64_t* stored) {
  const PyramidGeometry& g = reader.geometry();
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        RawTile raw;
        if (!reader.readRaw({l, x, y}, &raw)) return false;
        keys->push_back({l, x, y});
        *stored += raw.payload.size();
        if (!raw.payload.empty()) raws->push_back(std::move(raw));
      }
  return true;
}

// The store source's whole path: every key fetched (read, verify, decode,
// convert to RGBA8) by `threads` threads taking keys in turn.
void fetchAll(TileSource& source, const std::vector<TileKey>& keys, unsigned threads) {
  std::atomic<size_t> next{0};
  std::atomic<size_t> failures{0};
  std::vector<std::thread> pool;
  for (unsigned i = 0; i < threads; ++i)
    pool.emplace_back([&] {
      std::vector<uint8_t> rgba;
      for (size_t k; (k = next.fetch_add(1)) < keys.size();)
        if (!source.fetch(keys[k], &rgba)) failures++;
    });
  for (std::thread& t : pool) t.join();
  if (failures) std::fprintf(stderr, "%zu fetches failed\n", failures.load());
}

struct Measure {
  const char* name;
  unsigned threads;
  size_t tiles;
  std::function<void()> body;
  double best_s = 1e30;
};

// Runs every body `repeats` times, interleaved, keeping each one's best time.
void runInterleaved(int repeats, std::vector<Measure>* measures) {
  for (int r = 0; r < repeats; ++r)
    for (Measure& m : *measures) {
      const double t0 = nowS();
      m.body();
      m.best_s = std::min(m.best_s, nowS() - t0);
    }
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  const uint64_t side = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 4096;
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 5;
  const std::string path =
      (std::filesystem::temp_directory_path() / "clipstream_bench_throughput.cts").string();

  PyramidGeometry g;
  if (!makePyramidGeometry(side, side, 128, PixelFormat::kRGB8, &g)) return 1;
  if (!writeBenchStore(path, g)) return 1;
  std::unique_ptr<TileStoreReader> reader;
  Status s = TileStoreReader::open(path, &reader);
  if (!s) return 1;
  std::vector<TileKey> keys;
  std::vector<RawTile> raws;
  uint64_t stored = 0;
  if (!readAllRaw(*reader, &keys, &raws, &stored)) return 1;
  const double tile_mb = double(g.tileBytes()) / (1024.0 * 1024.0);

  Status open_status;
  auto source = openStoreSource(path, &open_status);
  if (!source) return 1;

  // Every measurement as a body; the repeats run them interleaved (raw
  // zstd, each stage, the pipeline, then again) so that load from other
  // processes drifting during the run hits all of them alike. Best of N each.
  std::vector<uint8_t> zstd_out(g.tileBytes());
  ZSTD_DCtx* dctx = ZSTD_createDCtx();
  std::vector<uint8_t> decoded(g.tileBytes());
  std::vector<uint8_t> rgba_out(size_t(g.tile_px) * g.tile_px * 4);
  std::vector<Measure> measures = {
      // Raw zstd: decompress every non-constant payload on one thread.
      {"raw_zstd", 1, raws.size(),
       [&] {
         for (const RawTile& raw : raws)
           ZSTD_decompressDCtx(dctx, zstd_out.data(), zstd_out.size(), raw.payload.data(),
                               raw.payload.size());
       }},
      // Where a single-thread fetch spends its time: each stage alone.
      {"stage:readRaw(pread+xxh3)", 1, keys.size(),
       [&] {
         RawTile raw;
         for (const TileKey& k : keys) (void)reader->readRaw(k, &raw);
       }},
      // The unfused path: decodeTile (zstd + in-place predictor inverse) ...
      {"stage:decode(zstd+predictor)", 1, raws.size(),
       [&] {
         for (const RawTile& raw : raws) (void)reader->decode(raw, decoded);
       }},
      // ... then the streamer's RGB8 -> RGBA8 conversion.
      {"stage:convert(RGB8->RGBA8)", 1, raws.size(),
       [&] {
         for (size_t i = 0; i < raws.size(); ++i)
           (void)convertToRgba8(g.format, decoded, rgba_out.data(), size_t(g.tile_px) * g.tile_px);
       }},
      // The fused path the store source uses: zstd, then predictor inverse
      // and RGB8 -> RGBA8 in one pass.
      {"stage:decodeTileRgba8(zstd+fused_predictor_convert)", 1, raws.size(),
       [&] {
         for (const RawTile& raw : raws)
           (void)decodeTileRgba8(g, reader->info().encoding, raw, rgba_out);
       }},
      {"read_verify_decode_rgba8", 1, keys.size(), [&] { fetchAll(*source, keys, 1); }},
      {"read_verify_decode_rgba8", 2, keys.size(), [&] { fetchAll(*source, keys, 2); }},
  };
  runInterleaved(repeats, &measures);
  ZSTD_freeDCtx(dctx);

  const double zstd_tiles_s = double(raws.size()) / measures[0].best_s;
  std::printf("# store %llux%llu RGB8 tile 128: %zu tiles (%zu non-constant), %.1f MiB stored, "
              "%.2fx compression; best of %d, interleaved\n",
              (unsigned long long)side, (unsigned long long)side, keys.size(), raws.size(),
              double(stored) / (1024.0 * 1024.0),
              double(raws.size()) * double(g.tileBytes()) / double(stored), repeats);
  table.row("pipeline\tthreads\ttiles\tbest_s\ttiles_per_s\tdecoded_mib_per_s\tper_thread_vs_zstd_%%\n");
  for (const Measure& m : measures) {
    const double tiles_s = double(m.tiles) / m.best_s;
    table.row("%s\t%u\t%zu\t%.4f\t%.0f\t%.1f\t%.1f\n", m.name, m.threads, m.tiles, m.best_s,
                tiles_s, tiles_s * tile_mb, 100.0 * tiles_s / m.threads / zstd_tiles_s);
  }
  std::filesystem::remove(path);
  return table.commit() ? 0 : 1;
}
