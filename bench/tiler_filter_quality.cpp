// Filter quality for docs/tiler.md: PSNR of each store's level 1 against a
// high-quality 2x reduction of the source computed here independently
// (separable Lanczos-8 in linear light, double precision, edge clamp) -
// a much wider, gamma-correct low-pass than anything the tiler offers.
//
//   tiler_filter_quality IMAGE STORE... [--tsv FILE]
// Prints a tab-separated table (store, PSNR dB, max abs error); --tsv FILE
// also writes it into FILE (docs/data/tiler_filter_quality.tsv).
#include <clipstream/store/tile_store.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <vector>

#include "tsv_out.h"

namespace {

double sinc(double x) {
  return x == 0.0 ? 1.0 : std::sin(std::numbers::pi * x) / (std::numbers::pi * x);
}
double toLinear(double e) { return e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4); }
double toSrgb(double l) {
  l = std::clamp(l, 0.0, 1.0);
  return l <= 0.0031308 ? l * 12.92 : 1.055 * std::pow(l, 1.0 / 2.4) - 0.055;
}

}  // namespace

int main(int argc, char** argv) {
  clipstream::bench::TsvOut table(clipstream::bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s IMAGE STORE... [--tsv FILE]\n", argv[0]);
    return 2;
  }
  auto in = OIIO::ImageInput::open(argv[1]);
  if (!in) {
    std::fprintf(stderr, "%s: %s\n", argv[1], OIIO::geterror().c_str());
    return 1;
  }
  const long w = in->spec().width, h = in->spec().height;
  const int nc = 3;
  std::vector<uint8_t> src(size_t(w) * h * nc);
  if (!in->read_image(0, 0, 0, nc, OIIO::TypeDesc::UINT8, src.data())) return 1;
  const long ow = (w + 1) / 2, oh = (h + 1) / 2;
  constexpr int kLobes = 8;
  std::vector<double> wts;
  for (int k = -2 * kLobes + 1; k <= 2 * kLobes; ++k) {
    const double d = (k - 0.5) / 2.0;
    wts.push_back(std::abs(d) < kLobes ? sinc(d) * sinc(d / kLobes) : 0.0);
  }
  double sum = 0;
  for (double v : wts) sum += v;
  for (double& v : wts) v /= sum;
  const int first = -2 * kLobes + 1;
  // Horizontal pass in linear light, then vertical.
  std::vector<double> lin(src.size());
  for (size_t i = 0; i < src.size(); ++i) lin[i] = toLinear(src[i] / 255.0);
  std::vector<double> hpass(size_t(ow) * h * nc);
  for (long y = 0; y < h; ++y)
    for (long x = 0; x < ow; ++x)
      for (int c = 0; c < nc; ++c) {
        double acc = 0;
        for (size_t k = 0; k < wts.size(); ++k) {
          const long sx = std::clamp<long>(2 * x + first + long(k), 0, w - 1);
          acc += wts[k] * lin[(size_t(y) * w + sx) * nc + c];
        }
        hpass[(size_t(y) * ow + x) * nc + c] = acc;
      }
  std::vector<double> ref(size_t(ow) * oh * nc);
  for (long y = 0; y < oh; ++y)
    for (long x = 0; x < ow; ++x)
      for (int c = 0; c < nc; ++c) {
        double acc = 0;
        for (size_t k = 0; k < wts.size(); ++k) {
          const long sy = std::clamp<long>(2 * y + first + long(k), 0, h - 1);
          acc += wts[k] * hpass[(size_t(sy) * ow + x) * nc + c];
        }
        ref[(size_t(y) * ow + x) * nc + c] = toSrgb(acc) * 255.0;
      }

  table.row("store\tpsnr_db\tmax_abs_error\n");
  for (int a = 2; a < argc; ++a) {
    std::unique_ptr<clipstream::TileStoreReader> reader;
    const clipstream::Status s = clipstream::TileStoreReader::open(argv[a], &reader);
    if (!s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return 1;
    }
    const auto& g = reader->geometry();
    const auto& l1 = g.levels.at(1);
    double se = 0;
    double worst = 0;
    std::vector<uint8_t> px;
    for (uint32_t ty = 0; ty < l1.tiles_y; ++ty)
      for (uint32_t tx = 0; tx < l1.tiles_x; ++tx) {
        if (!reader->readTile({1, tx, ty}, &px)) return 1;
        for (uint32_t y = 0; y < g.tile_px; ++y)
          for (uint32_t x = 0; x < g.tile_px; ++x) {
            const long gx = long(tx) * g.tile_px + x, gy = long(ty) * g.tile_px + y;
            if (gx >= ow || gy >= oh) continue;
            for (int c = 0; c < nc; ++c) {
              const double d = px[(size_t(y) * g.tile_px + x) * nc + c] - ref[(size_t(gy) * ow + gx) * nc + c];
              se += d * d;
              worst = std::max(worst, std::abs(d));
            }
          }
      }
    const double mse = se / double(ow * oh * nc);
    table.row("%s\t%.2f\t%.1f\n", argv[a], 10.0 * std::log10(255.0 * 255.0 / mse), worst);
  }
  return table.commit() ? 0 : 1;
}
