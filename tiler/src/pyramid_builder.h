// Incremental pyramid construction over one rectangular region of a level
// (the whole image, or one panel block). Rows of the first level arrive top
// to bottom; each level keeps only the rows it still needs (the unfinished
// tile row plus the filter's reach) and emits a tile row as soon as it is
// complete.
//
// Thread rule: owned by one thread (the tiler's build thread). The tile
// sink and row sink are called on that thread.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/tiler/downsample.h>

#include <cstdint>
#include <functional>
#include <vector>

namespace clipstream {

struct RegionSpec {
  uint32_t first_level = 0;  // level of the rows passed to appendRows
  uint32_t last_level = 0;   // coarsest level built here
  uint64_t x0_px = 0;        // region origin at first_level (multiple of tile_px)
  uint64_t y0_px = 0;
  uint64_t width_px = 0;     // region size at first_level; 0 = up to the image edge
  uint64_t height_px = 0;
  bool emit_first = true;    // emit first_level's tiles (false when another builder did)
};

class PyramidBuilder {
 public:
  // Receives one finished tile: tileBytes() bytes, edge pixels clamped.
  using TileSink = std::function<void(const TileKey& key, std::vector<uint8_t>&& pixels)>;
  // Receives finished rows of last_level (region-relative row index).
  using RowSink = std::function<void(uint64_t row, const uint8_t* pixels, uint64_t width_px)>;

  // Supplies a recycled buffer for a tile (may be empty; resized here).
  using BufferSource = std::function<std::vector<uint8_t>()>;

  PyramidBuilder(const PyramidGeometry& geometry, const Downsampler& downsampler,
                 const RegionSpec& region, TileSink tile_sink, RowSink row_sink = {},
                 BufferSource tile_buffers = {});

  // Appends `rows` rows (each width(first_level) pixels, `stride` bytes
  // apart) of the first level, continuing from the previous call.
  void appendRows(const uint8_t* pixels, size_t stride, uint64_t rows);

  // Region size at a level (absolute level number).
  uint64_t width(uint32_t level) const;
  uint64_t height(uint32_t level) const;
  // Bytes held by all level buffers (for the memory model).
  static uint64_t bufferBytes(const PyramidGeometry& geometry, const Downsampler& downsampler,
                              uint64_t width_px_first, uint32_t levels);
  // True once every row of every level was produced and emitted.
  bool complete() const;

 private:
  struct Level {
    uint32_t level = 0;
    uint64_t width_px = 0;
    uint64_t height_px = 0;
    uint64_t x0_px = 0;
    uint64_t y0_px = 0;
    size_t row_bytes = 0;
    uint64_t capacity_rows = 0;
    std::vector<uint8_t> buffer;
    uint64_t first_row = 0;      // region row held in buffer row 0
    uint64_t rows_held = 0;
    uint64_t next_tile_row = 0;  // first region row of the next tile row to emit
    uint64_t next_out_row = 0;   // next row of the coarser level to produce
    bool emit = true;
  };

  static uint64_t capacityRows(uint32_t tile_px, const Downsampler& d);
  uint8_t* rowPtr(Level& l, uint64_t row) { return l.buffer.data() + (row - l.first_row) * l.row_bytes; }
  void compact(size_t index);
  void process(size_t index);
  void emitTileRow(Level& l, uint64_t start_row);

  const PyramidGeometry& m_geometry;
  const Downsampler& m_downsampler;
  RegionSpec m_region;
  TileSink m_tile_sink;
  RowSink m_row_sink;
  BufferSource m_tile_buffers;
  std::vector<Level> m_levels;
  std::vector<float> m_scratch;
  std::vector<const uint8_t*> m_taps;
};

}  // namespace clipstream
