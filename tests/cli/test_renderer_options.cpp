// The renderer's option values: every word the reports print parses back
// to its mode, anything else is refused with the message the programs show.
#include <clipstream/cli/renderer_options.h>

#include <gtest/gtest.h>

namespace clipstream::cli {
namespace {

TEST(RendererOptions, ParsesEveryBufferingByItsReportName) {
  for (Buffering b : {Buffering::kSingle, Buffering::kDoubleUploadTwice, Buffering::kDoubleCopy,
                      Buffering::kStaged}) {
    Buffering parsed = b == Buffering::kSingle ? Buffering::kStaged : Buffering::kSingle;
    ASSERT_TRUE(parseBuffering(bufferingName(b), &parsed).ok()) << bufferingName(b);
    EXPECT_TRUE(parsed == b) << bufferingName(b);
  }
}

TEST(RendererOptions, RefusesOtherBufferingsNamingTheChoices) {
  for (const char* text : {"", "triple", "Single", "double", " staged"}) {
    Buffering parsed = Buffering::kDoubleCopy;
    const Status s = parseBuffering(text, &parsed);
    EXPECT_EQ(s.code, ErrorCode::kInvalidArgument) << '\'' << text << '\'';
    EXPECT_TRUE(parsed == Buffering::kDoubleCopy) << "changed on a refused word";
  }
  Buffering parsed;
  EXPECT_EQ(parseBuffering("triple", &parsed).message,
            "buffering \"triple\" is not single, double-upload, double-copy or staged");
  // Control bytes in the word are shown as '?' and long words cut.
  EXPECT_EQ(parseBuffering("a\nb", &parsed).message,
            "buffering \"a?b\" is not single, double-upload, double-copy or staged");
}

TEST(RendererOptions, ParsesEveryTerrainMethodByItsReportName) {
  for (TerrainMethod m : {TerrainMethod::kClipmap, TerrainMethod::kQuadtree, TerrainMethod::kFlat,
                          TerrainMethod::kFull}) {
    TerrainMethod parsed = m == TerrainMethod::kClipmap ? TerrainMethod::kFull : TerrainMethod::kClipmap;
    ASSERT_TRUE(parseTerrainMethod(terrainMethodName(m), &parsed).ok()) << terrainMethodName(m);
    EXPECT_EQ(parsed, m) << terrainMethodName(m);
  }
  TerrainMethod parsed = TerrainMethod::kFlat;
  const Status s = parseTerrainMethod("mesh", &parsed);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.message, "terrain method 'mesh': must be clipmap, quadtree, flat or full");
  EXPECT_EQ(parsed, TerrainMethod::kFlat);
}

// "auto" is automaticTextureMemory() of the terrain and buffering; a
// choice given is taken as given; --pool-mb needs the pool.
TEST(RendererOptions, TextureMemoryAutoFollowsTheRendererAndThePoolNeedsPaged) {
  TextureMemory m = TextureMemory::kStack;
  ASSERT_TRUE(parseTextureMemory("auto", false, Buffering::kStaged, false, &m).ok());
  EXPECT_TRUE(m == TextureMemory::kPaged);
  ASSERT_TRUE(parseTextureMemory("auto", true, Buffering::kStaged, false, &m).ok());
  EXPECT_TRUE(m == TextureMemory::kStack);
  ASSERT_TRUE(parseTextureMemory("auto", false, Buffering::kDoubleCopy, false, &m).ok());
  EXPECT_TRUE(m == TextureMemory::kStack);
  for (TextureMemory given : {TextureMemory::kStack, TextureMemory::kPaged}) {
    m = given == TextureMemory::kStack ? TextureMemory::kPaged : TextureMemory::kStack;
    ASSERT_TRUE(parseTextureMemory(textureMemoryName(given), true, Buffering::kDoubleCopy, false, &m).ok());
    EXPECT_TRUE(m == given) << textureMemoryName(given);
  }
  ASSERT_TRUE(parseTextureMemory("paged", false, Buffering::kStaged, true, &m).ok());
  ASSERT_TRUE(parseTextureMemory("auto", false, Buffering::kSingle, true, &m).ok());

  EXPECT_EQ(parseTextureMemory("foo", false, Buffering::kStaged, false, &m).message,
            "--texture-memory foo is not one of: auto, stack, paged");
  EXPECT_EQ(parseTextureMemory("Stack", false, Buffering::kStaged, false, &m).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(parseTextureMemory("stack", false, Buffering::kStaged, true, &m).message,
            "--pool-mb sizes the pool of --texture-memory paged");
  EXPECT_EQ(parseTextureMemory("auto", false, Buffering::kDoubleUploadTwice, true, &m).message,
            "--pool-mb sizes the page pool, and auto chose the stack (the pool does not draw double "
            "buffering yet)");
  EXPECT_EQ(parseTextureMemory("auto", true, Buffering::kStaged, true, &m).message,
            "--pool-mb sizes the page pool, and auto chose the stack (the pool does not draw --elevation yet)");
}

}  // namespace
TEST(RendererOptions, ParsesTheColourTileFormatsOnly) {
  TileContent c = TileContent::kRgba8;
  EXPECT_TRUE(cli::parseTileFormat("bc1", &c).ok());
  EXPECT_EQ(c, TileContent::kBc1);
  EXPECT_TRUE(cli::parseTileFormat("rgba8", &c).ok());
  EXPECT_EQ(c, TileContent::kRgba8);
  const Status bc7 = cli::parseTileFormat("bc7", &c);
  EXPECT_EQ(bc7.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(bc7.message, "tile format \"bc7\" is not rgba8 or bc1");
  EXPECT_EQ(cli::parseTileFormat("f32", &c).code, ErrorCode::kInvalidArgument);  // heights are not colour
  EXPECT_EQ(c, TileContent::kRgba8);  // untouched on failure
}

}  // namespace clipstream::cli
