// Test/benchmark wrapper that slows a source down and fails chosen tiles.
// The failing set is a pure function of (key, seed) so a test knows it.
#include <clipstream/streamer/tile_source.h>
#include <clipstream/streamer/testing/faulty_source.h>

#include <chrono>
#include <thread>

namespace clipstream {
namespace {

class FaultySource final : public TileSource {
 public:
  FaultySource(std::shared_ptr<TileSource> inner, const FaultSpec& spec)
      : m_inner(std::move(inner)), m_spec(spec) {}

  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return m_inner->content(); }
  ElevationInfo elevationInfo() const override { return m_inner->elevationInfo(); }
  // Bounds come from the index, which the injected faults leave alone.
  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    return m_inner->tileHeightBounds(key, out);
  }

  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    FetchInfo info;
    return fetchWithInfo(key, rgba, &info);
  }

  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    *info = {};
    if (m_spec.latency_ms > 0.0)
      std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(m_spec.latency_ms));
    if (failsTile(m_spec, key))
      return Status::error(m_spec.fail_code, "injected failure: level " + std::to_string(key.level) +
                                                 " tile (" + std::to_string(key.x) + ", " +
                                                 std::to_string(key.y) + ")");
    return m_inner->fetchWithInfo(key, rgba, info);
  }

  std::string describe() const override { return "faulty:" + m_inner->describe(); }
  unsigned suggestedLoaderThreads() const override { return m_inner->suggestedLoaderThreads(); }
  RemoteStats remoteStats() const override { return m_inner->remoteStats(); }

 private:
  std::shared_ptr<TileSource> m_inner;
  FaultSpec m_spec;
};

}  // namespace

bool failsTile(const FaultSpec& spec, const TileKey& key) {
  if (spec.fail_fraction <= 0.0) return false;
  if (spec.fail_fraction >= 1.0) return true;
  uint64_t h = TileKeyHash{}(key) ^ (uint64_t(spec.seed) * 0x9E3779B97F4A7C15ull);
  h = (h ^ (h >> 33)) * 0xFF51AFD7ED558CCDull;
  h ^= h >> 33;
  return double(h >> 11) * (1.0 / 9007199254740992.0) < spec.fail_fraction;
}

std::shared_ptr<TileSource> makeFaultySource(std::shared_ptr<TileSource> inner,
                                             const FaultSpec& spec) {
  if (!inner) return nullptr;
  return std::make_shared<FaultySource>(std::move(inner), spec);
}

}  // namespace clipstream
