// The downsampling filters (downsample.h) on hand-computed rows: the box
// filter's odd edge and the Lanczos-3 weights. Whole pyramids against the
// reference implementations are in test_roundtrip.cpp.
#include <clipstream/tiler/downsample.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

namespace clipstream::test {
namespace {

TEST(Downsampler, BoxOddEdgeAveragesAvailablePixels) {
  Downsampler box(DownsampleFilter::kBox, false, PixelFormat::kR8);
  const uint8_t a[3] = {10, 20, 31};
  const uint8_t b[3] = {11, 21, 40};
  const uint8_t* rows[2] = {a, b};
  uint8_t out[2] = {};
  std::vector<float> scratch;
  box.downsampleRow(rows, 3, out, &scratch);
  EXPECT_EQ(out[0], (10 + 20 + 11 + 21 + 2) / 4);
  EXPECT_EQ(out[1], (31 + 40 + 1) / 2);
}

TEST(Downsampler, LanczosWeightsAreNormalisedAndSymmetric) {
  Downsampler l(DownsampleFilter::kLanczos3, false, PixelFormat::kRGB8);
  ASSERT_EQ(l.tapCount(), 12);
  EXPECT_EQ(l.firstTap(), -5);
  double sum = 0;
  for (float w : l.weights()) sum += w;
  EXPECT_NEAR(sum, 1.0, 1e-6);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(l.weights()[size_t(k)], l.weights()[size_t(11 - k)], 1e-7);
}

}  // namespace
}  // namespace clipstream::test
