// Tile pipeline throughput: read + verify + decode + convert through the
// store source with 1 and 2 workers, against raw single-thread zstd
// decompression of the same payloads. Builds its own store (synthetic
// pixels, store writer) in the temp directory; the file is in the page
// cache, so "read" is a positional copy from memory.
//
// Usage: bench_streamer_throughput [side_px=4096] [repeats=5]
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

}  // namespace

int main(int argc, char** argv) {
  const uint64_t side = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 4096;
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 5;
  const std::string path =
      (std::filesystem::temp_directory_path() / "clipstream_bench_throughput.cts").string();

  PyramidGeometry g;
  if (!makePyramidGeometry(side, side, 128, PixelFormat::kRGB8, &g)) return 1;
  {
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
      return 1;
    }
  }
  std::unique_ptr<TileStoreReader> reader;
  Status s = TileStoreReader::open(path, &reader);
  if (!s) return 1;
  std::vector<TileKey> keys;
  std::vector<RawTile> raws;
  uint64_t stored = 0;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        RawTile raw;
        if (!reader->readRaw({l, x, y}, &raw)) return 1;
        keys.push_back({l, x, y});
        stored += raw.payload.size();
        if (!raw.payload.empty()) raws.push_back(std::move(raw));
      }
  const double tile_mb = double(g.tileBytes()) / (1024.0 * 1024.0);

  // Raw zstd: decompress every non-constant payload on one thread.
  double zstd_best = 1e30;
  {
    std::vector<uint8_t> out(g.tileBytes());
    ZSTD_DCtx* dctx = ZSTD_createDCtx();
    for (int r = 0; r < repeats; ++r) {
      const double t0 = nowS();
      for (const RawTile& raw : raws)
        ZSTD_decompressDCtx(dctx, out.data(), out.size(), raw.payload.data(), raw.payload.size());
      zstd_best = std::min(zstd_best, nowS() - t0);
    }
    ZSTD_freeDCtx(dctx);
  }
  const double zstd_tiles_s = double(raws.size()) / zstd_best;

  // Where a single-thread fetch spends its time: each stage alone.
  auto bestOf = [&](const std::function<void()>& body) {
    double best = 1e30;
    for (int r = 0; r < repeats; ++r) {
      const double t0 = nowS();
      body();
      best = std::min(best, nowS() - t0);
    }
    return best;
  };
  const double read_s = bestOf([&] {
    RawTile raw;
    for (const TileKey& k : keys) (void)reader->readRaw(k, &raw);
  });
  std::vector<uint8_t> decoded(g.tileBytes());
  const double decode_s = bestOf([&] {
    for (const RawTile& raw : raws) (void)reader->decode(raw, decoded);
  });
  std::vector<uint8_t> rgba_out(size_t(g.tile_px) * g.tile_px * 4);
  const double convert_s = bestOf([&] {
    for (size_t i = 0; i < raws.size(); ++i)
      (void)convertToRgba8(g.format, decoded, rgba_out.data(), size_t(g.tile_px) * g.tile_px);
  });

  Status open_status;
  auto source = openStoreSource(path, &open_status);
  if (!source) return 1;
  std::printf("# store %llux%llu RGB8 tile 128: %zu tiles (%zu non-constant), %.1f MiB stored, "
              "%.2fx compression; best of %d\n",
              (unsigned long long)side, (unsigned long long)side, keys.size(), raws.size(),
              double(stored) / (1024.0 * 1024.0),
              double(raws.size()) * double(g.tileBytes()) / double(stored), repeats);
  std::printf("pipeline\tthreads\ttiles\tbest_s\ttiles_per_s\tdecoded_MiB_per_s\tper_thread_vs_zstd_%%\n");
  std::printf("raw_zstd\t1\t%zu\t%.4f\t%.0f\t%.1f\t100.0\n", raws.size(), zstd_best, zstd_tiles_s,
              zstd_tiles_s * tile_mb);
  auto stageRow = [&](const char* name, double secs, size_t n) {
    const double tiles_s = double(n) / secs;
    std::printf("%s\t1\t%zu\t%.4f\t%.0f\t%.1f\t%.1f\n", name, n, secs, tiles_s, tiles_s * tile_mb,
                100.0 * tiles_s / zstd_tiles_s);
  };
  stageRow("stage:readRaw(pread+xxh3)", read_s, keys.size());
  stageRow("stage:decode(zstd+predictor)", decode_s, raws.size());
  stageRow("stage:convert(RGB8->RGBA8)", convert_s, raws.size());
  for (unsigned threads : {1u, 2u}) {
    double best = 1e30;
    for (int r = 0; r < repeats; ++r) {
      std::atomic<size_t> next{0};
      std::atomic<size_t> failures{0};
      const double t0 = nowS();
      std::vector<std::thread> pool;
      for (unsigned i = 0; i < threads; ++i)
        pool.emplace_back([&] {
          std::vector<uint8_t> rgba;
          for (size_t k; (k = next.fetch_add(1)) < keys.size();)
            if (!source->fetch(keys[k], &rgba)) failures++;
        });
      for (std::thread& t : pool) t.join();
      best = std::min(best, nowS() - t0);
      if (failures) std::fprintf(stderr, "%zu fetches failed\n", failures.load());
    }
    const double tiles_s = double(keys.size()) / best;
    std::printf("read_verify_decode_rgba8\t%u\t%zu\t%.4f\t%.0f\t%.1f\t%.1f\n", threads, keys.size(),
                best, tiles_s, tiles_s * tile_mb, 100.0 * tiles_s / threads / zstd_tiles_s);
  }
  std::filesystem::remove(path);
  return 0;
}
