// The decode floor of a tiling run: reads an image top to bottom in
// strips of 128 full-width rows through the tiler's image source (the same
// reader and conversion clipstream-tile uses) and does nothing else. Prints
// one tab-separated line: decoder, threads, wall seconds, CPU seconds,
// megapixels per second. scripts/bench_tile.sh compares the tiler's time
// with this.
//
//   tiler_decode IMAGE [THREADS] [openimageio]
#include <clipstream/tiler/image_source.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s IMAGE [THREADS] [openimageio]\n", argv[0]);
    return 2;
  }
  clipstream::ImageReadOptions read;
  read.decode_threads = argc > 2 ? unsigned(std::strtoul(argv[2], nullptr, 10)) : 0;
  if (argc > 3 && std::string(argv[3]) == "openimageio") read.reader = clipstream::ImageReader::kOpenImageIO;
  read.memory_budget_bytes = uint64_t(256) << 20;
  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t c0 = std::clock();
  std::unique_ptr<clipstream::ImageSource> src;
  clipstream::Status s = clipstream::openImageFile(argv[1], std::nullopt, &src, read);
  if (!s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  const clipstream::SourceInfo& info = src->info();
  const size_t row = size_t(info.width_px) * clipstream::bytesPerPixel(info.format);
  std::vector<uint8_t> strip(row * 128);
  for (uint64_t y = 0; y < info.height_px; y += 128) {
    const uint32_t rows = uint32_t(std::min<uint64_t>(128, info.height_px - y));
    s = src->readRows(y, rows, 0, info.width_px, strip.data(), row);
    if (!s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return 1;
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
  std::printf("%s\t%u\t%.3f\t%.3f\t%.1f\n", info.decoder.c_str(), read.decode_threads, wall, cpu,
              double(info.width_px * info.height_px) / 1e6 / wall);
  return 0;
}
