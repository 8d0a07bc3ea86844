// BC1 tiles from an RGBA8 source, transcoded inside fetch() (loader
// threads), and the tile content names. See tile_source.h and bc1.h.
#include <clipstream/streamer/bc1.h>
#include <clipstream/streamer/tile_source.h>

#include <chrono>

namespace clipstream {

uint64_t tileContentBytes(TileContent content, uint32_t tile_px) {
  if (content == TileContent::kBc1) return bc1TileBytes(tile_px);
  return uint64_t(tile_px) * tile_px * 4;
}

const char* tileContentName(TileContent content) {
  switch (content) {
    case TileContent::kRgba8: return "rgba8";
    case TileContent::kHeightF32: return "f32";
    case TileContent::kBc1: return "bc1";
  }
  return "?";
}

namespace {

class Bc1Source final : public TileSource {
 public:
  explicit Bc1Source(std::shared_ptr<TileSource> inner) : m_inner(std::move(inner)) {}

  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return TileContent::kBc1; }

  Status fetch(const TileKey& key, std::vector<uint8_t>* blocks) override {
    FetchInfo info;
    return fetchWithInfo(key, blocks, &info);
  }

  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* blocks, FetchInfo* info) override {
    std::vector<uint8_t> rgba;
    if (Status s = m_inner->fetchWithInfo(key, &rgba, info); !s) return s;
    const auto start = std::chrono::steady_clock::now();
    Status s = encodeBc1Tile(rgba, m_inner->geometry().tile_px, blocks);
    info->decode_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return s;
  }

  void fetchBatch(std::span<const TileKey> keys, std::span<std::vector<uint8_t>* const> blocks,
                  std::span<Status> statuses, std::span<FetchInfo> infos) override {
    // The inner source batches its reads (one HTTP range for a row); each
    // tile is then encoded where it landed.
    std::vector<std::vector<uint8_t>> rgba(keys.size());
    std::vector<std::vector<uint8_t>*> outs(keys.size());
    for (size_t i = 0; i < keys.size(); ++i) outs[i] = &rgba[i];
    m_inner->fetchBatch(keys, outs, statuses, infos);
    for (size_t i = 0; i < keys.size(); ++i) {
      if (!statuses[i]) continue;
      const auto start = std::chrono::steady_clock::now();
      statuses[i] = encodeBc1Tile(rgba[i], m_inner->geometry().tile_px, blocks[i]);
      infos[i].decode_ms +=
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    }
  }

  std::string describe() const override { return "bc1:" + m_inner->describe(); }
  size_t maxBatch() const override { return m_inner->maxBatch(); }
  unsigned suggestedLoaderThreads() const override { return m_inner->suggestedLoaderThreads(); }
  RemoteStats remoteStats() const override { return m_inner->remoteStats(); }

 private:
  std::shared_ptr<TileSource> m_inner;
};

}  // namespace

std::shared_ptr<TileSource> makeBc1Source(std::shared_ptr<TileSource> rgba8, Status* status) {
  *status = okStatus();
  if (!rgba8) {
    *status = Status::error(ErrorCode::kInvalidArgument, "BC1 tiles: no source");
    return nullptr;
  }
  if (rgba8->content() != TileContent::kRgba8) {
    *status = Status::error(ErrorCode::kInvalidArgument,
                            "BC1 tiles: " + rgba8->describe() + " does not hand out RGBA8 colour tiles");
    return nullptr;
  }
  const uint32_t tile_px = rgba8->geometry().tile_px;
  if (tile_px == 0 || tile_px % kBc1BlockPx != 0) {
    *status = Status::error(ErrorCode::kInvalidArgument,
                            "BC1 tiles: " + rgba8->describe() + " has " + std::to_string(tile_px) +
                                "-px tiles; BC1 needs a multiple of 4");
    return nullptr;
  }
  return std::make_shared<Bc1Source>(std::move(rgba8));
}

}  // namespace clipstream
