// libFuzzer driver for mosaic lists (tiler/src/mosaic_source.cpp): a
// mutated list file or GDAL VRT, read by openMosaic() as `clipstream-tile
// --mosaic` reads it, beside two small georeferenced sheets the names may
// point at; a mosaic that opens is read whole. Seeds: a plain list, a
// commented one, a VRT with and without an XML declaration.
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./mosaic_fuzz -runs=0   # write seeds
//   ./mosaic_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"

#include <clipstream/tiler/mosaic.h>

#include <tiffio.h>
#include <sys/stat.h>

#include <string>
#include <vector>

namespace {

using namespace clipstream;

// A 40 x 30 RGB sheet and its world file (1 unit a pixel, x0 units east).
void writeSheet(const std::string& path, double x0) {
  TIFF* t = TIFFOpen(path.c_str(), "w");
  if (t == nullptr) std::abort();
  TIFFSetField(t, TIFFTAG_IMAGEWIDTH, 40u);
  TIFFSetField(t, TIFFTAG_IMAGELENGTH, 30u);
  TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 3);
  TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, 8);
  TIFFSetField(t, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_RGB);
  TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, 30u);
  std::vector<uint8_t> row(40 * 3);
  for (uint32_t y = 0; y < 30; ++y) {
    for (size_t i = 0; i < row.size(); ++i) row[i] = uint8_t(i + y * 3 + uint32_t(x0));
    TIFFWriteScanline(t, row.data(), y, 0);
  }
  TIFFClose(t);
  fuzz::writeFile(path.substr(0, path.size() - 4) + ".tfw",
                  "1.0\n0.0\n0.0\n-1.0\n" + std::to_string(x0 + 0.5) + "\n1000.5\n");
}

const std::string& folder() {
  static const std::string dir = [] {
    const std::string d = fuzz::scratchPath("mosaic");
    ::mkdir(d.c_str(), 0700);
    writeSheet(d + "/a.tif", 0.0);
    writeSheet(d + "/b.tif", 40.0);
    return d;
  }();
  return dir;
}

std::string vrt(bool prolog) {
  std::string t = prolog ? "<?xml version=\"1.0\"?>\n<!-- two sheets -->\n" : "";
  t += "<VRTDataset rasterXSize=\"80\" rasterYSize=\"30\">\n";
  for (int band = 1; band <= 3; ++band) {
    t += "  <VRTRasterBand dataType=\"Byte\" band=\"" + std::to_string(band) + "\">\n";
    for (const char* name : {"a.tif", "b.tif"}) {
      t += std::string("    <SimpleSource>\n      <SourceFilename relativeToVRT=\"1\">") + name +
           "</SourceFilename>\n      <SourceBand>" + std::to_string(band) +
           "</SourceBand>\n      <SrcRect xOff=\"0\" yOff=\"0\" xSize=\"40\" ySize=\"30\" />\n"
           "      <DstRect xOff=\"" + (name[0] == 'a' ? "0" : "40") +
           "\" yOff=\"0\" xSize=\"40\" ySize=\"30\" />\n    </SimpleSource>\n";
    }
    t += "  </VRTRasterBand>\n";
  }
  return t + "</VRTDataset>\n";
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = fuzz::seedDir()) {
    const std::string d = dir;
    fuzz::writeFile(d + "/list", "a.tif\nb.tif\n");
    fuzz::writeFile(d + "/commented", "# sheets\n  b.tif  \n\na.tif\r\n");
    fuzz::writeFile(d + "/vrt", vrt(false));
    fuzz::writeFile(d + "/vrt_prolog", "\xEF\xBB\xBF" + vrt(true));
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string list = folder() + "/list.vrt";
  fuzz::writeFile(list, data, size);
  std::unique_ptr<ImageSource> source;
  MosaicInfo info;
  if (!openMosaic(list, std::nullopt, 7, &source, &info, {})) return 0;
  const SourceInfo& s = source->info();
  if (s.width_px * s.height_px > (uint64_t(1) << 20)) return 0;
  const size_t row_bytes = size_t(s.width_px) * bytesPerPixel(s.format);
  std::vector<uint8_t> rows(row_bytes * 8);
  for (uint64_t y = 0; y < s.height_px; y += 8) {
    const uint32_t n = uint32_t(std::min<uint64_t>(8, s.height_px - y));
    if (!source->readRows(y, n, 0, s.width_px, rows.data(), row_bytes)) break;
  }
  return 0;
}
