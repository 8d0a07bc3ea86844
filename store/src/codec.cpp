// Tile payload codec: constant detection, left-delta predictor and zstd.
// encodeTile() and TileStoreReader::decode() are the only producers and
// consumers of payload bytes.
#include "format.h"

#include <clipstream/store/tile_store.h>

#include <xxhash.h>
#include <zstd.h>

#include <algorithm>
#include <memory>

namespace clipstream {
namespace format {

uint64_t checksum64(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

size_t maxStoredBytes(size_t tile_bytes, Compression compression) {
  return compression == Compression::kZstd ? ZSTD_compressBound(tile_bytes) : tile_bytes;
}

std::string keyText(const TileKey& key) {
  return "level " + std::to_string(key.level) + " tile (" + std::to_string(key.x) + ", " +
         std::to_string(key.y) + ")";
}

}  // namespace format

namespace {

// Per row, per channel: out[x] = in[x] - in[x - 1] modulo the sample width.
// The first pixel of each row is kept as is. 16-bit samples are treated as
// little-endian u16.
void applyLeftDelta(const uint8_t* in, uint8_t* out, uint32_t tile_px, PixelFormat format) {
  const size_t row_bytes = size_t(tile_px) * bytesPerPixel(format);
  if (format == PixelFormat::kR16) {
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

// Inverse of applyLeftDelta, in place.
void undoLeftDelta(uint8_t* pixels, uint32_t tile_px, PixelFormat format) {
  const size_t row_bytes = size_t(tile_px) * bytesPerPixel(format);
  if (format == PixelFormat::kR16) {
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
  // Each byte depends on the one a pixel earlier; measured faster than
  // keeping per-channel sums in locals (which GCC 12 spills).
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
    return Status::ok();
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
  return Status::ok();
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
    return Status::ok();
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
  return Status::ok();
}

}  // namespace clipstream
