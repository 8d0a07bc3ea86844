#include "pyramid_builder.h"

#include <algorithm>
#include <cstring>

namespace clipstream {

uint64_t PyramidBuilder::capacityRows(uint32_t tile_px, const Downsampler& d) {
  // One full tile row plus the filter's reach above and below, so a level
  // never holds more than about one tile row of its width.
  return uint64_t(tile_px) + uint64_t(d.tapCount()) + 4;
}

uint64_t PyramidBuilder::bufferBytes(const PyramidGeometry& geometry, const Downsampler& d,
                                     uint64_t width_px_first, uint32_t levels) {
  uint64_t total = 0;
  uint64_t w = width_px_first;
  for (uint32_t i = 0; i < levels; ++i) {
    total += capacityRows(geometry.tile_px, d) * w * bytesPerPixel(geometry.format);
    w = (w + 1) / 2;
  }
  return total;
}

PyramidBuilder::PyramidBuilder(const PyramidGeometry& geometry, const Downsampler& downsampler,
                               const RegionSpec& region, TileSink tile_sink, RowSink row_sink,
                               BufferSource tile_buffers)
    : m_geometry(geometry),
      m_downsampler(downsampler),
      m_region(region),
      m_tile_sink(std::move(tile_sink)),
      m_row_sink(std::move(row_sink)),
      m_tile_buffers(std::move(tile_buffers)) {
  const uint32_t bpp = bytesPerPixel(geometry.format);
  for (uint32_t lv = region.first_level; lv <= region.last_level; ++lv) {
    const uint32_t shift = lv - region.first_level;
    const LevelInfo& info = geometry.levels[lv];
    Level l;
    l.level = lv;
    l.x0_px = region.x0_px >> shift;
    l.y0_px = region.y0_px >> shift;
    // Region origins are multiples of tile_px << (last - first), so the
    // region's extent at each level is the global extent minus its origin,
    // capped by the (halved) region size of the level above.
    l.width_px = info.width_px - l.x0_px;
    l.height_px = info.height_px - l.y0_px;
    if (m_levels.empty()) {
      if (region.width_px != 0) l.width_px = std::min(l.width_px, region.width_px);
      if (region.height_px != 0) l.height_px = std::min(l.height_px, region.height_px);
    } else {
      l.width_px = std::min(l.width_px, (m_levels.back().width_px + 1) / 2);
      l.height_px = std::min(l.height_px, (m_levels.back().height_px + 1) / 2);
    }
    l.row_bytes = size_t(l.width_px) * bpp;
    l.capacity_rows = capacityRows(geometry.tile_px, downsampler);
    l.buffer.resize(size_t(l.capacity_rows) * l.row_bytes);
    l.emit = lv > region.first_level || region.emit_first;
    m_levels.push_back(std::move(l));
  }
}

uint64_t PyramidBuilder::width(uint32_t level) const {
  return m_levels[level - m_region.first_level].width_px;
}
uint64_t PyramidBuilder::height(uint32_t level) const {
  return m_levels[level - m_region.first_level].height_px;
}

bool PyramidBuilder::complete() const {
  for (const Level& l : m_levels) {
    if (l.first_row + l.rows_held != l.height_px) return false;
    if (l.emit && l.next_tile_row < l.height_px) return false;
  }
  return true;
}

void PyramidBuilder::appendRows(const uint8_t* pixels, size_t stride, uint64_t rows) {
  Level& l = m_levels[0];
  while (rows > 0) {
    compact(0);
    const uint64_t room = l.capacity_rows - l.rows_held;
    const uint64_t n = std::min(room, rows);
    for (uint64_t r = 0; r < n; ++r) {
      std::memcpy(l.buffer.data() + (l.rows_held + r) * l.row_bytes, pixels + r * stride, l.row_bytes);
    }
    l.rows_held += n;
    pixels += n * stride;
    rows -= n;
    process(0);
  }
}

void PyramidBuilder::compact(size_t index) {
  Level& l = m_levels[index];
  uint64_t keep_from = l.first_row + l.rows_held;
  if (l.emit) keep_from = std::min(keep_from, l.next_tile_row);
  if (index + 1 < m_levels.size()) {
    const int64_t need = int64_t(l.next_out_row) * 2 + m_downsampler.firstTap();
    keep_from = std::min<uint64_t>(keep_from, uint64_t(std::max<int64_t>(need, 0)));
  }
  keep_from = std::max(keep_from, l.first_row);
  const uint64_t drop = keep_from - l.first_row;
  if (drop == 0) return;
  const uint64_t keep = l.rows_held - drop;
  if (keep > 0) std::memmove(l.buffer.data(), l.buffer.data() + drop * l.row_bytes, keep * l.row_bytes);
  l.first_row = keep_from;
  l.rows_held = keep;
}

void PyramidBuilder::process(size_t index) {
  Level& l = m_levels[index];
  const uint64_t received = l.first_row + l.rows_held;
  const uint32_t tile = m_geometry.tile_px;

  if (index + 1 == m_levels.size() && m_row_sink) {
    // Forward rows not yet forwarded (tracked through next_out_row, which
    // the last level does not otherwise use).
    for (; l.next_out_row < received; ++l.next_out_row) {
      m_row_sink(l.next_out_row, rowPtr(l, l.next_out_row), l.width_px);
    }
  }

  if (l.emit) {
    while (l.next_tile_row < l.height_px &&
           (l.next_tile_row + tile <= received || received == l.height_px)) {
      emitTileRow(l, l.next_tile_row);
      l.next_tile_row += tile;
    }
  }

  if (index + 1 >= m_levels.size()) return;
  Level& c = m_levels[index + 1];
  const int first_tap = m_downsampler.firstTap();
  const int taps = m_downsampler.tapCount();
  m_taps.resize(size_t(taps));
  const int64_t last_row = int64_t(l.height_px) - 1;
  bool produced = false;
  while (l.next_out_row < c.height_px) {
    const int64_t need_last =
        std::min<int64_t>(int64_t(l.next_out_row) * 2 + first_tap + taps - 1, last_row);
    if (need_last >= int64_t(received)) break;
    if (c.rows_held == c.capacity_rows) {
      process(index + 1);
      compact(index + 1);
      if (c.rows_held == c.capacity_rows) break;  // cannot happen: coarser level drains
    }
    for (int k = 0; k < taps; ++k) {
      const int64_t r = std::clamp<int64_t>(int64_t(l.next_out_row) * 2 + first_tap + k, 0, last_row);
      m_taps[size_t(k)] = rowPtr(l, uint64_t(r));
    }
    uint8_t* out = c.buffer.data() + c.rows_held * c.row_bytes;
    m_downsampler.downsampleRow(m_taps.data(), l.width_px, out, &m_scratch);
    ++c.rows_held;
    ++l.next_out_row;
    produced = true;
  }
  if (produced) {
    process(index + 1);
    compact(index + 1);
  }
}

void PyramidBuilder::emitTileRow(Level& l, uint64_t start_row) {
  const uint32_t tile = m_geometry.tile_px;
  const uint32_t bpp = bytesPerPixel(m_geometry.format);
  const size_t tile_row_bytes = size_t(tile) * bpp;
  const uint64_t tiles_x = (l.width_px + tile - 1) / tile;
  for (uint64_t tx = 0; tx < tiles_x; ++tx) {
    std::vector<uint8_t> pixels = m_tile_buffers ? m_tile_buffers() : std::vector<uint8_t>();
    pixels.resize(m_geometry.tileBytes());  // every byte is overwritten below
    const uint64_t x0 = tx * tile;
    const uint64_t valid_w = std::min<uint64_t>(tile, l.width_px - x0);
    for (uint32_t r = 0; r < tile; ++r) {
      // Rows and columns past the level's edge repeat the last one (edge
      // clamp), matching what the box filter does at odd edges.
      const uint64_t src_row = std::min<uint64_t>(start_row + r, l.height_px - 1);
      const uint8_t* src = rowPtr(l, src_row) + x0 * bpp;
      uint8_t* dst = pixels.data() + r * tile_row_bytes;
      std::memcpy(dst, src, valid_w * bpp);
      for (uint64_t x = valid_w; x < tile; ++x) std::memcpy(dst + x * bpp, src + (valid_w - 1) * bpp, bpp);
    }
    TileKey key;
    key.level = l.level;
    key.x = uint32_t((l.x0_px + x0) / tile);
    key.y = uint32_t((l.y0_px + start_row) / tile);
    m_tile_sink(key, std::move(pixels));
  }
}

}  // namespace clipstream
