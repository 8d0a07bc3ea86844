// libFuzzer driver for the tiler's own image readers (TIFF through
// libtiff, JPEG through libjpeg-turbo, PNG through libpng; tiler/src/
// native_source.h): opens a mutated file by its first bytes, as the tiler
// does, and reads every row. Files the readers leave to OpenImageIO are not
// opened (that library is not ours to fuzz). Seeds: small files of every
// layout the readers cover, written by the codec libraries.
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./image_fuzz -runs=0   # write seeds
//   ./image_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"
#include "native_source.h"

#include <clipstream/tiler/image_source.h>

#include <jpeglib.h>
#include <png.h>
#include <tiffio.h>

#include <csetjmp>
#include <cstring>
#include <string>
#include <vector>

namespace {

using namespace clipstream;

uint8_t sample(uint32_t x, uint32_t y, uint32_t c) { return uint8_t(x * 7 + y * 13 + c * 61); }

void writeTiff(const std::string& path, uint32_t w, uint32_t h, uint16_t spp, uint16_t bits,
               uint16_t format, uint16_t compression, uint32_t tile, uint16_t photometric) {
  TIFF* t = TIFFOpen(path.c_str(), "w");
  if (t == nullptr) std::abort();
  TIFFSetField(t, TIFFTAG_IMAGEWIDTH, w);
  TIFFSetField(t, TIFFTAG_IMAGELENGTH, h);
  TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, spp);
  TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, bits);
  TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, format);
  TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(t, TIFFTAG_PHOTOMETRIC, photometric);
  TIFFSetField(t, TIFFTAG_COMPRESSION, compression);
  if (spp == 4) {
    const uint16_t extra = EXTRASAMPLE_UNASSALPHA;
    TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, &extra);
  }
  if (compression == COMPRESSION_JPEG) TIFFSetField(t, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
  const size_t pixel = size_t(spp) * bits / 8;
  if (tile > 0) {
    TIFFSetField(t, TIFFTAG_TILEWIDTH, tile);
    TIFFSetField(t, TIFFTAG_TILELENGTH, tile);
    std::vector<uint8_t> buf(size_t(tile) * tile * pixel);
    for (uint32_t ty = 0; ty < h; ty += tile)
      for (uint32_t tx = 0; tx < w; tx += tile) {
        for (size_t i = 0; i < buf.size(); ++i) buf[i] = sample(tx + uint32_t(i / pixel) % tile, ty, uint32_t(i % pixel));
        TIFFWriteTile(t, buf.data(), tx, ty, 0, 0);
      }
  } else {
    TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, 8);
    std::vector<uint8_t> row(size_t(w) * pixel);
    for (uint32_t y = 0; y < h; ++y) {
      for (size_t i = 0; i < row.size(); ++i) row[i] = sample(uint32_t(i / pixel), y, uint32_t(i % pixel));
      if (format == SAMPLEFORMAT_IEEEFP && bits == 32) {
        for (size_t i = 0; i + 4 <= row.size(); i += 4) {
          const float v = float(row[i]) * 0.5f;
          std::memcpy(row.data() + i, &v, 4);
        }
      }
      TIFFWriteScanline(t, row.data(), y, 0);
    }
  }
  TIFFClose(t);
}

void writeJpeg(const std::string& path, uint32_t w, uint32_t h, int components, bool progressive) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  jpeg_compress_struct c{};
  jpeg_error_mgr err{};
  c.err = jpeg_std_error(&err);
  jpeg_create_compress(&c);
  jpeg_stdio_dest(&c, f);
  c.image_width = w;
  c.image_height = h;
  c.input_components = components;
  c.in_color_space = components == 1 ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_set_defaults(&c);
  jpeg_set_quality(&c, 80, TRUE);
  if (progressive) jpeg_simple_progression(&c);
  jpeg_start_compress(&c, TRUE);
  std::vector<uint8_t> row(size_t(w) * components);
  while (c.next_scanline < h) {
    for (size_t i = 0; i < row.size(); ++i) row[i] = sample(uint32_t(i) / components, c.next_scanline, uint32_t(i) % components);
    JSAMPROW rows[1] = {row.data()};
    jpeg_write_scanlines(&c, rows, 1);
  }
  jpeg_finish_compress(&c);
  jpeg_destroy_compress(&c);
  std::fclose(f);
}

void writePng(const std::string& path, uint32_t w, uint32_t h, int color_type, int bits) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) std::abort();
  png_init_io(png, f);
  png_set_IHDR(png, info, w, h, bits, color_type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  const int channels = color_type == PNG_COLOR_TYPE_GRAY ? 1 : color_type == PNG_COLOR_TYPE_GRAY_ALPHA ? 2
                       : color_type == PNG_COLOR_TYPE_RGB ? 3 : 4;
  std::vector<uint8_t> row(size_t(w) * channels * (bits / 8));
  for (uint32_t y = 0; y < h; ++y) {
    for (size_t i = 0; i < row.size(); ++i) row[i] = sample(uint32_t(i), y, 0);
    png_write_row(png, row.data());
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  std::fclose(f);
}

void writeSeeds(const std::string& dir) {
  int n = 0;
  auto name = [&](const char* ext) { return dir + "/seed" + std::to_string(n++) + ext; };
  writeTiff(name(".tif"), 37, 21, 3, 8, SAMPLEFORMAT_UINT, COMPRESSION_NONE, 0, PHOTOMETRIC_RGB);
  writeTiff(name(".tif"), 40, 33, 3, 8, SAMPLEFORMAT_UINT, COMPRESSION_ADOBE_DEFLATE, 16, PHOTOMETRIC_RGB);
  writeTiff(name(".tif"), 30, 20, 4, 8, SAMPLEFORMAT_UINT, COMPRESSION_LZW, 0, PHOTOMETRIC_RGB);
  writeTiff(name(".tif"), 25, 19, 1, 16, SAMPLEFORMAT_INT, COMPRESSION_ADOBE_DEFLATE, 0, PHOTOMETRIC_MINISBLACK);
  writeTiff(name(".tif"), 24, 24, 1, 16, SAMPLEFORMAT_UINT, COMPRESSION_NONE, 16, PHOTOMETRIC_MINISBLACK);
  writeTiff(name(".tif"), 20, 18, 1, 32, SAMPLEFORMAT_IEEEFP, COMPRESSION_ADOBE_DEFLATE, 0, PHOTOMETRIC_MINISBLACK);
  writeTiff(name(".tif"), 32, 24, 3, 8, SAMPLEFORMAT_UINT, COMPRESSION_JPEG, 0, PHOTOMETRIC_YCBCR);
  writeJpeg(name(".jpg"), 33, 17, 3, false);
  writeJpeg(name(".jpg"), 40, 24, 3, true);
  writeJpeg(name(".jpg"), 19, 23, 1, false);
  writePng(name(".png"), 31, 17, PNG_COLOR_TYPE_RGB, 8);
  writePng(name(".png"), 20, 20, PNG_COLOR_TYPE_RGBA, 8);
  writePng(name(".png"), 21, 9, PNG_COLOR_TYPE_GRAY, 16);
  writePng(name(".png"), 12, 12, PNG_COLOR_TYPE_GRAY_ALPHA, 8);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = fuzz::seedDir()) writeSeeds(dir);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = fuzz::scratchPath("image");
  fuzz::writeFile(path, data, size);
  ImageReadOptions read;
  read.decode_threads = 2;  // the TIFF decode workers too
  read.memory_budget_bytes = uint64_t(64) << 20;
  std::unique_ptr<ImageSource> source;
  bool covered = false;
  if (!openNativeImage(path, std::nullopt, read, &source, &covered) || !covered) return 0;
  const SourceInfo& info = source->info();
  // Every row of a small image; a large one is opened (its header checked)
  // but not decoded, to keep each input fast.
  if (info.width_px == 0 || info.width_px * info.height_px > (uint64_t(1) << 20)) return 0;
  const size_t row_bytes = size_t(info.width_px) * bytesPerPixel(info.format);
  constexpr uint32_t kRows = 16;
  std::vector<uint8_t> rows(row_bytes * kRows);
  for (uint64_t y = 0; y < info.height_px; y += kRows) {
    const uint32_t n = uint32_t(std::min<uint64_t>(kRows, info.height_px - y));
    if (!source->readRows(y, n, 0, info.width_px, rows.data(), row_bytes)) break;
  }
  return 0;
}
