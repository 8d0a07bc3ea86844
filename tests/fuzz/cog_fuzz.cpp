// libFuzzer driver for the COG reader (store/src/cog_reader.cpp): opens a
// mutated tiled TIFF as the programs do (CogReader::open) and reads every
// tile of its pyramid, the built levels included. Seeds: small tiled TIFFs
// with reduced-resolution directories, in every compression the reader is
// tested with, written by libtiff.
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./cog_fuzz -runs=0   # write seeds
//   ./cog_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"

#include <clipstream/store/cog.h>

#include <tiffio.h>

#include <cstdlib>
#include <string>
#include <vector>

namespace {

using namespace clipstream;

// Pyramid tiles read per input at most: a mutated size may claim millions.
constexpr uint64_t kMaxTilesRead = 256;

void writeImage(TIFF* t, uint32_t w, uint32_t h, uint16_t spp, uint16_t compression, uint32_t tile, bool overview) {
  TIFFSetField(t, TIFFTAG_SUBFILETYPE, overview ? FILETYPE_REDUCEDIMAGE : 0);
  TIFFSetField(t, TIFFTAG_IMAGEWIDTH, w);
  TIFFSetField(t, TIFFTAG_IMAGELENGTH, h);
  TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, spp);
  TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, 8);
  TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(t, TIFFTAG_PHOTOMETRIC, spp >= 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK);
  TIFFSetField(t, TIFFTAG_COMPRESSION, compression);
  if (spp == 4 || spp == 2) {
    const uint16_t extra = EXTRASAMPLE_UNASSALPHA;
    TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, &extra);
  }
  TIFFSetField(t, TIFFTAG_TILEWIDTH, tile);
  TIFFSetField(t, TIFFTAG_TILELENGTH, tile);
  std::vector<uint8_t> buf(size_t(tile) * tile * spp);
  for (uint32_t ty = 0; ty < h; ty += tile)
    for (uint32_t tx = 0; tx < w; tx += tile) {
      for (size_t i = 0; i < buf.size(); ++i) buf[i] = uint8_t(tx * 3 + ty * 5 + i * 7 + (i >> 5));
      TIFFWriteTile(t, buf.data(), tx, ty, 0, 0);
    }
  TIFFWriteDirectory(t);
}

void writeSeeds(const std::string& dir) {
  struct Seed {
    uint32_t w, h;
    uint16_t spp, compression;
    uint32_t tile;
    int overviews;
  } seeds[] = {
      {300, 200, 3, COMPRESSION_ADOBE_DEFLATE, 64, 2}, {257, 129, 1, COMPRESSION_LZW, 32, 1},
      {200, 300, 4, COMPRESSION_ZSTD, 128, 1},         {160, 160, 3, COMPRESSION_JPEG, 32, 2},
      {140, 90, 3, COMPRESSION_WEBP, 16, 0},           {130, 70, 2, COMPRESSION_NONE, 16, 1},
  };
  int n = 0;
  for (const Seed& s : seeds) {
    TIFF* t = TIFFOpen((dir + "/seed" + std::to_string(n++) + ".tif").c_str(), "w");
    if (t == nullptr) std::abort();
    writeImage(t, s.w, s.h, s.spp, s.compression, s.tile, false);
    for (int o = 1; o <= s.overviews; ++o)
      writeImage(t, (s.w + (1u << o) - 1) >> o, (s.h + (1u << o) - 1) >> o, s.spp, s.compression, s.tile, true);
    TIFFClose(t);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  TIFFSetErrorHandler(nullptr);
  TIFFSetWarningHandler(nullptr);
  if (const char* dir = fuzz::seedDir()) writeSeeds(dir);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = fuzz::scratchPath("cog.tif");
  fuzz::writeFile(path, data, size);
  std::unique_ptr<CogReader> reader;
  if (!CogReader::open(path, {}, &reader)) return 0;
  const PyramidGeometry& g = reader->geometry();
  std::vector<uint8_t> pixels(g.tileBytes());
  uint64_t read = 0;
  // Coarsest levels first: they are built from every level below them.
  for (uint32_t l = g.levelCount(); l-- > 0;)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        if (++read > kMaxTilesRead) return 0;
        uint64_t bytes = 0;
        (void)reader->readTile({l, x, y}, pixels, &bytes);
      }
  return 0;
}
