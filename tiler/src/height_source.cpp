#include "height_source.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace clipstream {
namespace {

double nativeSample(PixelFormat format, const uint8_t* p) {
  switch (format) {
    case PixelFormat::kI16: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case PixelFormat::kR16: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    default: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
  }
}

bool isNodata(const HeightConversion& c, double v) {
  if (!std::isfinite(v)) return true;
  if (!c.has_nodata) return false;
  // A NaN no-data value marks NaNs only (handled above).
  return v == c.nodata;
}

// Eight directions of the fill's search.
constexpr int kDirections[8][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}, {1, 1}, {1, -1}, {-1, 1}, {-1, -1}};

}  // namespace

HeightSource::HeightSource(std::unique_ptr<ImageSource> inner, const HeightConversion& conversion)
    : m_inner(std::move(inner)), m_conversion(conversion), m_info(m_inner->info()) {
  m_info.format = conversion.stored;
}

Status HeightSource::readHeights(uint64_t y0, uint64_t h, uint64_t x0, uint64_t w,
                                 std::vector<float>* out, std::vector<uint8_t>* valid) {
  const PixelFormat native = m_inner->info().format;
  const size_t bpp = bytesPerPixel(native);
  m_native.resize(size_t(w) * h * bpp);
  Status s = m_inner->readRows(y0, uint32_t(h), x0, w, m_native.data(), size_t(w) * bpp);
  if (!s) return s;
  out->resize(size_t(w) * h);
  valid->resize(size_t(w) * h);
  for (size_t i = 0; i < out->size(); ++i) {
    const double v = nativeSample(native, m_native.data() + i * bpp);
    (*valid)[i] = !isNodata(m_conversion, v);
    (*out)[i] = float(v);
  }
  return okStatus();
}

double HeightSource::fill(const std::vector<float>& heights, const std::vector<uint8_t>& valid,
                          uint64_t w, uint64_t h, uint64_t x, uint64_t y, double fallback) const {
  // Inverse-distance weighting of the nearest valid sample along each of
  // eight directions (the rule of GDAL's FillNodata, without smoothing).
  double sum = 0.0, weights = 0.0;
  for (const auto& d : kDirections) {
    const double step = (d[0] != 0 && d[1] != 0) ? std::sqrt(2.0) : 1.0;
    for (uint32_t k = 1; k <= kHeightFillRadius; ++k) {
      const int64_t xx = int64_t(x) + d[0] * int64_t(k), yy = int64_t(y) + d[1] * int64_t(k);
      if (xx < 0 || yy < 0 || xx >= int64_t(w) || yy >= int64_t(h)) break;
      const size_t i = size_t(yy) * w + size_t(xx);
      if (valid[i]) {
        const double weight = 1.0 / (step * k);
        sum += weight * heights[i];
        weights += weight;
        break;
      }
    }
  }
  return weights > 0.0 ? sum / weights : fallback;
}

void HeightSource::store(double height, bool was_valid, uint8_t* dst) {
  const HeightConversion& c = m_conversion;
  double stored = height;
  switch (c.stored) {
    case PixelFormat::kI16: {
      const int16_t v = int16_t(std::clamp(std::round(height), -32768.0, 32767.0));
      std::memcpy(dst, &v, 2);
      stored = v;
      break;
    }
    case PixelFormat::kR16: {
      const double q = std::clamp(std::round((height - c.offset) / c.scale), 0.0, 65535.0);
      const uint16_t v = uint16_t(q);
      std::memcpy(dst, &v, 2);
      stored = c.offset + c.scale * q;
      break;
    }
    default: {
      const float v = float(height);
      std::memcpy(dst, &v, 4);
      stored = v;
      break;
    }
  }
  if (was_valid) m_max_error = std::max(m_max_error, std::abs(stored - height));
}

Status HeightSource::readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width,
                              uint8_t* dst, size_t dst_stride) {
  Status s = readHeights(y0, rows, x0, width, &m_heights, &m_valid);
  if (!s) return s;
  const bool holes = std::find(m_valid.begin(), m_valid.end(), uint8_t(0)) != m_valid.end();
  uint64_t hx0 = x0, hy0 = y0, hw = width, hh = rows;
  double fallback = m_last_fallback;
  if (holes) {
    // The neighbourhood within reach of the fill, clamped to the image.
    const uint64_t r = kHeightFillRadius;
    hx0 = x0 >= r ? x0 - r : 0;
    hy0 = y0 >= r ? y0 - r : 0;
    hw = std::min(x0 + width + r, m_info.width_px) - hx0;
    hh = std::min(y0 + rows + r, m_info.height_px) - hy0;
    s = readHeights(hy0, hh, hx0, hw, &m_halo, &m_halo_valid);
    if (!s) return s;
    double lowest = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < m_halo.size(); ++i) {
      if (m_halo_valid[i]) lowest = std::min(lowest, double(m_halo[i]));
    }
    if (std::isfinite(lowest)) fallback = m_last_fallback = lowest;
  }
  const size_t bpp = bytesPerPixel(m_info.format);
  for (uint32_t r = 0; r < rows; ++r) {
    uint8_t* out = dst + size_t(r) * dst_stride;
    for (uint64_t x = 0; x < width; ++x) {
      const size_t i = size_t(r) * width + x;
      if (m_valid[i]) {
        store(m_heights[i], true, out + x * bpp);
        continue;
      }
      const double h = fill(m_halo, m_halo_valid, hw, hh, x0 + x - hx0, y0 + r - hy0, fallback);
      store(h, false, out + x * bpp);
      ++m_filled;
    }
  }
  return okStatus();
}

Status scanHeightRange(ImageSource* source, const HeightConversion& conversion, double* min,
                       double* max) {
  const SourceInfo& info = source->info();
  const size_t bpp = bytesPerPixel(info.format);
  constexpr uint32_t kRows = 64;
  std::vector<uint8_t> strip(size_t(info.width_px) * kRows * bpp);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (uint64_t y = 0; y < info.height_px; y += kRows) {
    const uint32_t rows = uint32_t(std::min<uint64_t>(kRows, info.height_px - y));
    Status s = source->readRows(y, rows, 0, info.width_px, strip.data(), size_t(info.width_px) * bpp);
    if (!s) return s;
    for (size_t i = 0; i < size_t(rows) * info.width_px; ++i) {
      const double v = nativeSample(info.format, strip.data() + i * bpp);
      if (isNodata(conversion, v)) continue;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  }
  if (!std::isfinite(lo)) {
    return Status::error(ErrorCode::kInvalidArgument, "the input holds no valid height (every sample is no-data)");
  }
  *min = lo;
  *max = hi;
  return okStatus();
}

}  // namespace clipstream
