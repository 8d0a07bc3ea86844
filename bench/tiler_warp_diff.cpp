// Level 0 of a store against a reference image on the same grid (the
// output of gdalwarp for the same reprojection), sample by sample, read by
// the tiler's own reader in the store's format. Heights are compared as
// numbers where the reference has one (its no-data samples are skipped: the
// store fills them); colour as 8-bit samples, alpha included. Prints one
// tab-separated line: samples compared, largest and mean absolute
// difference, share of samples that differ, largest offset of the grids'
// origins in reference pixels. scripts/bench_warp.sh runs it.
//
//   tiler_warp_diff STORE REFERENCE
#include <clipstream/store/tile_store.h>
#include <clipstream/tiler/georef.h>
#include <clipstream/tiler/image_source.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace {

using namespace clipstream;

int fail(const std::string& what) {
  std::fprintf(stderr, "tiler_warp_diff: %s\n", what.c_str());
  return 1;
}

double sampleAt(const uint8_t* p, PixelFormat format) {
  switch (format) {
    case PixelFormat::kI16: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case PixelFormat::kF32: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    case PixelFormat::kR16: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    default: return *p;
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) return fail("usage: tiler_warp_diff STORE REFERENCE");
  std::unique_ptr<TileStoreReader> store;
  Status s = TileStoreReader::open(argv[1], &store);
  if (!s) return fail(s.toString());
  const PyramidGeometry& g = store->geometry();
  const ElevationInfo& elevation = store->info().elevation;
  std::unique_ptr<ImageSource> ref;
  s = openImageFile(argv[2], g.format, &ref);
  if (!s) return fail(s.toString());
  if (ref->info().width_px != g.width_px || ref->info().height_px != g.height_px) {
    return fail("the store and the reference differ in size");
  }
  GeoReference ref_geo;
  ElevationTags tags;
  if (!findGeoReference(argv[2], &ref_geo) || !readElevationTags(argv[2], &tags)) {
    return fail("cannot read the reference's georeference");
  }
  const GeoReference& geo = store->info().geo;
  const double pixel = std::hypot(ref_geo.transform[1], ref_geo.transform[4]);
  const double offset = std::max(std::abs(geo.transform[0] - ref_geo.transform[0]),
                                 std::abs(geo.transform[3] - ref_geo.transform[3])) / pixel;

  const uint32_t bpp = bytesPerPixel(g.format), t = g.tile_px;
  const uint32_t channels = elevation.present ? 1 : bpp;  // colour formats: one byte a channel
  const uint32_t step = elevation.present ? bpp : 1;
  const size_t row = size_t(g.width_px) * bpp;
  std::vector<uint8_t> strip(row * t), tile;
  uint64_t compared = 0, differ = 0;
  double largest = 0.0, sum = 0.0;
  for (uint32_t ty = 0; ty < g.levels[0].tiles_y; ++ty) {
    const uint64_t y0 = uint64_t(ty) * t;
    const uint32_t rows = uint32_t(std::min<uint64_t>(t, g.height_px - y0));
    s = ref->readRows(y0, rows, 0, g.width_px, strip.data(), row);
    if (!s) return fail(s.toString());
    for (uint32_t tx = 0; tx < g.levels[0].tiles_x; ++tx) {
      s = store->readTile({0, tx, ty}, &tile);
      if (!s) return fail(s.toString());
      const uint64_t x0 = uint64_t(tx) * t, w = std::min<uint64_t>(t, g.width_px - x0);
      for (uint32_t y = 0; y < rows; ++y) {
        for (uint64_t i = 0; i < w * channels; ++i) {
          const double b = sampleAt(strip.data() + size_t(y) * row + x0 * bpp + i * step, g.format);
          if (elevation.present && tags.has_nodata && (b == tags.nodata || std::isnan(b))) continue;
          const double a = sampleAt(tile.data() + size_t(y) * t * bpp + i * step, g.format);
          const double d = std::abs(a - b);
          ++compared;
          differ += d != 0.0;
          largest = std::max(largest, d);
          sum += d;
        }
      }
    }
  }
  std::printf("%llu\t%.6g\t%.6g\t%.6f\t%.3g\n", (unsigned long long)compared, largest,
              compared ? sum / double(compared) : 0.0, compared ? double(differ) / double(compared) : 0.0,
              offset);
  return 0;
}
