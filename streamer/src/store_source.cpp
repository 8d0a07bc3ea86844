// TileSources over tile store files: positional reads through
// TileStoreReader (no lock around I/O), then decodeTileRgba8 (decode,
// predictor inverse and conversion to RGBA8 in one pass) for colour
// stores, decodeTileHeights (heights as float32) for elevation stores.
#include <clipstream/store/cog.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/tile_source.h>

#include "convert.h"

#include <bit>
#include <chrono>
#include <cstring>

namespace clipstream {
namespace {

class StoreSource final : public TileSource {
 public:
  StoreSource(std::unique_ptr<TileStoreReader> reader, std::string path)
      : m_reader(std::move(reader)), m_path(std::move(path)) {}

  const PyramidGeometry& geometry() const override { return m_reader->geometry(); }

  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    FetchInfo info;
    return fetchWithInfo(key, rgba, &info);
  }

  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    *info = {};
    const PyramidGeometry& geo = m_reader->geometry();
    // Scratch buffers are per thread so concurrent fetches share nothing.
    thread_local RawTile raw;
    Status status = m_reader->readRaw(key, &raw);
    if (!status) return status;
    info->bytes_read = raw.payload.size();
    const auto start = std::chrono::steady_clock::now();
    const size_t tile_px2 = size_t(geo.tile_px) * geo.tile_px;
    rgba->resize(tile_px2 * 4);
    // Predictor inverse fused with the RGBA8 expansion (one pass after zstd).
    status = decodeTileRgba8(geo, m_reader->info().encoding, raw, std::span<uint8_t>(*rgba));
    info->decode_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return status;
  }

  size_t maxBatch() const override { return m_reader->suggestedBatchTiles(); }
  BatchShape batchShape() const override { return m_reader->suggestedBatchShape(); }

  void fetchBatch(std::span<const TileKey> keys, std::span<std::vector<uint8_t>* const> rgba,
                  std::span<Status> statuses, std::span<FetchInfo> infos) override {
    const PyramidGeometry& geo = m_reader->geometry();
    thread_local std::vector<RawTile> raws;
    raws.resize(keys.size());
    // Neighbours in the file come in one read (one range request remotely).
    m_reader->readRawBatch(keys, raws, statuses);
    for (size_t i = 0; i < keys.size(); ++i) {
      infos[i] = {};
      if (!statuses[i]) continue;
      infos[i].bytes_read = raws[i].payload.size();
      const auto start = std::chrono::steady_clock::now();
      rgba[i]->resize(size_t(geo.tile_px) * geo.tile_px * 4);
      statuses[i] = decodeTileRgba8(geo, m_reader->info().encoding, raws[i],
                                    std::span<uint8_t>(*rgba[i]));
      infos[i].decode_ms = std::chrono::duration<double, std::milli>(
                               std::chrono::steady_clock::now() - start)
                               .count();
    }
  }

  std::string describe() const override { return "store:" + m_path; }
  unsigned suggestedLoaderThreads() const override { return m_reader->suggestedReadThreads(); }
  RemoteStats remoteStats() const override { return m_reader->remoteStats(); }

 private:
  std::unique_ptr<TileStoreReader> m_reader;
  std::string m_path;
};

// An elevation store's tiles as float32 heights (offset + scale * sample,
// or the F32 sample), 4 bytes a texel like RGBA8.
class ElevationStoreSource final : public TileSource {
 public:
  ElevationStoreSource(std::unique_ptr<TileStoreReader> reader, std::string path)
      : m_reader(std::move(reader)), m_path(std::move(path)) {}

  const PyramidGeometry& geometry() const override { return m_reader->geometry(); }
  TileContent content() const override { return TileContent::kHeightF32; }
  ElevationInfo elevationInfo() const override { return m_reader->info().elevation; }

  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    *out = {};
    TileLocation location;
    if (Status s = m_reader->locate(key, &location); !s) return s;
    *out = {location.min_height, location.max_height, location.error};
    return okStatus();
  }

  Status fetch(const TileKey& key, std::vector<uint8_t>* heights) override {
    FetchInfo info;
    return fetchWithInfo(key, heights, &info);
  }

  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* heights, FetchInfo* info) override {
    *info = {};
    const StoreInfo& store = m_reader->info();
    const PyramidGeometry& geo = store.geometry;
    thread_local RawTile raw;
    Status status = m_reader->readRaw(key, &raw);
    if (!status) return status;
    info->bytes_read = raw.payload.size();
    const auto start = std::chrono::steady_clock::now();
    const size_t count = size_t(geo.tile_px) * geo.tile_px;
    // Decoded as floats, then copied: the cache holds bytes, and a float
    // view of a byte vector's storage would not be a float object.
    thread_local std::vector<float> samples;
    samples.resize(count);
    status = decodeTileHeights(geo, store.encoding, store.elevation, raw, samples);
    if (status) {
      heights->resize(count * sizeof(float));
      std::memcpy(heights->data(), samples.data(), count * sizeof(float));
    }
    info->decode_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return status;
  }

  std::string describe() const override { return "elevation:" + m_path; }
  unsigned suggestedLoaderThreads() const override { return m_reader->suggestedReadThreads(); }
  RemoteStats remoteStats() const override { return m_reader->remoteStats(); }

 private:
  std::unique_ptr<TileStoreReader> m_reader;
  std::string m_path;
};

// A Cloud-Optimized GeoTIFF read directly (CogReader): its tiles in the
// COG's pixel format, converted to RGBA8 like a store's.
class CogSource final : public TileSource {
 public:
  CogSource(std::unique_ptr<CogReader> reader, std::string path)
      : m_reader(std::move(reader)), m_path(std::move(path)) {}

  const PyramidGeometry& geometry() const override { return m_reader->geometry(); }

  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    FetchInfo info;
    return fetchWithInfo(key, rgba, &info);
  }

  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    *info = {};
    const PyramidGeometry& geo = m_reader->geometry();
    thread_local std::vector<uint8_t> pixels;
    pixels.resize(geo.tileBytes());
    const auto start = std::chrono::steady_clock::now();
    // Reading and decoding happen together here (an internal tile is
    // decoded whole), so decode_ms includes the read.
    Status status = m_reader->readTile(key, pixels, &info->bytes_read);
    if (!status) return status;
    const size_t count = size_t(geo.tile_px) * geo.tile_px;
    rgba->resize(count * 4);
    status = convertToRgba8(geo.format, pixels, rgba->data(), count);
    info->decode_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return status;
  }

  std::string describe() const override { return "cog:" + m_path; }
  unsigned suggestedLoaderThreads() const override { return m_reader->suggestedReadThreads(); }
  RemoteStats remoteStats() const override { return m_reader->remoteStats(); }

 private:
  std::unique_ptr<CogReader> m_reader;
  std::string m_path;
};

}  // namespace

Status convertToRgba8(PixelFormat format, std::span<const uint8_t> src, uint8_t* dst,
                      size_t pixel_count) {
  if (!isValidPixelFormat(uint32_t(format)))
    return Status::error(ErrorCode::kUnsupported, "cannot convert unknown pixel format to RGBA8");
  if (src.size() < pixel_count * bytesPerPixel(format))
    return Status::error(ErrorCode::kInvalidArgument, "pixel buffer smaller than the tile");
  const uint8_t* s = src.data();
  switch (format) {
    case PixelFormat::kR8:
      for (size_t i = 0; i < pixel_count; ++i, dst += 4) {
        dst[0] = dst[1] = dst[2] = s[i];
        dst[3] = 255;
      }
      break;
    case PixelFormat::kR16:
      // Little-endian samples; the high byte is the second one.
      for (size_t i = 0; i < pixel_count; ++i, dst += 4) {
        dst[0] = dst[1] = dst[2] = s[2 * i + 1];
        dst[3] = 255;
      }
      break;
    case PixelFormat::kRGB8: {
      size_t i = 0;
      if constexpr (std::endian::native == std::endian::little) {
        // Four pixels from three 32-bit loads: r0g0b0r1 g1b1r2g2 b2r3g3b3.
        for (; i + 4 <= pixel_count; i += 4, s += 12, dst += 16) {
          uint32_t a, b, c;
          std::memcpy(&a, s, 4);
          std::memcpy(&b, s + 4, 4);
          std::memcpy(&c, s + 8, 4);
          const uint32_t out[4] = {a | 0xFF000000u, (a >> 24) | (b << 8) | 0xFF000000u,
                                   (b >> 16) | (c << 16) | 0xFF000000u, (c >> 8) | 0xFF000000u};
          std::memcpy(dst, out, 16);
        }
      }
      for (; i < pixel_count; ++i, dst += 4, s += 3) {
        dst[0] = s[0];
        dst[1] = s[1];
        dst[2] = s[2];
        dst[3] = 255;
      }
      break;
    }
    case PixelFormat::kRGBA8:
      std::copy(s, s + pixel_count * 4, dst);
      break;
    case PixelFormat::kI16:
    case PixelFormat::kF32:
      return Status::error(ErrorCode::kUnsupported,
                           std::string("pixel format ") + pixelFormatName(format) +
                               " holds heights, not colour");
  }
  return okStatus();
}

std::shared_ptr<TileSource> openStoreSource(const std::string& path, Status* status) {
  return openStoreSource(path, RemoteOptions{}, status);
}

std::shared_ptr<TileSource> openStoreSource(const std::string& path, const RemoteOptions& remote,
                                            Status* status) {
  std::unique_ptr<TileStoreReader> reader;
  *status = TileStoreReader::open(path, remote, &reader);
  if (!*status && status->code == ErrorCode::kBadMagic) {
    // Not a store: a Cloud-Optimized GeoTIFF is read directly.
    std::unique_ptr<CogReader> cog;
    const Status opened = CogReader::open(path, remote, &cog);
    if (opened.code == ErrorCode::kBadMagic) {
      *status = Status::error(ErrorCode::kBadMagic, displayStorePath(path) +
                                                        ": not a clipstream tile store nor a TIFF (bad magic)");
      return nullptr;
    }
    *status = opened;
    if (!opened) return nullptr;
    return std::make_shared<CogSource>(std::move(cog), displayStorePath(path));
  }
  if (!*status) return nullptr;
  if (reader->info().elevation.present) {
    *status = Status::error(ErrorCode::kUnsupported,
                            displayStorePath(path) +
                                " is an elevation store (heights), not a colour image: give it "
                                "as the scene's elevation layer (--elevation)");
    return nullptr;
  }
  return std::make_shared<StoreSource>(std::move(reader), displayStorePath(path));
}

std::shared_ptr<TileSource> openElevationSource(const std::string& path, Status* status) {
  return openElevationSource(path, RemoteOptions{}, status);
}

std::shared_ptr<TileSource> openElevationSource(const std::string& path,
                                                const RemoteOptions& remote, Status* status) {
  std::unique_ptr<TileStoreReader> reader;
  *status = TileStoreReader::open(path, remote, &reader);
  if (!*status) return nullptr;
  if (!reader->info().elevation.present || !isHeightFormat(reader->geometry().format)) {
    *status = Status::error(ErrorCode::kUnsupported,
                            displayStorePath(path) + " is a colour store (" +
                                pixelFormatName(reader->geometry().format) +
                                "), not an elevation store: tile a DEM (clipstream-tile DEM.tif "
                                "dem.cstore) for the scene's elevation layer");
    return nullptr;
  }
  return std::make_shared<ElevationStoreSource>(std::move(reader), displayStorePath(path));
}

}  // namespace clipstream
