// The tile codec alone, no file: encodeTile() / decodeTile() (constant
// tiles, the predictor at wrap-around, exactly one zstd frame), and
// decodeTileRgba8 (fused predictor inverse + RGBA8 expansion) against the
// plain path: decodeTile() into the stored format, then a per-pixel
// expansion written here independently. Metric: every output byte equal.
#include <clipstream/store/tile_store.h>
#include <clipstream/testing/synthetic_store.h>

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace clipstream {
namespace {

// The reference expansion: grey for R8/R16 (R16 keeps its high, second,
// byte), A = 255 unless stored.
std::vector<uint8_t> expandReference(const std::vector<uint8_t>& pixels, PixelFormat format) {
  const size_t bpp = bytesPerPixel(format), n = pixels.size() / bpp;
  std::vector<uint8_t> out(n * 4);
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* p = &pixels[i * bpp];
    uint8_t* o = &out[i * 4];
    switch (format) {
      case PixelFormat::kR8: o[0] = o[1] = o[2] = p[0]; o[3] = 255; break;
      case PixelFormat::kR16: o[0] = o[1] = o[2] = p[1]; o[3] = 255; break;
      case PixelFormat::kRGB8: o[0] = p[0]; o[1] = p[1]; o[2] = p[2]; o[3] = 255; break;
      case PixelFormat::kRGBA8: std::memcpy(o, p, 4); break;
      case PixelFormat::kI16:
      case PixelFormat::kF32: break;  // heights: no colour
    }
  }
  return out;
}

enum class Content { kRandom, kConstant, kExtremes, kGradient, kTwoValues };

// Contents chosen to stress the prefix sums: random bytes (every sum wraps),
// 0/255 alternation (largest deltas), long ramps, runs of two values.
std::vector<uint8_t> makeContent(const PyramidGeometry& g, Content content, uint32_t seed) {
  std::vector<uint8_t> px(g.tileBytes());
  std::mt19937 rng(seed);
  const size_t bpp = bytesPerPixel(g.format);
  for (size_t i = 0; i < px.size(); ++i) {
    const size_t pixel = i / bpp, x = pixel % g.tile_px, y = pixel / g.tile_px;
    switch (content) {
      case Content::kRandom: px[i] = uint8_t(rng()); break;
      case Content::kConstant: px[i] = uint8_t(0x5a + i % bpp * 17); break;
      case Content::kExtremes: px[i] = ((x + y + i % bpp) & 1) ? 255 : 0; break;
      case Content::kGradient: px[i] = uint8_t(x * 7 + y * 3 + (i % bpp) * 50); break;
      case Content::kTwoValues: px[i] = (rng() % 8 == 0) ? 250 : 3; break;
    }
  }
  return px;
}

TEST(StoreDecodeRgba8, FusedPathEqualsPlainDecodeForEveryFormatAndEncoding) {
  const PixelFormat formats[] = {PixelFormat::kR8, PixelFormat::kR16, PixelFormat::kRGB8,
                                 PixelFormat::kRGBA8};
  // Odd sizes exercise the scalar tails after the 4/8/16-pixel blocks.
  const uint32_t tile_sizes[] = {1, 3, 5, 15, 16, 17, 33, 128};
  const Content contents[] = {Content::kRandom, Content::kConstant, Content::kExtremes,
                              Content::kGradient, Content::kTwoValues};
  int checked = 0;
  for (PixelFormat format : formats)
    for (uint32_t tile_px : tile_sizes)
      for (Predictor predictor : {Predictor::kNone, Predictor::kLeftDelta})
        for (Compression compression : {Compression::kNone, Compression::kZstd})
          for (Content content : contents) {
            PyramidGeometry g;
            ASSERT_TRUE(makePyramidGeometry(tile_px * 2, tile_px, tile_px, format, &g));
            StoreEncoding enc;
            enc.predictor = predictor;
            enc.compression = compression;
            enc.zstd_level = 1;
            const TileKey key{0, 1, 0};
            const std::vector<uint8_t> pixels = makeContent(g, content, uint32_t(checked));
            EncodedTile encoded;
            ASSERT_TRUE(encodeTile(g, enc, key, pixels, &encoded).ok());
            RawTile raw;
            raw.key = key;
            raw.location = encoded.location;
            raw.payload = encoded.payload;

            std::vector<uint8_t> plain(g.tileBytes());
            ASSERT_TRUE(decodeTile(g, enc, raw, plain).ok());
            ASSERT_EQ(plain, pixels);
            const std::vector<uint8_t> want = expandReference(plain, format);
            std::vector<uint8_t> got(size_t(tile_px) * tile_px * 4, 0xCD);
            const Status status = decodeTileRgba8(g, enc, raw, got);
            ASSERT_TRUE(status.ok()) << status.toString();
            ASSERT_EQ(got, want) << "format " << int(format) << " tile " << tile_px
                                 << " predictor " << int(predictor) << " compression "
                                 << int(compression) << " content " << int(content);
            ++checked;
          }
  EXPECT_EQ(checked, 4 * 8 * 2 * 2 * 5);
}

TEST(StoreDecodeRgba8, RejectsWhatDecodeTileRejects) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 32, PixelFormat::kRGB8, &g));
  StoreEncoding enc;
  const TileKey key{0, 0, 0};
  std::vector<uint8_t> pixels(g.tileBytes());
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t(i * 31 / 7);
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(g, enc, key, pixels, &encoded).ok());
  RawTile raw{key, encoded.location, encoded.payload};
  std::vector<uint8_t> rgba(32 * 32 * 4);

  std::vector<uint8_t> small(rgba.size() - 4);
  EXPECT_EQ(decodeTileRgba8(g, enc, raw, small).code, ErrorCode::kInvalidArgument);

  RawTile truncated = raw;
  truncated.payload.resize(truncated.payload.size() / 2);
  truncated.location.stored_bytes = uint32_t(truncated.payload.size());
  std::vector<uint8_t> plain(g.tileBytes());
  const Status want = decodeTile(g, enc, truncated, plain);
  const Status got = decodeTileRgba8(g, enc, truncated, rgba);
  EXPECT_FALSE(got.ok());
  EXPECT_EQ(got.code, want.code);
  EXPECT_EQ(got.code, ErrorCode::kCorruptTile);
}

TEST(StoreEncode, ConstantTilesHaveNoPayloadAndKeepTheirValue) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(256, 256, 16, PixelFormat::kRGB8, &g));
  std::vector<uint8_t> pixels(g.tileBytes());
  for (size_t i = 0; i < pixels.size(); i += 3) {
    pixels[i] = 10;
    pixels[i + 1] = 20;
    pixels[i + 2] = 30;
  }
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(g, StoreEncoding{}, TileKey{0, 1, 2}, pixels, &encoded).ok());
  EXPECT_TRUE(encoded.location.constant);
  EXPECT_TRUE(encoded.payload.empty());
  EXPECT_EQ(encoded.location.constant_pixel[0], 10);
  EXPECT_EQ(encoded.location.constant_pixel[1], 20);
  EXPECT_EQ(encoded.location.constant_pixel[2], 30);
  pixels[pixels.size() - 1] = 31;  // one sample differs: no longer constant
  ASSERT_TRUE(encodeTile(g, StoreEncoding{}, TileKey{0, 1, 2}, pixels, &encoded).ok());
  EXPECT_FALSE(encoded.location.constant);
  EXPECT_FALSE(encoded.payload.empty());
}

TEST(StoreDecode, RejectsBytesAfterTheZstdFrame) {
  // A payload is exactly one frame. ZSTD_decompressDCtx alone would accept a
  // trailing skippable frame (or a second frame that fits), so the decoder
  // checks the frame length itself.
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(16, 16, 16, PixelFormat::kRGB8, &g));
  StoreEncoding encoding;  // zstd + left delta
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(g, encoding, {}, test::syntheticTile(g, {}, test::ConstantTiles::kNone), &encoded).ok());
  RawTile raw;
  raw.location = encoded.location;
  raw.payload = encoded.payload;
  std::vector<uint8_t> pixels(g.tileBytes());
  ASSERT_TRUE(decodeTile(g, encoding, raw, pixels).ok());
  // Skippable frame: magic 0x184D2A50, zero-length body.
  for (uint8_t b : {0x50, 0x2A, 0x4D, 0x18, 0x00, 0x00, 0x00, 0x00}) raw.payload.push_back(b);
  raw.location.stored_bytes = static_cast<uint32_t>(raw.payload.size());
  Status status = decodeTile(g, encoding, raw, pixels);
  EXPECT_EQ(status.code, ErrorCode::kCorruptTile) << status.toString();
  EXPECT_NE(status.message.find("exactly one zstd frame"), std::string::npos) << status.message;
  // A truncated frame is reported too, never read past.
  raw.payload.assign(encoded.payload.begin(), encoded.payload.end() - 1);
  raw.location.stored_bytes = static_cast<uint32_t>(raw.payload.size());
  EXPECT_EQ(decodeTile(g, encoding, raw, pixels).code, ErrorCode::kCorruptTile);
}

TEST(StoreEncode, PredictorRoundTripsEveryFormatAtWrapAround) {
  // Values that wrap modulo 2^bits between neighbours.
  for (PixelFormat format : {PixelFormat::kR8, PixelFormat::kR16, PixelFormat::kRGB8,
                             PixelFormat::kRGBA8}) {
    PyramidGeometry g;
    ASSERT_TRUE(makePyramidGeometry(16, 16, 16, format, &g));
    std::vector<uint8_t> pixels(g.tileBytes());
    std::mt19937 rng(42);
    for (uint8_t& b : pixels) b = (rng() & 1) ? 0xff : 0x00;
    pixels[0] = 1;
    for (Compression compression : {Compression::kNone, Compression::kZstd}) {
      StoreEncoding encoding;
      encoding.compression = compression;
      encoding.predictor = Predictor::kLeftDelta;
      EncodedTile encoded;
      ASSERT_TRUE(encodeTile(g, encoding, {}, pixels, &encoded).ok());
      RawTile raw;
      raw.location = encoded.location;
      raw.payload = encoded.payload;
      std::vector<uint8_t> decoded(g.tileBytes());
      ASSERT_TRUE(decodeTile(g, encoding, raw, decoded).ok());
      EXPECT_EQ(decoded, pixels) << pixelFormatName(format);
    }
  }
}

}  // namespace
}  // namespace clipstream
