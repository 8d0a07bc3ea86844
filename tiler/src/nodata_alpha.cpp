// A colour input's no-data value as transparency (nodata_alpha.h).
#include "nodata_alpha.h"

#include <algorithm>

namespace clipstream {

NoDataAlphaSource::NoDataAlphaSource(std::unique_ptr<ImageSource> inner, uint8_t nodata)
    : m_inner(std::move(inner)), m_info(m_inner->info()), m_nodata(nodata) {
  m_info.format = PixelFormat::kRGBA8;
}

Status NoDataAlphaSource::readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                                   size_t dst_stride) {
  const uint32_t stride = bytesPerPixel(m_inner->info().format);  // 1 (R8), 3 (RGB8) or 4 (RGBA8)
  const uint32_t channels = std::min(stride, 3u);                   // the colour ones
  const size_t row = size_t(width) * stride;
  m_rows.resize(row * rows);
  Status s = m_inner->readRows(y0, rows, x0, width, m_rows.data(), row);
  if (!s) return s;
  for (uint32_t r = 0; r < rows; ++r) {
    const uint8_t* in = m_rows.data() + r * row;
    uint8_t* out = dst + r * dst_stride;
    for (uint64_t x = 0; x < width; ++x, in += stride, out += 4) {
      bool empty = true;
      for (uint32_t c = 0; c < channels; ++c) empty = empty && in[c] == m_nodata;
      if (empty) {
        out[0] = out[1] = out[2] = out[3] = 0;
        ++m_transparent;
        continue;
      }
      out[0] = in[0];
      out[1] = in[channels == 3 ? 1 : 0];
      out[2] = in[channels == 3 ? 2 : 0];
      out[3] = 255;
    }
  }
  m_info.clamped_samples = m_inner->info().clamped_samples;
  return okStatus();
}

}  // namespace clipstream
