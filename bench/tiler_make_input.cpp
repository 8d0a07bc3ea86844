// Writes the tiling benchmark's input: a SIZE x SIZE RGB8 uncompressed
// TIFF, deterministic. With a source photo it is that photo mirror-tiled at
// its native resolution (so detail and compressibility are those of a real
// orthophoto) plus +-2 of hashed noise so no two repeats are identical;
// without one it is the tiler's procedural image. Rows are written as they
// are made: memory is one row plus the source.
//
//   tiler_make_input OUT.tif SIZE [SOURCE_IMAGE]
#include <clipstream/tiler/image_source.h>

#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s OUT.tif SIZE [SOURCE_IMAGE]\n", argv[0]);
    return 2;
  }
  const std::string out_path = argv[1];
  const long size = std::strtol(argv[2], nullptr, 10);
  if (size <= 0 || size > 65536) {
    std::fprintf(stderr, "SIZE must be 1..65536\n");
    return 2;
  }
  std::vector<uint8_t> src;
  long sw = 0, sh = 0;
  if (argc > 3) {
    auto in = OIIO::ImageInput::open(argv[3]);
    if (!in) {
      std::fprintf(stderr, "%s: %s\n", argv[3], OIIO::geterror().c_str());
      return 1;
    }
    sw = in->spec().width, sh = in->spec().height;
    src.resize(size_t(sw) * sh * 3);
    // The first three channels as RGB: the benchmark source is an RGB photo.
    if (!in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, src.data())) {
      std::fprintf(stderr, "%s: %s\n", argv[3], in->geterror().c_str());
      return 1;
    }
  }
  auto out = OIIO::ImageOutput::create(out_path);
  OIIO::ImageSpec spec(static_cast<int>(size), static_cast<int>(size), 3, OIIO::TypeDesc::UINT8);
  spec.attribute("compression", "none");
  if (!out || !out->open(out_path, spec)) {
    std::fprintf(stderr, "%s: %s\n", out_path.c_str(), OIIO::geterror().c_str());
    return 1;
  }
  std::vector<uint8_t> row(size_t(size) * 3);
  for (long y = 0; y < size; ++y) {
    if (src.empty()) {
      for (long x = 0; x < size; ++x) {
        clipstream::syntheticPixel(uint64_t(x), uint64_t(y), clipstream::PixelFormat::kRGB8,
                                          &row[size_t(x) * 3]);
      }
    } else {
      // Mirror tiling keeps the content continuous across repeats.
      const long ry = y % (2 * sh);
      const long sy = ry < sh ? ry : 2 * sh - 1 - ry;
      for (long x = 0; x < size; ++x) {
        const long rx = x % (2 * sw);
        const long sx = rx < sw ? rx : 2 * sw - 1 - rx;
        uint64_t h = uint64_t(x) * 0x9E3779B185EBCA87ull ^ uint64_t(y) * 0xC2B2AE3D27D4EB4Full;
        h ^= h >> 31;
        for (int c = 0; c < 3; ++c) {
          const int noise = int((h >> (8 * c)) % 5) - 2;
          const int v = src[(size_t(sy) * sw + sx) * 3 + c] + noise;
          row[size_t(x) * 3 + c] = uint8_t(v < 0 ? 0 : v > 255 ? 255 : v);
        }
      }
    }
    if (!out->write_scanline(int(y), 0, OIIO::TypeDesc::UINT8, row.data())) {
      std::fprintf(stderr, "%s: %s\n", out_path.c_str(), out->geterror().c_str());
      return 1;
    }
  }
  if (!out->close()) {
    std::fprintf(stderr, "%s: %s\n", out_path.c_str(), out->geterror().c_str());
    return 1;
  }
  return 0;
}
