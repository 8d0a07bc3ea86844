#include "relief_source.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace clipstream {
namespace {

// The tint, lowest height to highest: lowland green, upland tan, rock
// brown, grey, snow (stops evenly spaced).
constexpr float kRamp[][3] = {{0.27f, 0.47f, 0.25f}, {0.55f, 0.66f, 0.36f}, {0.84f, 0.78f, 0.53f},
                              {0.62f, 0.47f, 0.34f}, {0.60f, 0.58f, 0.56f}, {0.97f, 0.97f, 0.98f}};
constexpr int kRampStops = int(sizeof(kRamp) / sizeof(kRamp[0]));

// The light: from azimuth 315 degrees (north-west), 45 degrees above the
// horizon; east, north, up.
constexpr double kLight[3] = {-0.5, 0.5, 0.70710678118654752};
// How much of the colour a slope facing away from the light keeps.
constexpr double kAmbient = 0.35;

// Samples read per request: rows and columns in one strip of heights.
constexpr uint64_t kStripRows = 256;

}  // namespace

ReliefSource::ReliefSource(std::unique_ptr<ImageSource> heights, const ReliefOptions& options)
    : m_heights(std::move(heights)), m_options(options) {
  const SourceInfo& in = m_heights->info();
  m_info = in;
  m_info.width_px = in.width_px * options.scale;
  m_info.height_px = in.height_px * options.scale;
  m_info.format = PixelFormat::kRGB8;
}

Status ReliefSource::open(std::unique_ptr<ImageSource> heights, const ReliefOptions& options,
                          std::unique_ptr<ImageSource>* out) {
  if (heights->info().format != PixelFormat::kF32) {
    return Status::error(ErrorCode::kInvalidArgument, "relief: heights must be delivered as F32");
  }
  if (options.scale < 1 || options.scale > kMaxReliefScale) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--relief-scale must be from 1 to " + std::to_string(kMaxReliefScale));
  }
  std::unique_ptr<ReliefSource> relief(new ReliefSource(std::move(heights), options));
  const uint64_t w = relief->m_heights->info().width_px, h = relief->m_heights->info().height_px;
  std::vector<float> strip;
  double lo = INFINITY, hi = -INFINITY;
  for (uint64_t y = 0; y < h; y += kStripRows) {
    const uint32_t rows = uint32_t(std::min(kStripRows, h - y));
    strip.resize(size_t(w) * rows);
    Status s = relief->m_heights->readRows(y, rows, 0, w, reinterpret_cast<uint8_t*>(strip.data()),
                                           size_t(w) * sizeof(float));
    if (!s) return s;
    for (float v : strip) {
      lo = std::min(lo, double(v));
      hi = std::max(hi, double(v));
    }
  }
  relief->m_min = lo;
  relief->m_max = hi;
  *out = std::move(relief);
  return okStatus();
}

Status ReliefSource::readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                              size_t dst_stride) {
  const uint64_t w = m_heights->info().width_px, h = m_heights->info().height_px;
  const double n = double(m_options.scale);
  // Pixel p lies at sample coordinate (p + 0.5) / n - 0.5; the bilinear
  // weights need samples floor(u) and floor(u) + 1, their central
  // differences one more on each side.
  auto first = [&](uint64_t p, uint64_t size) {
    const double u = std::floor((double(p) + 0.5) / n - 0.5) - 1.0;
    return uint64_t(std::clamp(u, 0.0, double(size - 1)));
  };
  auto last = [&](uint64_t p, uint64_t size) {
    const double u = std::floor((double(p) + 0.5) / n - 0.5) + 2.0;
    return uint64_t(std::clamp(u, 0.0, double(size - 1)));
  };
  const uint64_t sx0 = first(x0, w), sx1 = last(x0 + width - 1, w);
  const uint64_t sy0 = first(y0, h), sy1 = last(y0 + rows - 1, h);
  const uint64_t ww = sx1 - sx0 + 1, wh = sy1 - sy0 + 1;
  m_window.resize(size_t(ww * wh));
  Status s = m_heights->readRows(sy0, uint32_t(wh), sx0, ww, reinterpret_cast<uint8_t*>(m_window.data()),
                                 size_t(ww) * sizeof(float));
  if (!s) return s;

  // Height and gradient (height units per sample) at window sample (i, j),
  // central differences, one-sided at the DEM's edges.
  auto at = [&](int64_t i, int64_t j) {
    i = std::clamp<int64_t>(i, 0, int64_t(ww) - 1);
    j = std::clamp<int64_t>(j, 0, int64_t(wh) - 1);
    return double(m_window[size_t(j) * ww + size_t(i)]);
  };
  auto gradient = [&](int64_t i, int64_t j, double* gx, double* gy) {
    const int64_t gi = int64_t(sx0) + i, gj = int64_t(sy0) + j;
    const int64_t l = gi > 0 ? i - 1 : i, r = gi + 1 < int64_t(w) ? i + 1 : i;
    const int64_t u = gj > 0 ? j - 1 : j, d = gj + 1 < int64_t(h) ? j + 1 : j;
    *gx = r > l ? (at(r, j) - at(l, j)) / double(r - l) : 0.0;
    *gy = d > u ? (at(i, d) - at(i, u)) / double(d - u) : 0.0;
  };
  const double range = m_max > m_min ? m_max - m_min : 1.0;
  const double kx = m_options.metres_per_height / m_options.sample_x_metres;
  const double ky = m_options.metres_per_height / m_options.sample_y_metres;
  for (uint32_t r = 0; r < rows; ++r) {
    const double v = std::clamp((double(y0 + r) + 0.5) / n - 0.5, 0.0, double(h - 1));
    const double vf = std::floor(v);
    const double fy = v - vf;
    const int64_t j = int64_t(vf) - int64_t(sy0);
    uint8_t* out = dst + size_t(r) * dst_stride;
    for (uint64_t c = 0; c < width; ++c) {
      const double u = std::clamp((double(x0 + c) + 0.5) / n - 0.5, 0.0, double(w - 1));
      const double uf = std::floor(u);
      const double fx = u - uf;
      const int64_t i = int64_t(uf) - int64_t(sx0);
      double height = 0.0, gx = 0.0, gy = 0.0;
      for (int k = 0; k < 4; ++k) {
        const int64_t di = k & 1, dj = k >> 1;
        const double weight = (di ? fx : 1.0 - fx) * (dj ? fy : 1.0 - fy);
        if (weight == 0.0) continue;
        double ax = 0.0, ay = 0.0;
        gradient(i + di, j + dj, &ax, &ay);
        height += weight * at(i + di, j + dj);
        gx += weight * ax;
        gy += weight * ay;
      }
      // Slopes in metres per metre: east, and north (rows run south).
      const double east = gx * kx, north = -gy * ky;
      const double norm = std::sqrt(east * east + north * north + 1.0);
      const double lit = std::max(0.0, (-east * kLight[0] - north * kLight[1] + kLight[2]) / norm);
      const double shade = kAmbient + (1.0 - kAmbient) * lit;
      const double t = std::clamp((height - m_min) / range, 0.0, 1.0) * (kRampStops - 1);
      const int stop = std::min(int(t), kRampStops - 2);
      const double f = t - stop;
      for (int ch = 0; ch < 3; ++ch) {
        const double colour = kRamp[stop][ch] * (1.0 - f) + kRamp[stop + 1][ch] * f;
        out[c * 3 + ch] = uint8_t(std::lround(std::clamp(colour * shade, 0.0, 1.0) * 255.0));
      }
    }
  }
  return okStatus();
}

}  // namespace clipstream
