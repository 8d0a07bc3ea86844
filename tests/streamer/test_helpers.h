// Shared helpers for the streamer tests: a recording source wrapper and a
// small synthetic tile store written with the store writer.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

namespace clipstream::test {

inline constexpr double kPi = 3.14159265358979323846;

// A camera straight above (x, z), looking down.
inline Camera lookingDown(double x, double z, double height) {
  Camera c;
  c.position = {x, height, z};
  c.pitch_rad = -kPi / 2;
  return c;
}

// A procedural square texture of `side` texels.
inline std::shared_ptr<TileSource> procedural(uint64_t side, uint32_t tile_px = 128) {
  ProceduralSpec spec;
  spec.width_px = spec.height_px = side;
  spec.tile_px = tile_px;
  return makeProceduralSource(spec);
}

// Polls until nothing is queued or in flight. Sleeps in short steps; the
// timeout only turns a hang into a failure.
inline bool waitIdle(const Streamer& s, double timeout_s = 30.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    const StreamerStats st = s.stats();
    if (st.queue_depth == 0 && st.in_flight == 0) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return false;
}

// Records every fetch (key, thread) in call order; optional extra latency.
class RecordingSource final : public TileSource {
 public:
  explicit RecordingSource(std::shared_ptr<TileSource> inner, double latency_ms = 0.0)
      : m_inner(std::move(inner)), m_latency_ms(latency_ms) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    FetchInfo info;
    return fetchWithInfo(key, rgba, &info);
  }
  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      m_keys.push_back(key);
      m_threads.push_back(std::this_thread::get_id());
    }
    if (m_latency_ms > 0.0)
      std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(m_latency_ms));
    return m_inner->fetchWithInfo(key, rgba, info);
  }
  std::string describe() const override { return "recording:" + m_inner->describe(); }

  std::vector<TileKey> keys() const {
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_keys;
  }
  std::vector<std::thread::id> threads() const {
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_threads;
  }

 private:
  std::shared_ptr<TileSource> m_inner;
  double m_latency_ms;
  mutable std::mutex m_mutex;
  std::vector<TileKey> m_keys;
  std::vector<std::thread::id> m_threads;
};

// Pixel (px, py) of a tile, in the store's format: encodes level and
// position so any converted texel can be checked.
inline void syntheticPixel(PixelFormat format, const TileKey& key, uint32_t px, uint32_t py,
                           uint8_t* out) {
  const uint32_t v = key.level * 31 + key.x * 7 + key.y * 13 + px * 3 + py * 5;
  switch (format) {
    case PixelFormat::kR8: out[0] = uint8_t(v); break;
    case PixelFormat::kR16: out[0] = uint8_t(v * 11); out[1] = uint8_t(v); break;
    case PixelFormat::kRGB8: out[0] = uint8_t(v); out[1] = uint8_t(v + 85); out[2] = uint8_t(v + 170); break;
    case PixelFormat::kRGBA8:
      out[0] = uint8_t(v); out[1] = uint8_t(v + 85); out[2] = uint8_t(v + 170); out[3] = uint8_t(v ^ 0x5A);
      break;
  }
}

// Expected RGBA8 after the store source's conversion of syntheticPixel().
inline void expectedRgba(PixelFormat format, const TileKey& key, uint32_t px, uint32_t py,
                         uint8_t rgba[4]) {
  uint8_t raw[4] = {0, 0, 0, 0};
  syntheticPixel(format, key, px, py, raw);
  switch (format) {
    case PixelFormat::kR8: rgba[0] = rgba[1] = rgba[2] = raw[0]; rgba[3] = 255; break;
    case PixelFormat::kR16: rgba[0] = rgba[1] = rgba[2] = raw[1]; rgba[3] = 255; break;
    case PixelFormat::kRGB8: rgba[0] = raw[0]; rgba[1] = raw[1]; rgba[2] = raw[2]; rgba[3] = 255; break;
    case PixelFormat::kRGBA8: for (int c = 0; c < 4; ++c) rgba[c] = raw[c]; break;
  }
}

// A fresh path in the temp directory, removed by the destructor.
struct TempFile {
  std::string path;
  explicit TempFile(const std::string& name) {
    static std::atomic<int> counter{0};
    path = (std::filesystem::temp_directory_path() /
            ("clipstream_streamer_" + std::to_string(::getpid()) + "_" +
             std::to_string(counter++) + "_" + name))
               .string();
  }
  ~TempFile() {
    std::error_code ec;
    std::filesystem::remove(path, ec);
  }
};

// Writes a store of the given size whose tiles hold syntheticPixel().
inline Status writeSyntheticStore(const std::string& path, uint64_t width_px, uint64_t height_px,
                                  uint32_t tile_px, PixelFormat format) {
  PyramidGeometry geometry;
  if (!makePyramidGeometry(width_px, height_px, tile_px, format, &geometry))
    return Status::error(ErrorCode::kInvalidArgument, "bad geometry");
  WriterOptions options;
  options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  Status status = TileStoreWriter::create(path, geometry, options, &writer);
  if (!status) return status;
  std::vector<uint8_t> pixels(geometry.tileBytes());
  const uint32_t bpp = bytesPerPixel(format);
  for (uint32_t level = 0; level < geometry.levelCount(); ++level) {
    for (uint32_t ty = 0; ty < geometry.levels[level].tiles_y; ++ty) {
      for (uint32_t tx = 0; tx < geometry.levels[level].tiles_x; ++tx) {
        const TileKey key{level, tx, ty};
        for (uint32_t py = 0; py < tile_px; ++py)
          for (uint32_t px = 0; px < tile_px; ++px)
            syntheticPixel(format, key, px, py, &pixels[(size_t(py) * tile_px + px) * bpp]);
        EncodedTile encoded;
        status = encodeTile(geometry, options.encoding, key, pixels, &encoded);
        if (!status) return status;
        status = writer->write(std::move(encoded));
        if (!status) return status;
      }
    }
  }
  return writer->finish();
}

}  // namespace clipstream::test
