// Tile payload codec: constant detection, left-delta predictor and zstd.
// encodeTile() and TileStoreReader::decode() are the only producers and
// consumers of payload bytes.
#include "format.h"

#include <clipstream/store/tile_store.h>

#include <zstd.h>

#include <algorithm>
#include <memory>

namespace clipstream {
namespace {

// Single-channel 32-bit samples (F32) as little-endian u32 words.
void applyLeftDelta32(const uint8_t* in, uint8_t* out, uint32_t tile_px) {
  for (uint32_t y = 0; y < tile_px; ++y) {
    uint32_t previous = 0;
    for (uint32_t x = 0; x < tile_px; ++x) {
      uint32_t value;
      std::memcpy(&value, in + (size_t(y) * tile_px + x) * 4, 4);
      const uint32_t delta = value - previous;
      std::memcpy(out + (size_t(y) * tile_px + x) * 4, &delta, 4);
      previous = value;
    }
  }
}

void undoLeftDelta32(uint8_t* pixels, uint32_t tile_px) {
  for (uint32_t y = 0; y < tile_px; ++y) {
    uint32_t run = 0;
    for (uint32_t x = 0; x < tile_px; ++x) {
      uint32_t delta;
      std::memcpy(&delta, pixels + (size_t(y) * tile_px + x) * 4, 4);
      run += delta;
      std::memcpy(pixels + (size_t(y) * tile_px + x) * 4, &run, 4);
    }
  }
}

// Per row, per channel: out[x] = in[x] - in[x - 1] modulo the sample width.
// The first pixel of each row is kept as is. 16-bit samples (R16, I16) are
// treated as little-endian u16, F32 samples as u32 words.
void applyLeftDelta(const uint8_t* in, uint8_t* out, uint32_t tile_px, PixelFormat format) {
  const size_t row_bytes = size_t(tile_px) * bytesPerPixel(format);
  if (format == PixelFormat::kF32) {
    applyLeftDelta32(in, out, tile_px);
    return;
  }
  if (format == PixelFormat::kR16 || format == PixelFormat::kI16) {
    for (uint32_t y = 0; y < tile_px; ++y) {
      const uint8_t* src = in + y * row_bytes;
      uint8_t* dst = out + y * row_bytes;
      uint16_t previous = 0;
      for (uint32_t x = 0; x < tile_px; ++x) {
        const uint16_t value = uint16_t(src[2 * x] | (src[2 * x + 1] << 8));
        const uint16_t delta = uint16_t(value - previous);
        dst[2 * x] = uint8_t(delta & 0xff);
        dst[2 * x + 1] = uint8_t(delta >> 8);
        previous = value;
      }
    }
    return;
  }
  const size_t bpp = bytesPerPixel(format);
  for (uint32_t y = 0; y < tile_px; ++y) {
    const uint8_t* src = in + y * row_bytes;
    uint8_t* dst = out + y * row_bytes;
    std::copy(src, src + bpp, dst);
    for (size_t i = bpp; i < row_bytes; ++i) dst[i] = uint8_t(src[i] - src[i - bpp]);
  }
}

// Vectorised rows of undoLeftDelta (defined with decodeTileRgba8 below);
// false when this build or CPU has no fast path for the format.
bool undoLeftDeltaFast(uint8_t* pixels, uint32_t tile_px, PixelFormat format);

// Inverse of applyLeftDelta, in place.
void undoLeftDelta(uint8_t* pixels, uint32_t tile_px, PixelFormat format) {
  if (undoLeftDeltaFast(pixels, tile_px, format)) return;
  const size_t row_bytes = size_t(tile_px) * bytesPerPixel(format);
  if (format == PixelFormat::kF32) {
    undoLeftDelta32(pixels, tile_px);
    return;
  }
  if (format == PixelFormat::kR16 || format == PixelFormat::kI16) {
    for (uint32_t y = 0; y < tile_px; ++y) {
      uint8_t* row = pixels + y * row_bytes;
      uint16_t previous = 0;
      for (uint32_t x = 0; x < tile_px; ++x) {
        const uint16_t delta = uint16_t(row[2 * x] | (row[2 * x + 1] << 8));
        const uint16_t value = uint16_t(previous + delta);
        row[2 * x] = uint8_t(value & 0xff);
        row[2 * x + 1] = uint8_t(value >> 8);
        previous = value;
      }
    }
    return;
  }
  // Portable fallback. Each byte depends on the one a pixel earlier;
  // measured faster than keeping per-channel sums in locals (which GCC 12
  // spills).
  const size_t bpp = bytesPerPixel(format);
  for (uint32_t y = 0; y < tile_px; ++y) {
    uint8_t* row = pixels + y * row_bytes;
    for (size_t i = bpp; i < row_bytes; ++i) row[i] = uint8_t(row[i] + row[i - bpp]);
  }
}

struct CCtxDeleter {
  void operator()(ZSTD_CCtx* ctx) const { ZSTD_freeCCtx(ctx); }
};
struct DCtxDeleter {
  void operator()(ZSTD_DCtx* ctx) const { ZSTD_freeDCtx(ctx); }
};

// One context per thread: creating a zstd context per tile costs more than
// compressing a small tile.
ZSTD_CCtx* threadCCtx() {
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxDeleter> ctx(ZSTD_createCCtx());
  return ctx.get();
}
ZSTD_DCtx* threadDCtx() {
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxDeleter> ctx(ZSTD_createDCtx());
  return ctx.get();
}

}  // namespace

Status encodeTile(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                  const TileKey& key, std::span<const uint8_t> pixels, EncodedTile* out) {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "encodeTile: null output");
  const size_t tile_bytes = geometry.tileBytes();
  if (pixels.size() != tile_bytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         format::keyText(key) + ": tile has " + std::to_string(pixels.size()) +
                             " bytes, expected " + std::to_string(tile_bytes));
  }
  if (!geometry.contains(key)) {
    return Status::error(ErrorCode::kOutOfRange, format::keyText(key) + " is outside the pyramid");
  }
  out->key = key;
  out->location = TileLocation{};
  out->payload.clear();

  const size_t bpp = bytesPerPixel(geometry.format);
  bool constant = true;
  for (size_t i = bpp; i < tile_bytes; i += bpp) {
    if (std::memcmp(pixels.data() + i, pixels.data(), bpp) != 0) {
      constant = false;
      break;
    }
  }
  if (constant) {
    out->location.constant = true;
    std::memcpy(out->location.constant_pixel, pixels.data(), bpp);
    return okStatus();
  }

  std::vector<uint8_t> predicted;
  std::span<const uint8_t> source = pixels;
  if (encoding.predictor == Predictor::kLeftDelta) {
    predicted.resize(tile_bytes);
    applyLeftDelta(pixels.data(), predicted.data(), geometry.tile_px, geometry.format);
    source = predicted;
  } else if (encoding.predictor != Predictor::kNone) {
    return Status::error(ErrorCode::kInvalidArgument, "unknown predictor");
  }

  if (encoding.compression == Compression::kZstd) {
    out->payload.resize(ZSTD_compressBound(tile_bytes));
    ZSTD_CCtx* ctx = threadCCtx();
    ZSTD_CCtx_reset(ctx, ZSTD_reset_session_and_parameters);
    ZSTD_CCtx_setParameter(ctx, ZSTD_c_compressionLevel, encoding.zstd_level);
    // The frame carries its content size so a reader can reject a payload
    // that claims the wrong size before decompressing it.
    ZSTD_CCtx_setParameter(ctx, ZSTD_c_contentSizeFlag, 1);
    const size_t written = ZSTD_compress2(ctx, out->payload.data(), out->payload.size(),
                                          source.data(), source.size());
    if (ZSTD_isError(written)) {
      return Status::error(ErrorCode::kInvalidArgument,
                           format::keyText(key) + ": zstd: " + ZSTD_getErrorName(written));
    }
    out->payload.resize(written);
  } else if (encoding.compression == Compression::kNone) {
    out->payload.assign(source.begin(), source.end());
  } else {
    return Status::error(ErrorCode::kInvalidArgument, "unknown compression");
  }
  out->location.stored_bytes = static_cast<uint32_t>(out->payload.size());
  out->location.checksum = format::tileChecksum(out->payload.data(), out->payload.size());
  return okStatus();
}

Status decodeTile(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                     const RawTile& raw, std::span<uint8_t> pixels) {
  const size_t tile_bytes = geometry.tileBytes();
  if (pixels.size() != tile_bytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "decode: output holds " + std::to_string(pixels.size()) +
                             " bytes, expected " + std::to_string(tile_bytes));
  }
  const size_t bpp = bytesPerPixel(geometry.format);
  if (raw.location.constant) {
    for (size_t i = 0; i < tile_bytes; i += bpp) {
      std::memcpy(pixels.data() + i, raw.location.constant_pixel, bpp);
    }
    return okStatus();
  }
  const std::string where = format::keyText(raw.key);
  if (raw.payload.size() != raw.location.stored_bytes) {
    return Status::error(ErrorCode::kCorruptTile, where + ": payload size does not match index");
  }
  if (encoding.compression == Compression::kZstd) {
    const unsigned long long content =
        ZSTD_getFrameContentSize(raw.payload.data(), raw.payload.size());
    if (content == ZSTD_CONTENTSIZE_ERROR || content == ZSTD_CONTENTSIZE_UNKNOWN) {
      return Status::error(ErrorCode::kCorruptTile, where + ": payload is not a zstd frame");
    }
    // Exactly one frame: trailing bytes (even a skippable frame, which
    // ZSTD_decompressDCtx would accept) mean the payload is not ours.
    const size_t frame_bytes = ZSTD_findFrameCompressedSize(raw.payload.data(), raw.payload.size());
    if (ZSTD_isError(frame_bytes) || frame_bytes != raw.payload.size()) {
      return Status::error(ErrorCode::kCorruptTile,
                           where + ": payload is not exactly one zstd frame");
    }
    if (content != tile_bytes) {
      return Status::error(ErrorCode::kCorruptTile,
                           where + ": payload decodes to " + std::to_string(content) +
                               " bytes, expected " + std::to_string(tile_bytes));
    }
    const size_t got = ZSTD_decompressDCtx(threadDCtx(), pixels.data(), pixels.size(),
                                           raw.payload.data(), raw.payload.size());
    if (ZSTD_isError(got)) {
      return Status::error(ErrorCode::kCorruptTile,
                           where + ": zstd: " + ZSTD_getErrorName(got));
    }
    if (got != tile_bytes) {
      return Status::error(ErrorCode::kCorruptTile,
                           where + ": payload decoded to " + std::to_string(got) +
                               " bytes, expected " + std::to_string(tile_bytes));
    }
  } else {
    if (raw.payload.size() != tile_bytes) {
      return Status::error(ErrorCode::kCorruptTile,
                           where + ": uncompressed payload has " +
                               std::to_string(raw.payload.size()) + " bytes, expected " +
                               std::to_string(tile_bytes));
    }
    std::memcpy(pixels.data(), raw.payload.data(), tile_bytes);
  }
  if (encoding.predictor == Predictor::kLeftDelta) {
    undoLeftDelta(pixels.data(), geometry.tile_px, geometry.format);
  }
  return okStatus();
}

}  // namespace clipstream

// ---------------------------------------------------------------------------
// decodeTileRgba8: decode + predictor inverse + RGBA8 expansion in one pass.
//
// The left-delta inverse is a prefix sum along each row. Done byte by byte in
// place every byte waits on a store a pixel earlier; here each row is summed
// in registers, four pixels (SSE) or one pixel (portable) at a time, and
// written straight out as RGBA8, so the tile is touched once after zstd
// instead of twice (undo, then convert). The in-place vector rows that
// undoLeftDelta uses live here too (undoLeftDeltaFast).
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace clipstream {
namespace {

inline uint32_t load32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}
inline void storeRgba(uint8_t* dst, uint8_t r, uint8_t g, uint8_t b, uint8_t a) {
  dst[0] = r;
  dst[1] = g;
  dst[2] = b;
  dst[3] = a;
}

// One row of `px` pixels from src (stored format, predictor applied when
// kDelta) to RGBA8 at dst. Grey for R8/R16 (R16 keeps the high byte), A = 255
// unless stored. Same results as undoLeftDelta followed by the streamer's
// conversion, which the store tests check bit for bit.
template <bool kDelta>
void rowR8(const uint8_t* src, uint8_t* dst, uint32_t px) {
  uint32_t x = 0;
  uint8_t run = 0;
#if defined(__SSE2__)
  const __m128i alpha = _mm_set1_epi32(int32_t(0xFF000000u));
  __m128i carry = _mm_setzero_si128();
  for (; x + 16 <= px; x += 16, src += 16, dst += 64) {
    __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src));
    if constexpr (kDelta) {
      v = _mm_add_epi8(v, _mm_slli_si128(v, 1));
      v = _mm_add_epi8(v, _mm_slli_si128(v, 2));
      v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
      v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
      v = _mm_add_epi8(v, carry);
      carry = _mm_shuffle_epi32(_mm_shufflehi_epi16(_mm_unpackhi_epi8(v, v), 0xFF), 0xFF);
    }
    const __m128i lo = _mm_unpacklo_epi8(v, v), hi = _mm_unpackhi_epi8(v, v);
    __m128i* out = reinterpret_cast<__m128i*>(dst);
    _mm_storeu_si128(out + 0, _mm_or_si128(_mm_unpacklo_epi16(lo, lo), alpha));
    _mm_storeu_si128(out + 1, _mm_or_si128(_mm_unpackhi_epi16(lo, lo), alpha));
    _mm_storeu_si128(out + 2, _mm_or_si128(_mm_unpacklo_epi16(hi, hi), alpha));
    _mm_storeu_si128(out + 3, _mm_or_si128(_mm_unpackhi_epi16(hi, hi), alpha));
  }
  run = uint8_t(_mm_cvtsi128_si32(carry));
#endif
  for (; x < px; ++x, ++src, dst += 4) {
    run = kDelta ? uint8_t(run + src[0]) : src[0];
    storeRgba(dst, run, run, run, 255);
  }
}

template <bool kDelta>
void rowR16(const uint8_t* src, uint8_t* dst, uint32_t px) {
  uint32_t x = 0;
  uint16_t run = 0;
#if defined(__SSE2__)
  const __m128i alpha = _mm_set1_epi32(int32_t(0xFF000000u));
  __m128i carry = _mm_setzero_si128();
  for (; x + 8 <= px; x += 8, src += 16, dst += 32) {
    __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src));
    if constexpr (kDelta) {
      v = _mm_add_epi16(v, _mm_slli_si128(v, 2));
      v = _mm_add_epi16(v, _mm_slli_si128(v, 4));
      v = _mm_add_epi16(v, _mm_slli_si128(v, 8));
      v = _mm_add_epi16(v, carry);
      carry = _mm_shuffle_epi32(_mm_shufflehi_epi16(v, 0xFF), 0xFF);
    }
    const __m128i high = _mm_packus_epi16(_mm_srli_epi16(v, 8), _mm_setzero_si128());
    const __m128i twice = _mm_unpacklo_epi8(high, high);
    __m128i* out = reinterpret_cast<__m128i*>(dst);
    _mm_storeu_si128(out + 0, _mm_or_si128(_mm_unpacklo_epi16(twice, twice), alpha));
    _mm_storeu_si128(out + 1, _mm_or_si128(_mm_unpackhi_epi16(twice, twice), alpha));
  }
  run = uint16_t(_mm_cvtsi128_si32(carry));
#endif
  for (; x < px; ++x, src += 2, dst += 4) {
    const uint16_t sample = uint16_t(src[0] | (src[1] << 8));
    run = kDelta ? uint16_t(run + sample) : sample;
    const uint8_t grey = uint8_t(run >> 8);
    storeRgba(dst, grey, grey, grey, 255);
  }
}

// RGB8 and RGBA8 (kChannels 3 or 4). RGBA8 may run in place (src == dst).
template <bool kDelta, int kChannels>
void rowRgb(const uint8_t* src, uint8_t* dst, uint32_t px) {
  uint32_t x = 0;
  uint8_t run[4] = {0, 0, 0, 0};
#if defined(__SSE2__)
  // Byte-wise adds never carry between channels, so the junk in the alpha
  // byte of the RGB8 lanes cannot reach R, G or B; it is overwritten by A=255.
  const __m128i alpha = _mm_set1_epi32(kChannels == 3 ? int32_t(0xFF000000u) : 0);
  __m128i carry = _mm_setzero_si128();
  for (; x + 4 <= px; x += 4, src += 4 * kChannels, dst += 16) {
    __m128i v;
    if constexpr (kChannels == 3) {
      // Four pixels from three 32-bit loads: r0g0b0r1 g1b1r2g2 b2r3g3b3.
      const uint32_t a = load32(src), b = load32(src + 4), c = load32(src + 8);
      v = _mm_set_epi32(int32_t(c >> 8), int32_t((b >> 16) | (c << 16)),
                        int32_t((a >> 24) | (b << 8)), int32_t(a));
    } else {
      v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src));
    }
    if constexpr (kDelta) {
      v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
      v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
      v = _mm_add_epi8(v, carry);
      carry = _mm_shuffle_epi32(v, 0xFF);
    }
    _mm_storeu_si128(reinterpret_cast<__m128i*>(dst), _mm_or_si128(v, alpha));
  }
  const uint32_t last = uint32_t(_mm_cvtsi128_si32(carry));
  std::memcpy(run, &last, 4);
#endif
  for (; x < px; ++x, src += kChannels, dst += 4) {
    for (int c = 0; c < kChannels; ++c) run[c] = kDelta ? uint8_t(run[c] + src[c]) : src[c];
    storeRgba(dst, run[0], run[1], run[2], kChannels == 3 ? 255 : run[3]);
  }
}

#if defined(__SSE2__) && defined(__GNUC__)
#define CLIPSTREAM_HAVE_SSSE3_PATH 1
#include <tmmintrin.h>
// RGB8 rows with one byte shuffle per four pixels (SSSE3, chosen at run
// time). Reads 4 bytes past the row's last pixel: the caller guarantees
// them readable (the row after, or the scratch buffer's padding).
template <bool kDelta>
__attribute__((target("ssse3"))) void rowRgb8Ssse3(const uint8_t* src, uint8_t* dst, uint32_t px) {
  const __m128i spread = _mm_setr_epi8(0, 1, 2, -1, 3, 4, 5, -1, 6, 7, 8, -1, 9, 10, 11, -1);
  const __m128i alpha = _mm_set1_epi32(int32_t(0xFF000000u));
  __m128i carry = _mm_setzero_si128();
  uint32_t x = 0;
  for (; x + 4 <= px; x += 4, src += 12, dst += 16) {
    __m128i v = _mm_shuffle_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(src)), spread);
    if constexpr (kDelta) {
      v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
      v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
      v = _mm_add_epi8(v, carry);
      carry = _mm_shuffle_epi32(v, 0xFF);
    }
    _mm_storeu_si128(reinterpret_cast<__m128i*>(dst), _mm_or_si128(v, alpha));
  }
  uint8_t run[4];
  const uint32_t last = uint32_t(_mm_cvtsi128_si32(carry));
  std::memcpy(run, &last, 4);
  for (; x < px; ++x, src += 3, dst += 4) {
    for (int c = 0; c < 3; ++c) run[c] = kDelta ? uint8_t(run[c] + src[c]) : src[c];
    storeRgba(dst, run[0], run[1], run[2], 255);
  }
}
bool haveSsse3() {
  static const bool have = __builtin_cpu_supports("ssse3");
  return have;
}
#endif

// Bytes the source of tileToRgba8 must have readable past its end.
constexpr size_t kSourcePadding = 16;

template <bool kDelta>
void tileToRgba8(const uint8_t* src, uint8_t* dst, uint32_t tile_px, PixelFormat format) {
  const size_t in_row = size_t(tile_px) * bytesPerPixel(format), out_row = size_t(tile_px) * 4;
#if defined(CLIPSTREAM_HAVE_SSSE3_PATH)
  if (format == PixelFormat::kRGB8 && haveSsse3()) {
    for (uint32_t y = 0; y < tile_px; ++y, src += in_row, dst += out_row)
      rowRgb8Ssse3<kDelta>(src, dst, tile_px);
    return;
  }
#endif
  for (uint32_t y = 0; y < tile_px; ++y, src += in_row, dst += out_row) {
    switch (format) {
      case PixelFormat::kR8: rowR8<kDelta>(src, dst, tile_px); break;
      case PixelFormat::kR16: rowR16<kDelta>(src, dst, tile_px); break;
      case PixelFormat::kRGB8: rowRgb<kDelta, 3>(src, dst, tile_px); break;
      case PixelFormat::kRGBA8: rowRgb<kDelta, 4>(src, dst, tile_px); break;
      case PixelFormat::kI16:
      case PixelFormat::kF32: break;  // heights: refused by decodeTileRgba8
    }
  }
}

#if defined(__SSE2__)
// In-place prefix sums per row, the predictor inverse of decodeTile().
// Never touches a byte outside `pixels`.
template <int kBytes>
void undoRowsSse2(uint8_t* pixels, uint32_t tile_px) {
  const size_t row_bytes = size_t(tile_px) * kBytes;
  for (uint32_t y = 0; y < tile_px; ++y) {
    uint8_t* row = pixels + y * row_bytes;
    __m128i carry = _mm_setzero_si128();
    size_t i = 0;
    for (; i + 16 <= row_bytes; i += 16) {
      __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(row + i));
      if constexpr (kBytes == 1) {
        v = _mm_add_epi8(v, _mm_slli_si128(v, 1));
        v = _mm_add_epi8(v, _mm_slli_si128(v, 2));
        v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
        v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
        v = _mm_add_epi8(v, carry);
        carry = _mm_shuffle_epi32(_mm_shufflehi_epi16(_mm_unpackhi_epi8(v, v), 0xFF), 0xFF);
      } else if constexpr (kBytes == 2) {
        v = _mm_add_epi16(v, _mm_slli_si128(v, 2));
        v = _mm_add_epi16(v, _mm_slli_si128(v, 4));
        v = _mm_add_epi16(v, _mm_slli_si128(v, 8));
        v = _mm_add_epi16(v, carry);
        carry = _mm_shuffle_epi32(_mm_shufflehi_epi16(v, 0xFF), 0xFF);
      } else {
        v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
        v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
        v = _mm_add_epi8(v, carry);
        carry = _mm_shuffle_epi32(v, 0xFF);
      }
      _mm_storeu_si128(reinterpret_cast<__m128i*>(row + i), v);
    }
    // Scalar tail from the last summed sample.
    if constexpr (kBytes == 2) {
      uint16_t run = uint16_t(_mm_cvtsi128_si32(carry));
      for (; i < row_bytes; i += 2) {
        run = uint16_t(run + (row[i] | (row[i + 1] << 8)));
        row[i] = uint8_t(run & 0xff);
        row[i + 1] = uint8_t(run >> 8);
      }
    } else {
      uint8_t run[4];
      const uint32_t last = uint32_t(_mm_cvtsi128_si32(carry));
      std::memcpy(run, &last, 4);
      for (; i < row_bytes; ++i) row[i] = run[i % kBytes] = uint8_t(run[i % kBytes] + row[i]);
    }
  }
}

#if defined(CLIPSTREAM_HAVE_SSSE3_PATH)
// RGB8 in place: four pixels spread to RGBA lanes, summed, packed back.
// The 16-byte load covers 4 bytes of the next pixel; blocks stop 4 bytes
// before the row's end so nothing outside `pixels` is read.
__attribute__((target("ssse3"))) void undoRowsRgb8Ssse3(uint8_t* pixels, uint32_t tile_px) {
  const __m128i spread = _mm_setr_epi8(0, 1, 2, -1, 3, 4, 5, -1, 6, 7, 8, -1, 9, 10, 11, -1);
  const __m128i pack = _mm_setr_epi8(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1);
  const size_t row_bytes = size_t(tile_px) * 3;
  for (uint32_t y = 0; y < tile_px; ++y) {
    uint8_t* row = pixels + y * row_bytes;
    __m128i carry = _mm_setzero_si128();
    size_t i = 0;
    for (; i + 16 <= row_bytes; i += 12) {
      const __m128i in = _mm_loadu_si128(reinterpret_cast<const __m128i*>(row + i));
      __m128i v = _mm_shuffle_epi8(in, spread);
      v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
      v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
      v = _mm_add_epi8(v, carry);
      carry = _mm_shuffle_epi32(v, 0xFF);
      // 12 bytes back (8 + 4): a 16-byte store would overlap the next
      // load and defeat store-to-load forwarding.
      const __m128i out = _mm_shuffle_epi8(v, pack);
      _mm_storel_epi64(reinterpret_cast<__m128i*>(row + i), out);
      const uint32_t tail = uint32_t(_mm_cvtsi128_si32(_mm_srli_si128(out, 8)));
      std::memcpy(row + i + 8, &tail, 4);
    }
    uint8_t run[4];
    const uint32_t last = uint32_t(_mm_cvtsi128_si32(carry));
    std::memcpy(run, &last, 4);
    for (size_t c = 0; i < row_bytes; ++i, c = (c + 1) % 3) row[i] = run[c] = uint8_t(run[c] + row[i]);
  }
}
#endif

bool undoLeftDeltaFast(uint8_t* pixels, uint32_t tile_px, PixelFormat format) {
  switch (format) {
    case PixelFormat::kR8: undoRowsSse2<1>(pixels, tile_px); return true;
    case PixelFormat::kR16:
    case PixelFormat::kI16: undoRowsSse2<2>(pixels, tile_px); return true;
    case PixelFormat::kF32: return false;
    case PixelFormat::kRGBA8: undoRowsSse2<4>(pixels, tile_px); return true;
    case PixelFormat::kRGB8:
#if defined(CLIPSTREAM_HAVE_SSSE3_PATH)
      if (haveSsse3()) {
        undoRowsRgb8Ssse3(pixels, tile_px);
        return true;
      }
#endif
      return false;
  }
  return false;
}
#else
bool undoLeftDeltaFast(uint8_t*, uint32_t, PixelFormat) { return false; }
#endif

}  // namespace

Status decodeTileRgba8(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                       const RawTile& raw, std::span<uint8_t> rgba) {
  const size_t pixel_count = size_t(geometry.tile_px) * geometry.tile_px;
  if (!isValidPixelFormat(uint32_t(geometry.format)) || !isColourFormat(geometry.format)) {
    return Status::error(ErrorCode::kUnsupported,
                         std::string("decode: pixel format ") + pixelFormatName(geometry.format) +
                             " is not a colour format");
  }
  if (rgba.size() != pixel_count * 4) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "decode: RGBA8 output holds " + std::to_string(rgba.size()) +
                             " bytes, expected " + std::to_string(pixel_count * 4));
  }
  if (encoding.predictor != Predictor::kNone && encoding.predictor != Predictor::kLeftDelta) {
    return Status::error(ErrorCode::kInvalidArgument, "unknown predictor");
  }
  const bool delta = encoding.predictor == Predictor::kLeftDelta;
  if (raw.location.constant) {
    // One pixel, expanded once, repeated; no predictor on constant tiles.
    uint8_t one[4];
    uint8_t padded[8 + kSourcePadding] = {};
    std::memcpy(padded, raw.location.constant_pixel, sizeof(raw.location.constant_pixel));
    tileToRgba8<false>(padded, one, 1, geometry.format);
    for (size_t i = 0; i < pixel_count; ++i) std::memcpy(rgba.data() + 4 * i, one, 4);
    return okStatus();
  }
  // Decompression and every payload check is decodeTile's, with the
  // predictor left in; the inverse then runs fused with the expansion.
  StoreEncoding stored = encoding;
  stored.predictor = Predictor::kNone;
  if (geometry.format == PixelFormat::kRGBA8) {
    Status status = decodeTile(geometry, stored, raw, rgba);
    if (!status) return status;
    if (delta) tileToRgba8<true>(rgba.data(), rgba.data(), geometry.tile_px, geometry.format);
    return okStatus();
  }
  thread_local std::vector<uint8_t> scratch;
  scratch.resize(geometry.tileBytes() + kSourcePadding);
  Status status =
      decodeTile(geometry, stored, raw, std::span<uint8_t>(scratch.data(), geometry.tileBytes()));
  if (!status) return status;
  if (delta) {
    tileToRgba8<true>(scratch.data(), rgba.data(), geometry.tile_px, geometry.format);
  } else {
    tileToRgba8<false>(scratch.data(), rgba.data(), geometry.tile_px, geometry.format);
  }
  return okStatus();
}

}  // namespace clipstream
