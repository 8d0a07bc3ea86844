// Building one pyramid level from the level below it, one output row at a
// time. The caller gathers the input rows a filter needs (already clamped to
// the image, see docs/tiler.md) and this file does the arithmetic.
//
// Thread-safe: pure functions; a Downsampler is immutable after
// construction and may be shared by any number of threads.
#pragma once

#include <clipstream/store/types.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace clipstream {

class Downsampler {
 public:
  // `linear_light` applies to the Lanczos filter on 8-bit colour formats:
  // samples are decoded from sRGB, filtered, and re-encoded. Alpha and R16
  // are always filtered as stored.
  Downsampler(DownsampleFilter filter, bool linear_light, PixelFormat format);

  // Output row y of the coarser level reads input rows
  // y * 2 + firstTap() .. y * 2 + firstTap() + tapCount() - 1, each clamped
  // to [0, input height - 1] by the caller.
  int firstTap() const { return m_first_tap; }
  int tapCount() const { return int(m_weights.size()); }

  // Writes ceil(width_in / 2) pixels to `out` from the tapCount() input rows
  // in `rows` (each width_in pixels in the format). Columns past the right
  // edge are clamped to the last one. `scratch` is caller-owned working
  // memory (resized as needed) so a thread can reuse it across rows.
  void downsampleRow(const uint8_t* const* rows, uint64_t width_in, uint8_t* out,
                     std::vector<float>* scratch) const;

  // The normalised 1-D weights of the filter (2 for box, 12 for Lanczos-3).
  const std::vector<float>& weights() const { return m_weights; }

 private:
  void boxRow(const uint8_t* a, const uint8_t* b, uint64_t width_in, uint8_t* out) const;
  void filteredRow(const uint8_t* const* rows, uint64_t width_in, uint8_t* out,
                   std::vector<float>* scratch) const;

  DownsampleFilter m_filter;
  bool m_linear_light;
  PixelFormat m_format;
  int m_first_tap = 0;
  std::vector<float> m_weights;
};

// sRGB transfer functions used by --linear-light (exact IEC 61966-2-1
// curves; decode of 8-bit values is table driven).
float srgbToLinear(float encoded);
float linearToSrgb(float linear);

}  // namespace clipstream
