// An in-memory TileSource over an RGBA8 image. See tile_source.h.
#include <clipstream/streamer/tile_source.h>

#include <algorithm>

namespace clipstream {
namespace {

class ImageSource final : public TileSource {
 public:
  ImageSource(std::vector<uint8_t> rgba, uint32_t w, uint32_t h, uint32_t tile_px) {
    makePyramidGeometry(w, h, tile_px, PixelFormat::kRGBA8, &m_geometry);
    m_levels.push_back(std::move(rgba));
    for (uint32_t l = 1; l < m_geometry.levelCount(); ++l) {
      const LevelInfo& fine = m_geometry.levels[l - 1];
      const LevelInfo& info = m_geometry.levels[l];
      const std::vector<uint8_t>& src = m_levels.back();
      std::vector<uint8_t> dst(size_t(info.width_px) * info.height_px * 4);
      for (uint64_t y = 0; y < info.height_px; ++y) {
        for (uint64_t x = 0; x < info.width_px; ++x) {
          for (int c = 0; c < 4; ++c) {
            unsigned sum = 0;
            for (int j = 0; j < 2; ++j)
              for (int i = 0; i < 2; ++i) {
                const uint64_t sx = std::min<uint64_t>(2 * x + i, fine.width_px - 1);
                const uint64_t sy = std::min<uint64_t>(2 * y + j, fine.height_px - 1);
                sum += src[(sy * fine.width_px + sx) * 4 + c];
              }
            dst[(y * info.width_px + x) * 4 + c] = uint8_t((sum + 2) / 4);
          }
        }
      }
      m_levels.push_back(std::move(dst));
    }
  }
  const PyramidGeometry& geometry() const override { return m_geometry; }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    if (!m_geometry.contains(key))
      return Status::error(ErrorCode::kOutOfRange, "image source: tile outside the pyramid");
    const uint32_t tp = m_geometry.tile_px;
    const LevelInfo& info = m_geometry.levels[key.level];
    rgba->assign(size_t(tp) * tp * 4, 0);
    for (uint32_t y = 0; y < tp; ++y) {
      const uint64_t sy = uint64_t(key.y) * tp + y;
      if (sy >= info.height_px) break;
      for (uint32_t x = 0; x < tp; ++x) {
        const uint64_t sx = uint64_t(key.x) * tp + x;
        if (sx >= info.width_px) break;
        std::copy_n(m_levels[key.level].data() + (sy * info.width_px + sx) * 4, 4,
                    rgba->data() + (size_t(y) * tp + x) * 4);
      }
    }
    return okStatus();
  }
  std::string describe() const override {
    return "image:" + std::to_string(m_geometry.width_px) + "x" +
           std::to_string(m_geometry.height_px);
  }

 private:
  PyramidGeometry m_geometry;
  std::vector<std::vector<uint8_t>> m_levels;
};

}  // namespace

std::shared_ptr<TileSource> makeImageSource(std::vector<uint8_t> rgba, uint32_t width_px,
                                            uint32_t height_px, uint32_t tile_px) {
  return std::make_shared<ImageSource>(std::move(rgba), width_px, height_px, tile_px);
}

}  // namespace clipstream
