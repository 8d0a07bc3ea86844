// A shaded colour relief of a DEM (clipstream-tile --relief): wraps the
// source of filled F32 heights (HeightSource) and delivers RGB8 rows of a
// picture `scale` times the DEM's size, each pixel a hypsometric tint of its
// height (lowest to highest height of the DEM) darkened by a hillshade lit
// from the north-west, 45 degrees up, as cartographers (and gdaldem) light
// relief. Heights and their gradients are interpolated bilinearly between
// samples, so the picture is smooth at any scale. See docs/tiler.md,
// "Shaded relief".
//
// Thread rule: like every ImageSource, used by one thread at a time (the
// tiler's reader thread).
#pragma once

#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/tiler.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

struct ReliefOptions {
  uint32_t scale = 1;              // output pixels per DEM sample along each axis
  double sample_x_metres = 1.0;    // ground size of one DEM sample along x (east)
  double sample_y_metres = 1.0;    // and along y (rows, south when north is up)
  double metres_per_height = 1.0;  // a height unit in metres
};

class ReliefSource final : public ImageSource {
 public:
  // `heights` delivers F32 heights with no holes (HeightSource). Reads the
  // DEM once to find its lowest and highest height (the tint's range).
  static Status open(std::unique_ptr<ImageSource> heights, const ReliefOptions& options,
                     std::unique_ptr<ImageSource>* out);

  const SourceInfo& info() const override { return m_info; }
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override;

 private:
  ReliefSource(std::unique_ptr<ImageSource> heights, const ReliefOptions& options);

  std::unique_ptr<ImageSource> m_heights;
  ReliefOptions m_options;
  SourceInfo m_info;
  double m_min = 0.0, m_max = 0.0;
  std::vector<float> m_window;  // heights of the samples the last read needed
};

}  // namespace clipstream
