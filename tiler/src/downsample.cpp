// Pyramid filters. The box filter is integer-exact ((sum + 2) / 4); the
// Lanczos-3 filter decimates by exactly two, so its weights are the same for
// every output pixel and are computed once here.
#include <clipstream/tiler/downsample.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <numbers>

namespace clipstream {
namespace {

static_assert(std::endian::native == std::endian::little,
              "R16 samples are little-endian on disk and handled in place");

double sinc(double x) {
  if (x == 0.0) return 1.0;
  const double px = std::numbers::pi * x;
  return std::sin(px) / px;
}

const std::array<float, 256>& srgbDecodeTable() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[size_t(i)] = srgbToLinear(float(i) / 255.0f);
    return t;
  }();
  return table;
}

// Linear -> sRGB code values through a 64 Ki-entry table: fine enough near
// black, where the curve is steepest, to be within one code of exact.
constexpr int kEncodeSteps = 65536;
const std::array<uint8_t, kEncodeSteps + 1>& srgbEncodeTable() {
  static const std::array<uint8_t, kEncodeSteps + 1> table = [] {
    std::array<uint8_t, kEncodeSteps + 1> t{};
    for (int i = 0; i <= kEncodeSteps; ++i) {
      const float v = linearToSrgb(float(i) / float(kEncodeSteps)) * 255.0f + 0.5f;
      t[size_t(i)] = uint8_t(std::clamp(v, 0.0f, 255.0f));
    }
    return t;
  }();
  return table;
}

}  // namespace

float srgbToLinear(float e) {
  return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
}

float linearToSrgb(float l) {
  if (l <= 0.0f) return 0.0f;
  if (l >= 1.0f) return 1.0f;
  return l <= 0.0031308f ? l * 12.92f : 1.055f * std::pow(l, 1.0f / 2.4f) - 0.055f;
}

Downsampler::Downsampler(DownsampleFilter filter, bool linear_light, PixelFormat format)
    : m_filter(filter), m_linear_light(linear_light), m_format(format) {
  if (filter == DownsampleFilter::kDecimate) {
    // Output sample y is input sample 2y. The second tap (weight 0) makes
    // the builder wait for row 2y + 1, so a finer tile row is always emitted
    // before the coarser one built from it (the tiler's height bounds
    // depend on that order).
    m_first_tap = 0;
    m_weights = {1.0f, 0.0f};
    return;
  }
  if (filter == DownsampleFilter::kBox) {
    m_first_tap = 0;
    m_weights = {0.5f, 0.5f};
    return;
  }
  // Output pixel y covers input [2y, 2y + 2); its centre is input 2y + 1.
  // Input pixel j's centre j + 0.5 lies (j + 0.5 - (2y + 1)) / 2 output
  // pixels away; Lanczos-3 at the output scale reaches 3 output = 6 input
  // pixels each side: taps 2y - 5 .. 2y + 6.
  m_first_tap = -5;
  double sum = 0.0;
  std::array<double, 12> w{};
  for (int k = 0; k < 12; ++k) {
    const double d = (double(k + m_first_tap) - 0.5) / 2.0;
    w[size_t(k)] = std::abs(d) < 3.0 ? sinc(d) * sinc(d / 3.0) : 0.0;
    sum += w[size_t(k)];
  }
  for (double v : w) m_weights.push_back(float(v / sum));
}

void Downsampler::downsampleRow(const uint8_t* const* rows, uint64_t width_in, uint8_t* out,
                                std::vector<float>* scratch) const {
  if (m_filter == DownsampleFilter::kDecimate) {
    const size_t bpp = bytesPerPixel(m_format);
    const uint64_t width_out = (width_in + 1) / 2;
    for (uint64_t x = 0; x < width_out; ++x) std::memcpy(out + x * bpp, rows[0] + 2 * x * bpp, bpp);
  } else if (m_filter == DownsampleFilter::kBox) {
    boxRow(rows[0], rows[1], width_in, out);
  } else {
    filteredRow(rows, width_in, out, scratch);
  }
}

void Downsampler::boxRow(const uint8_t* a, const uint8_t* b, uint64_t width_in,
                         uint8_t* out) const {
  const uint64_t pairs = width_in / 2;
  const bool odd = (width_in & 1) != 0;
  // An odd last column is averaged with itself (edge clamp), which equals
  // the average of the pixels that exist: (2a + 2b + 2) / 4 == (a + b + 1) / 2.
  if (m_format == PixelFormat::kR16) {
    const auto* a16 = reinterpret_cast<const uint16_t*>(a);
    const auto* b16 = reinterpret_cast<const uint16_t*>(b);
    auto* o16 = reinterpret_cast<uint16_t*>(out);
    for (uint64_t x = 0; x < pairs; ++x) {
      const uint32_t s = uint32_t(a16[2 * x]) + a16[2 * x + 1] + b16[2 * x] + b16[2 * x + 1];
      o16[x] = uint16_t((s + 2) >> 2);
    }
    if (odd) {
      const uint32_t s = 2u * a16[width_in - 1] + 2u * b16[width_in - 1];
      o16[pairs] = uint16_t((s + 2) >> 2);
    }
    return;
  }
  const uint32_t nc = channelCount(m_format);
  auto body = [&](auto ncc) {
    constexpr uint32_t kNc = decltype(ncc)::value;
    for (uint64_t x = 0; x < pairs; ++x) {
      const uint8_t* pa = a + x * 2 * kNc;
      const uint8_t* pb = b + x * 2 * kNc;
      uint8_t* po = out + x * kNc;
      for (uint32_t c = 0; c < kNc; ++c) {
        const uint32_t s = uint32_t(pa[c]) + pa[c + kNc] + pb[c] + pb[c + kNc];
        po[c] = uint8_t((s + 2) >> 2);
      }
    }
  };
  switch (nc) {
    case 1: body(std::integral_constant<uint32_t, 1>{}); break;
    case 3: body(std::integral_constant<uint32_t, 3>{}); break;
    default: body(std::integral_constant<uint32_t, 4>{}); break;
  }
  if (odd) {
    const uint8_t* pa = a + (width_in - 1) * nc;
    const uint8_t* pb = b + (width_in - 1) * nc;
    uint8_t* po = out + pairs * nc;
    for (uint32_t c = 0; c < nc; ++c) po[c] = uint8_t((2u * pa[c] + 2u * pb[c] + 2u) >> 2);
  }
}

void Downsampler::filteredRow(const uint8_t* const* rows, uint64_t width_in, uint8_t* out,
                              std::vector<float>* scratch) const {
  const uint32_t nc = channelCount(m_format);
  const bool is16 = m_format == PixelFormat::kR16;
  const uint64_t width_out = (width_in + 1) / 2;
  const size_t samples_in = size_t(width_in) * nc;
  scratch->resize(samples_in);
  float* col = scratch->data();
  const int taps = tapCount();
  const auto& decode = srgbDecodeTable();
  const bool gamma = m_linear_light && !is16;
  // Alpha stays linear in linear-light mode.
  const uint32_t colour_channels = (m_format == PixelFormat::kRGBA8) ? 3 : nc;

  // Vertical pass into a float row.
  std::fill(col, col + samples_in, 0.0f);
  for (int k = 0; k < taps; ++k) {
    const float w = m_weights[size_t(k)];
    if (is16) {
      const auto* r = reinterpret_cast<const uint16_t*>(rows[k]);
      for (size_t i = 0; i < samples_in; ++i) col[i] += w * float(r[i]);
    } else if (gamma) {
      const uint8_t* r = rows[k];
      for (size_t i = 0; i < samples_in; ++i) {
        const uint32_t c = uint32_t(i % nc);
        col[i] += w * (c < colour_channels ? decode[r[i]] : float(r[i]) * (1.0f / 255.0f));
      }
    } else {
      const uint8_t* r = rows[k];
      for (size_t i = 0; i < samples_in; ++i) col[i] += w * float(r[i]);
    }
  }

  // Horizontal pass with edge clamp, then quantise.
  const int64_t last = int64_t(width_in) - 1;
  for (uint64_t x = 0; x < width_out; ++x) {
    for (uint32_t c = 0; c < nc; ++c) {
      float acc = 0.0f;
      for (int k = 0; k < taps; ++k) {
        const int64_t sx = std::clamp<int64_t>(int64_t(2 * x) + m_first_tap + k, 0, last);
        acc += m_weights[size_t(k)] * col[size_t(sx) * nc + c];
      }
      if (is16) {
        reinterpret_cast<uint16_t*>(out)[x] = uint16_t(std::clamp(acc + 0.5f, 0.0f, 65535.0f));
      } else if (gamma && c < colour_channels) {
        const float idx = std::clamp(acc, 0.0f, 1.0f) * float(kEncodeSteps) + 0.5f;
        out[x * nc + c] = srgbEncodeTable()[size_t(idx)];
      } else if (gamma) {
        out[x * nc + c] = uint8_t(std::clamp(acc * 255.0f + 0.5f, 0.0f, 255.0f));
      } else {
        out[x * nc + c] = uint8_t(std::clamp(acc + 0.5f, 0.0f, 255.0f));
      }
    }
  }
}

}  // namespace clipstream
