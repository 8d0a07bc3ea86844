// Tile read throughput of a real store: open cost, readTile() (read +
// checksum + zstd + predictor) with 1..N threads, and verifyAll(). The
// store is built from an image (level l = nearest subsample by 2^l, which
// is enough for a read benchmark) in a temporary folder and removed after.
// Best of N runs, warm page cache. Prints tab-separated tables; --tsv FILE
// also writes the reads' table into FILE, --open-tsv FILE the open's
// (docs/data/store_read.tsv, store_open.tsv).
//
//   store_read_bench [--runs N] [--threads N] [--tsv FILE] [--open-tsv FILE] [IMAGE]
#include <clipstream/store/tile_store.h>

#include <OpenImageIO/imageio.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "tsv_out.h"

namespace {

using namespace clipstream;
using Clock = std::chrono::steady_clock;

double seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// Writes a store of the image to store_path in geometry g: level l is the
// nearest subsample by 2^l. False when any step fails.
bool writeSubsampledStore(const std::vector<uint8_t>& image, uint64_t width, uint64_t height,
                          const PyramidGeometry& g, const std::string& store_path) {
  WriterOptions options;  // zstd 1 + left-delta: the defaults
  options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  if (!TileStoreWriter::create(store_path, g, options, &writer)) return false;
  std::vector<uint8_t> tile(g.tileBytes());
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t ty = 0; ty < g.levels[l].tiles_y; ++ty) {
      for (uint32_t tx = 0; tx < g.levels[l].tiles_x; ++tx) {
        for (uint32_t y = 0; y < g.tile_px; ++y) {
          const uint64_t ly = std::min<uint64_t>(uint64_t(ty) * g.tile_px + y, g.levels[l].height_px - 1);
          for (uint32_t x = 0; x < g.tile_px; ++x) {
            const uint64_t lx = std::min<uint64_t>(uint64_t(tx) * g.tile_px + x, g.levels[l].width_px - 1);
            const uint64_t sx = std::min(width - 1, lx << l), sy = std::min(height - 1, ly << l);
            std::memcpy(&tile[(size_t(y) * g.tile_px + x) * 3], &image[(sy * width + sx) * 3], 3);
          }
        }
        EncodedTile encoded;
        if (!encodeTile(g, options.encoding, {l, tx, ty}, tile, &encoded) ||
            !writer->write(std::move(encoded))) {
          return false;
        }
      }
    }
  }
  return bool(writer->finish());
}

// Best of `runs` times to readTile() every key with `threads` threads, each
// run on a freshly opened reader; false when an open or a read fails.
bool bestReadTileS(const std::string& store_path, const std::vector<TileKey>& keys, unsigned threads,
                   int runs, double* best_s) {
  *best_s = 1e30;
  for (int run = 0; run < runs; ++run) {
    std::unique_ptr<TileStoreReader> reader;  // fresh: index pages load inside the timing
    if (!TileStoreReader::open(store_path, &reader)) return false;
    std::atomic<size_t> next{0};
    std::atomic<bool> failed{false};
    const auto start = Clock::now();
    std::vector<std::thread> pool;
    for (unsigned t = 0; t < threads; ++t) {
      pool.emplace_back([&] {
        std::vector<uint8_t> pixels;
        for (size_t i; (i = next.fetch_add(1)) < keys.size();) {
          if (!reader->readTile(keys[i], &pixels)) failed = true;
        }
      });
    }
    for (auto& thread : pool) thread.join();
    *best_s = std::min(*best_s, seconds(start, Clock::now()));
    if (failed) return false;
  }
  return true;
}

// Best of `runs` times of verifyAll() with `threads` threads, each run on a
// freshly opened reader; false when an open or the verification fails.
bool bestVerifyAllS(const std::string& store_path, unsigned threads, int runs, double* best_s) {
  *best_s = 1e30;
  for (int run = 0; run < runs; ++run) {
    std::unique_ptr<TileStoreReader> reader;
    if (!TileStoreReader::open(store_path, &reader)) return false;
    const auto start = Clock::now();
    std::vector<TileStoreReader::Problem> problems;
    if (!reader->verifyAll(&problems, 10, {}, threads)) return false;
    *best_s = std::min(*best_s, seconds(start, Clock::now()));
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut reads_table(bench::takeOption(&argc, argv, "--tsv"));
  bench::TsvOut open_table(bench::takeOption(&argc, argv, "--open-tsv"));
  if (!reads_table.ok() || !open_table.ok()) return 1;
  int runs = 3;
  unsigned max_threads = 2;
  std::string path = std::string(CLIPSTREAM_STORE_BENCH_DATA) + "/fg_globe_colors_8192x4096.jpg";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
      runs = std::max(1, std::atoi(argv[++i]));
    } else if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      max_threads = unsigned(std::max(1, std::atoi(argv[++i])));
    } else {
      path = argv[i];
    }
  }
  auto input = OIIO::ImageInput::open(path);
  if (!input) {
    std::fprintf(stderr, "cannot open %s\n", path.c_str());
    return 1;
  }
  const uint64_t width = uint64_t(input->spec().width), height = uint64_t(input->spec().height);
  std::vector<uint8_t> image(width * height * 3);
  if (!input->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, image.data())) return 1;

  PyramidGeometry g;
  if (!makePyramidGeometry(width, height, 128, PixelFormat::kRGB8, &g)) return 1;
  const auto dir = std::filesystem::temp_directory_path() /
                   ("clipstream_store_read_bench_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string store_path = (dir / "bench.cst").string();
  if (!writeSubsampledStore(image, width, height, g, store_path)) return 1;

  std::vector<TileKey> keys;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});
    }
  }
  const double decoded_mb = double(keys.size()) * double(g.tileBytes()) / 1e6;

  double best_open_s = 1e30;
  uint64_t open_bytes = 0, file_bytes = 0;
  for (int run = 0; run < runs; ++run) {
    std::unique_ptr<TileStoreReader> reader;
    const auto start = Clock::now();
    if (!TileStoreReader::open(store_path, &reader)) return 1;
    best_open_s = std::min(best_open_s, seconds(start, Clock::now()));
    open_bytes = reader->bytesRead();
    file_bytes = reader->info().file_bytes;
  }
  open_table.row("store\ttiles\tfile_MB\topen_ms\topen_bytes_read\n");
  open_table.row("%s\t%zu\t%.1f\t%.3f\t%llu\n", path.substr(path.find_last_of('/') + 1).c_str(),
              keys.size(), double(file_bytes) / 1e6, best_open_s * 1e3,
              static_cast<unsigned long long>(open_bytes));

  std::printf("\n");
  reads_table.row("operation\tthreads\ttiles_per_s\tdecoded_MB_per_s\n");
  for (unsigned threads = 1; threads <= max_threads; ++threads) {
    double best_s = 0.0;
    if (!bestReadTileS(store_path, keys, threads, runs, &best_s)) return 1;
    reads_table.row("readTile\t%u\t%.0f\t%.0f\n", threads, double(keys.size()) / best_s, decoded_mb / best_s);
  }
  for (unsigned threads = 1; threads <= max_threads; ++threads) {
    double best_s = 0.0;
    if (!bestVerifyAllS(store_path, threads, runs, &best_s)) return 1;
    reads_table.row("verifyAll\t%u\t%.0f\t%.0f\n", threads, double(keys.size()) / best_s, decoded_mb / best_s);
  }
  std::filesystem::remove_all(dir);
  return open_table.commit() && reads_table.commit() ? 0 : 1;
}
