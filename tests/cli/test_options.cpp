// Option values the programs share: pixel formats.
#include <clipstream/cli/cli.h>

#include <gtest/gtest.h>

namespace clipstream::cli {
namespace {

TEST(CliOptions, ParsesEveryPixelFormatInAnyCase) {
  EXPECT_EQ(parsePixelFormat("R8"), PixelFormat::kR8);
  EXPECT_EQ(parsePixelFormat("r16"), PixelFormat::kR16);
  EXPECT_EQ(parsePixelFormat("Rgb8"), PixelFormat::kRGB8);
  EXPECT_EQ(parsePixelFormat("rgba8"), PixelFormat::kRGBA8);
}

TEST(CliOptions, RejectsAnythingElseAsAPixelFormat) {
  for (const char* text : {"", "R", "RGB", "RGB16", " R8", "R8 ", "R8\n", "RGBA8x", "unknown"}) {
    EXPECT_EQ(parsePixelFormat(text), std::nullopt) << '\'' << text << '\'';
  }
}

}  // namespace
}  // namespace clipstream::cli
