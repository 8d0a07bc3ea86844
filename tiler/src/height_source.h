// Heights for elevation stores: wraps the image source that decodes a DEM
// (delivering its native samples as I16, R16 or F32) and hands the pyramid
// builder rows in the store's format with every no-data sample filled from
// its valid neighbours, optionally quantised to R16. See docs/terrain.md
// ("Elevation stores") for the fill rule and its limits.
//
// Thread rule: like every ImageSource, used by one thread at a time (the
// tiler's reader thread); the statistics are read after the run.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/tiler/image_source.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

// How far (in samples) the fill looks for valid neighbours along each of
// eight directions. A no-data sample farther than this from any valid one
// (the inside of a large void, an ocean) takes the lowest valid height
// within reach instead: flat ground at the hole's lowest rim, never a spike.
// 32 covers the voids of SRTM and the skewed-quad edges of USGS DEMs while
// keeping the search (8 x 32 probes per hole sample) cheap.
inline constexpr uint32_t kHeightFillRadius = 32;

struct HeightConversion {
  PixelFormat stored = PixelFormat::kF32;  // I16, R16 or F32; R16 from F32 input quantises
  bool has_nodata = false;
  double nodata = 0.0;  // NaN samples count as no-data whatever this says
  double scale = 1.0;   // stored height = offset + scale * sample (quantised R16)
  double offset = 0.0;
};

class HeightSource final : public ImageSource {
 public:
  // `inner` delivers the native samples (its info().format is I16, R16 or F32).
  HeightSource(std::unique_ptr<ImageSource> inner, const HeightConversion& conversion);

  const SourceInfo& info() const override { return m_info; }
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override;

  uint64_t filledSamples() const { return m_filled; }
  double maxError() const { return m_max_error; }  // largest |stored - input| of a valid sample

 private:
  // Reads [x0, x0 + w) x [y0, y0 + h) of the native samples as heights;
  // valid[i] says whether sample i is a height (not no-data, not NaN).
  Status readHeights(uint64_t y0, uint64_t h, uint64_t x0, uint64_t w, std::vector<float>* out,
                     std::vector<uint8_t>* valid);
  double fill(const std::vector<float>& heights, const std::vector<uint8_t>& valid, uint64_t w,
              uint64_t h, uint64_t x, uint64_t y, double fallback) const;
  void store(double height, bool was_valid, uint8_t* dst);

  std::unique_ptr<ImageSource> m_inner;
  HeightConversion m_conversion;
  SourceInfo m_info;
  std::vector<uint8_t> m_native;
  std::vector<float> m_heights, m_halo;  // float: exact for I16, R16 and F32 samples
  std::vector<uint8_t> m_valid, m_halo_valid;
  double m_last_fallback = 0.0;
  uint64_t m_filled = 0;
  double m_max_error = 0.0;
};

// The lowest and highest valid height of `source` (native samples as above),
// read strip by strip: the offset and range of a quantised store.
// kInvalidArgument when the input holds no valid sample at all.
Status scanHeightRange(ImageSource* source, const HeightConversion& conversion, double* min,
                       double* max);

}  // namespace clipstream
