// Private: a colour input's no-data value as transparency. Wraps the source
// of an 8-bit grey or RGB input that declares a no-data value (GDAL's
// GDAL_NODATA TIFF tag, GDAL's own no-data for its inputs, or --nodata) and
// delivers RGBA8 rows: a pixel whose every channel holds the no-data value
// becomes (0, 0, 0, 0), black under zero alpha, which the renderer draws
// as premultiplied alpha (the sky colour shows where nothing is), and
// every other pixel is opaque. The filters then average covered and
// uncovered texels correctly at every level.
//
// Thread rule: like every ImageSource, one thread at a time.
#pragma once

#include <clipstream/tiler/image_source.h>

#include <memory>
#include <vector>

namespace clipstream {

class NoDataAlphaSource final : public ImageSource {
 public:
  // `inner` delivers R8, RGB8 or (forced by --format) opaque RGBA8 rows;
  // `nodata` is compared with each colour channel.
  NoDataAlphaSource(std::unique_ptr<ImageSource> inner, uint8_t nodata);

  const SourceInfo& info() const override { return m_info; }
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override;

  uint64_t transparentPixels() const { return m_transparent; }

 private:
  std::unique_ptr<ImageSource> m_inner;
  SourceInfo m_info;
  uint8_t m_nodata;
  std::vector<uint8_t> m_rows;
  uint64_t m_transparent = 0;
};

}  // namespace clipstream
