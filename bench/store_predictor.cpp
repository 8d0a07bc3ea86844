// Measures what the left-delta predictor buys on real imagery: compression
// ratio and single-thread encode/decode MB/s for each (predictor, zstd
// level), best of N runs. Prints a tab-separated table (--tsv FILE: also
// into FILE, docs/data/store_predictor.tsv); asserts nothing.
//
//   store_predictor_bench [--runs N] [--tsv FILE] [IMAGE...]
// Without images it uses autzen.jpg, fg_globe_colors_8192x4096.jpg and
// mt_rainier_90m.tif from CLIPSTREAM_STORE_BENCH_DATA.
#include <clipstream/store/tile_store.h>

#include <OpenImageIO/imageio.h>

#include "tsv_out.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace {

using namespace clipstream;
using Clock = std::chrono::steady_clock;

struct Image {
  std::string name;
  PixelFormat format = PixelFormat::kRGB8;
  uint64_t width = 0, height = 0;
  std::vector<uint8_t> pixels;
};

bool loadImage(const std::string& path, Image* out) {
  auto input = OIIO::ImageInput::open(path);
  if (!input) {
    std::fprintf(stderr, "cannot open %s: %s\n", path.c_str(), OIIO::geterror().c_str());
    return false;
  }
  const OIIO::ImageSpec& spec = input->spec();
  out->name = path.substr(path.find_last_of('/') + 1);
  out->width = uint64_t(spec.width);
  out->height = uint64_t(spec.height);
  OIIO::TypeDesc type = OIIO::TypeDesc::UINT8;
  int channels = 3;
  if (spec.nchannels == 1 && spec.format.size() == 2) {
    // 16-bit elevation: stored as R16 with the raw sample bits (the
    // predictor works modulo 2^16, so signedness does not matter).
    out->format = PixelFormat::kR16;
    type = spec.format;
    channels = 1;
  } else if (spec.nchannels == 1) {
    out->format = PixelFormat::kR8;
    channels = 1;
  } else {
    out->format = PixelFormat::kRGB8;
  }
  out->pixels.resize(out->width * out->height * size_t(channels) * type.size());
  if (!input->read_image(0, 0, 0, channels, type, out->pixels.data())) {
    std::fprintf(stderr, "cannot read %s: %s\n", path.c_str(), input->geterror().c_str());
    return false;
  }
  return true;
}

// Level-0 tiles cut from the image, edges clamped as the format specifies.
std::vector<std::vector<uint8_t>> cutTiles(const Image& image, const PyramidGeometry& g) {
  const uint32_t bpp = bytesPerPixel(image.format);
  std::vector<std::vector<uint8_t>> tiles;
  const LevelInfo& level = g.levels[0];
  for (uint32_t ty = 0; ty < level.tiles_y; ++ty) {
    for (uint32_t tx = 0; tx < level.tiles_x; ++tx) {
      std::vector<uint8_t> tile(g.tileBytes());
      for (uint32_t y = 0; y < g.tile_px; ++y) {
        const uint64_t sy = std::min<uint64_t>(uint64_t(ty) * g.tile_px + y, image.height - 1);
        for (uint32_t x = 0; x < g.tile_px; ++x) {
          const uint64_t sx = std::min<uint64_t>(uint64_t(tx) * g.tile_px + x, image.width - 1);
          std::memcpy(&tile[(size_t(y) * g.tile_px + x) * bpp],
                      &image.pixels[(sy * image.width + sx) * bpp], bpp);
        }
      }
      tiles.push_back(std::move(tile));
    }
  }
  return tiles;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  int runs = 3;
  std::vector<std::string> paths;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
      runs = std::max(1, std::atoi(argv[++i]));
    } else {
      paths.push_back(argv[i]);
    }
  }
  if (paths.empty()) {
    const std::string data = CLIPSTREAM_STORE_BENCH_DATA;
    paths = {data + "/autzen.jpg", data + "/fg_globe_colors_8192x4096.jpg",
             data + "/mt_rainier_90m.tif"};
  }
  table.row("image\tformat\ttile_px\ttiles\tpredictor\tzstd_level\traw_MB\tstored_MB\tratio\t"
              "encode_MB_per_s\tdecode_MB_per_s\n");
  for (const std::string& path : paths) {
    Image image;
    if (!loadImage(path, &image)) continue;
    PyramidGeometry g;
    if (!makePyramidGeometry(image.width, image.height, 128, image.format, &g)) continue;
    const auto tiles = cutTiles(image, g);
    const double raw_mb = double(tiles.size()) * double(g.tileBytes()) / 1e6;
    for (int level : {1, 3, 9}) {
      for (Predictor predictor : {Predictor::kNone, Predictor::kLeftDelta}) {
        StoreEncoding encoding;
        encoding.zstd_level = level;
        encoding.predictor = predictor;
        double best_encode_s = 1e30, best_decode_s = 1e30;
        uint64_t stored = 0;
        std::vector<EncodedTile> encoded(tiles.size());
        std::vector<uint8_t> pixels(g.tileBytes());
        for (int run = 0; run < runs; ++run) {
          auto start = Clock::now();
          stored = 0;
          for (size_t i = 0; i < tiles.size(); ++i) {
            const TileKey key{0, uint32_t(i % g.levels[0].tiles_x), uint32_t(i / g.levels[0].tiles_x)};
            if (!encodeTile(g, encoding, key, tiles[i], &encoded[i])) return 1;
            stored += encoded[i].payload.size();
          }
          best_encode_s = std::min(best_encode_s,
                                   std::chrono::duration<double>(Clock::now() - start).count());
          std::vector<RawTile> raws(tiles.size());
          for (size_t i = 0; i < tiles.size(); ++i) {
            raws[i].key = encoded[i].key;
            raws[i].location = encoded[i].location;
            raws[i].payload = encoded[i].payload;
          }
          start = Clock::now();
          bool decoded_ok = true;
          for (size_t i = 0; i < tiles.size(); ++i) {
            decoded_ok &= decodeTile(g, encoding, raws[i], pixels).ok();
          }
          const auto decode_end = Clock::now();
          // Checked outside the timed loop: the bench must also be right.
          for (size_t i = 0; i < tiles.size() && decoded_ok; ++i) {
            decoded_ok = decodeTile(g, encoding, raws[i], pixels).ok() && pixels == tiles[i];
          }
          if (!decoded_ok) {
            std::fprintf(stderr, "round trip failed\n");
            return 1;
          }
          best_decode_s = std::min(best_decode_s,
                                   std::chrono::duration<double>(decode_end - start).count());
        }
        table.row("%s\t%s\t%u\t%zu\t%s\t%d\t%.1f\t%.1f\t%.3f\t%.0f\t%.0f\n", image.name.c_str(),
                    pixelFormatName(image.format), g.tile_px, tiles.size(),
                    predictor == Predictor::kLeftDelta ? "left-delta" : "none", level, raw_mb,
                    double(stored) / 1e6, raw_mb * 1e6 / double(std::max<uint64_t>(stored, 1)),
                    raw_mb / best_encode_s, raw_mb / best_decode_s);
        std::fflush(stdout);
      }
    }
  }
  return table.commit() ? 0 : 1;
}
