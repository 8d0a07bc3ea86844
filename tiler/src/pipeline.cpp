// The tiler's reader -> builder -> encoder pipeline (pipeline.h).
#include "pipeline.h"

#include "bounded_queue.h"
#include "height_bounds.h"
#include "pyramid_builder.h"

#include <algorithm>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <time.h>

namespace clipstream {
namespace {

// CPU time of the calling thread: stage costs that do not count time spent
// waiting on queues or preempted by other processes.
double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// A refused thread (the system's thread or memory limit) fails the run
// like any other resource: reported, temporaries removed.
Status threadRefused(const char* which, const std::system_error& e) {
  return Status::error(ErrorCode::kIo, std::string("cannot start the ") + which + " thread: " + e.what());
}

// First error wins; later ones are usually consequences of it.
// Thread-safe: all public methods.
class ErrorSlot {
 public:
  void set(Status s) {
    std::lock_guard lock(m_mutex);
    if (m_status.ok()) m_status = std::move(s);
    m_failed.store(true, std::memory_order_release);
  }
  bool failed() const { return m_failed.load(std::memory_order_acquire); }
  Status get() {
    std::lock_guard lock(m_mutex);
    return m_status;
  }

 private:
  std::mutex m_mutex;  // guards m_status
  Status m_status;
  std::atomic<bool> m_failed{false};
};

struct StripItem {
  uint64_t bx = 0, by = 0;  // panel block
  uint64_t y0 = 0;          // first row, relative to the block
  uint32_t rows = 0;
  uint64_t width_px = 0;
  std::vector<uint8_t> pixels;
};

struct TileJob {
  TileKey key;
  std::vector<uint8_t> pixels;
  TileHeights heights;  // elevation stores
};

// One run. Owned by the thread that calls run(), which is the building
// stage; readStrips() runs on the reader thread and encodeTiles() on each
// encoder thread. The queues and the error slot are thread-safe; the other
// shared members say what guards them; the build state (m_coarse and
// below) belongs to the building thread.
class Pipeline {
 public:
  Pipeline(const PipelineInputs& in, ElevationInfo* elevation);
  Status run(PipelineFigures* figures);

 private:
  bool cancelled() const {
    return m_in.cancel != nullptr && m_in.cancel->load(std::memory_order_relaxed) != 0;
  }
  void abortAll();
  std::vector<uint8_t> takeBuffer();
  void readStrips();
  void readBlock(uint64_t bx, uint64_t by);
  void encodeTiles();
  void buildLevels();
  void startBlock(const StripItem& item);
  void emitTile(const TileKey& key, std::vector<uint8_t>&& pixels);

  const PipelineInputs& m_in;
  const PyramidGeometry& m_geometry;
  const PanelLayout& m_layout;
  ElevationInfo* m_elevation;
  const uint32_t m_tile;
  const uint32_t m_bpp;
  const uint32_t m_levels;
  const uint32_t m_m;  // the coarsest level built per block

  ErrorSlot m_error;
  BoundedQueue<StripItem> m_filled;
  BoundedQueue<std::vector<uint8_t>> m_free_buffers;
  BoundedQueue<TileJob> m_jobs;
  std::atomic<uint64_t> m_tiles_done{0};
  // Tile buffers go back here after encoding, so steady state allocates
  // (and zero-fills) nothing per tile. Bounded by the job queue's size.
  std::mutex m_recycled_mutex;  // guards m_recycled
  std::vector<std::vector<uint8_t>> m_recycled;
  double m_read_s = 0.0;  // written by the reader thread, read after it is joined
  std::mutex m_encode_time_mutex;  // guards m_encode_s
  double m_encode_s = 0.0;

  // Building thread only. The coarse builder over level m is fed from the
  // per-block builders' level-m rows through a staging strip one tile row
  // high.
  std::optional<HeightBoundsTracker> m_bounds;
  std::unique_ptr<PyramidBuilder> m_coarse;
  std::vector<uint8_t> m_staging;
  uint64_t m_staging_rows = 0;
  std::unique_ptr<PyramidBuilder> m_local;
  uint64_t m_cur_bx = UINT64_MAX, m_cur_by = UINT64_MAX;
};

Pipeline::Pipeline(const PipelineInputs& in, ElevationInfo* elevation)
    : m_in(in),
      m_geometry(*in.geometry),
      m_layout(*in.layout),
      m_elevation(elevation),
      m_tile(in.geometry->tile_px),
      m_bpp(bytesPerPixel(in.geometry->format)),
      m_levels(in.geometry->levelCount()),
      m_m(in.layout->local_levels - 1),
      m_filled(kStripsInFlight - 1),
      m_free_buffers(kStripsInFlight),
      m_jobs(size_t(in.threads) * kTileJobsPerThread) {
  for (uint32_t i = 0; i < kStripsInFlight; ++i) {
    std::vector<uint8_t> buffer;
    (void)m_free_buffers.push(std::move(buffer));
  }
}

void Pipeline::abortAll() {
  m_filled.abort();
  m_free_buffers.abort();
  m_jobs.abort();
}

std::vector<uint8_t> Pipeline::takeBuffer() {
  std::lock_guard lock(m_recycled_mutex);
  if (m_recycled.empty()) return {};
  std::vector<uint8_t> b = std::move(m_recycled.back());
  m_recycled.pop_back();
  return b;
}

// Reader thread: every block of the layout, row of blocks by row of blocks,
// left to right, one strip of a tile row at a time.
void Pipeline::readStrips() {
  try {
    const double cpu0 = threadCpuSeconds();
    for (uint64_t by = 0; by < m_layout.blocks_y && !m_error.failed(); ++by) {
      for (uint64_t bx = 0; bx < m_layout.blocks_x && !m_error.failed(); ++bx) readBlock(bx, by);
    }
    m_read_s = threadCpuSeconds() - cpu0;
  } catch (const std::bad_alloc&) {
    m_error.set(Status::error(ErrorCode::kOutOfMemory, "an allocation failed while reading the input"));
    abortAll();
  }
  m_filled.close();
}

void Pipeline::readBlock(uint64_t bx, uint64_t by) {
  const uint64_t y_origin = by * m_layout.panel_px;
  const uint64_t block_h = std::min(m_layout.panel_px, m_geometry.height_px - y_origin);
  const uint64_t x_origin = bx * m_layout.panel_px;
  const uint64_t block_w = std::min(m_layout.panel_px, m_geometry.width_px - x_origin);
  for (uint64_t y = 0; y < block_h; y += m_tile) {
    if (m_error.failed()) return;
    if (cancelled()) {
      m_error.set(Status::error(ErrorCode::kCancelled, "interrupted"));
      abortAll();
      return;
    }
    StripItem item;
    if (!m_free_buffers.pop(&item.pixels)) return;
    item.bx = bx, item.by = by, item.y0 = y, item.width_px = block_w;
    item.rows = uint32_t(std::min<uint64_t>(m_tile, block_h - y));
    item.pixels.resize(size_t(item.rows) * block_w * m_bpp);
    Status rs = m_in.source->readRows(y_origin + y, item.rows, x_origin, block_w,
                                      item.pixels.data(), size_t(block_w) * m_bpp);
    if (!rs) {
      m_error.set(std::move(rs));
      abortAll();
      return;
    }
    if (!m_filled.push(std::move(item))) return;
  }
}

// Each encoder thread: encodes and writes tiles until the queue is closed
// and drained, or aborted.
void Pipeline::encodeTiles() {
  const double cpu0 = threadCpuSeconds();
  TileJob job;
  EncodedTile encoded;
  while (m_jobs.pop(&job)) {
    Status es;
    try {
      es = encodeTile(m_geometry, *m_in.encoding, job.key, job.pixels, &encoded);
      encoded.location.min_height = job.heights.min_height;
      encoded.location.max_height = job.heights.max_height;
      encoded.location.error = job.heights.error;
      if (es) es = m_in.write(std::move(encoded));
    } catch (const std::bad_alloc&) {
      es = Status::error(ErrorCode::kOutOfMemory, "an allocation failed while encoding tiles");
    }
    {
      std::lock_guard lock(m_recycled_mutex);
      if (m_recycled.size() < size_t(m_in.threads) * (kTileJobsPerThread + 2)) {
        m_recycled.push_back(std::move(job.pixels));
      }
    }
    if (!es) {
      m_error.set(std::move(es));
      abortAll();
      break;
    }
    m_tiles_done.fetch_add(1, std::memory_order_relaxed);
  }
  std::lock_guard lock(m_encode_time_mutex);
  m_encode_s += threadCpuSeconds() - cpu0;
}

// Building thread: a finished tile goes to the encoders, with its height
// bounds in an elevation store.
void Pipeline::emitTile(const TileKey& key, std::vector<uint8_t>&& pixels) {
  TileHeights tile_heights;
  if (m_bounds) {
    tile_heights = m_bounds->add(key, pixels);
    if (key.level + 1 == m_levels) {
      m_elevation->min_height = tile_heights.min_height;
      m_elevation->max_height = tile_heights.max_height;
    }
  }
  if (!m_jobs.push(TileJob{key, std::move(pixels), tile_heights}) && !m_error.failed()) {
    m_error.set(Status::error(ErrorCode::kCancelled, "encoder queue closed"));
  }
}

// Building thread: a new block's builder of levels 0..m, whose level-m rows
// go into the staging strip when a coarse builder takes them.
void Pipeline::startBlock(const StripItem& item) {
  m_cur_bx = item.bx, m_cur_by = item.by;
  RegionSpec rs;
  rs.first_level = 0;
  rs.last_level = m_m;
  rs.x0_px = item.bx * m_layout.panel_px;
  rs.y0_px = item.by * m_layout.panel_px;
  rs.width_px = item.width_px;
  rs.height_px = std::min(m_layout.panel_px, m_geometry.height_px - rs.y0_px);
  PyramidBuilder::RowSink row_sink;
  if (m_coarse) {
    const uint64_t col = item.bx * m_tile;  // block origin at level m
    const uint64_t wm = m_geometry.levels[m_m].width_px;
    row_sink = [this, col, wm](uint64_t row, const uint8_t* px, uint64_t w) {
      std::memcpy(m_staging.data() + (row * wm + col) * m_bpp, px, size_t(w) * m_bpp);
      m_staging_rows = std::max(m_staging_rows, row + 1);
    };
  }
  m_local = std::make_unique<PyramidBuilder>(
      m_geometry, *m_in.downsampler, rs,
      [this](const TileKey& key, std::vector<uint8_t>&& pixels) { emitTile(key, std::move(pixels)); },
      row_sink, [this] { return takeBuffer(); });
}

// Building thread: appends each strip to its block's builder (and a
// finished row of blocks to the coarse builder), reporting progress, until
// the reader is done or a stage failed.
void Pipeline::buildLevels() {
  const uint64_t total_px = m_geometry.width_px * m_geometry.height_px;
  uint64_t done_px = 0;
  try {
    if (m_in.progress) m_in.progress(0, total_px);
    if (m_elevation->present) m_bounds.emplace(m_geometry, *m_elevation);
    const uint64_t wm = m_geometry.levels[m_m].width_px;
    if (m_m + 1 < m_levels) {
      RegionSpec cr;
      cr.first_level = m_m;
      cr.last_level = m_levels - 1;
      cr.emit_first = false;
      m_coarse = std::make_unique<PyramidBuilder>(
          m_geometry, *m_in.downsampler, cr,
          [this](const TileKey& key, std::vector<uint8_t>&& pixels) { emitTile(key, std::move(pixels)); },
          PyramidBuilder::RowSink{}, [this] { return takeBuffer(); });
      m_staging.resize(size_t(m_tile) * wm * m_bpp);
    }
    StripItem item;
    while (m_filled.pop(&item)) {
      if (m_error.failed()) break;
      if (cancelled()) {
        m_error.set(Status::error(ErrorCode::kCancelled, "interrupted"));
        break;
      }
      if (item.bx != m_cur_bx || item.by != m_cur_by) startBlock(item);
      m_local->appendRows(item.pixels.data(), size_t(item.width_px) * m_bpp, item.rows);
      if (m_coarse && m_local->complete() && item.bx + 1 == m_layout.blocks_x) {
        m_coarse->appendRows(m_staging.data(), size_t(wm) * m_bpp, m_staging_rows);
        m_staging_rows = 0;
      }
      done_px += uint64_t(item.rows) * item.width_px;
      if (m_in.progress) m_in.progress(done_px, total_px);
      if (!m_free_buffers.push(std::move(item.pixels))) break;
    }
  } catch (const std::bad_alloc&) {
    m_error.set(Status::error(ErrorCode::kOutOfMemory, "an allocation failed while building levels"));
  }
  // The build state is done with: free its memory before the encoders drain.
  m_local.reset();
  m_coarse.reset();
  m_staging = std::vector<uint8_t>();
  m_bounds.reset();
}

// Starts the reader and encoder threads, builds on this thread, then stops
// the others (close the job queue when all went well, else abort every
// queue) and joins them: the one shutdown order of the run.
Status Pipeline::run(PipelineFigures* figures) {
  std::thread reader;
  try {
    reader = std::thread([this] { readStrips(); });
  } catch (const std::system_error& e) {
    return threadRefused("reader", e);
  }
  std::vector<std::thread> encoders;
  for (unsigned t = 0; t < m_in.threads; ++t) {
    try {
      encoders.emplace_back([this] { encodeTiles(); });
    } catch (const std::system_error& e) {
      m_error.set(threadRefused("encoder", e));
      abortAll();
      break;
    }
  }
  const double build_cpu0 = threadCpuSeconds();
  buildLevels();
  if (m_error.failed() || cancelled()) {
    if (!m_error.failed()) m_error.set(Status::error(ErrorCode::kCancelled, "interrupted"));
    abortAll();
  } else {
    m_jobs.close();
  }
  const double build_s = threadCpuSeconds() - build_cpu0;
  reader.join();
  for (std::thread& t : encoders) t.join();
  if (m_error.failed()) return m_error.get();
  figures->tiles = m_tiles_done.load();
  figures->read_s = m_read_s;
  figures->build_s = build_s;
  figures->encode_s = m_encode_s;
  return okStatus();
}

}  // namespace

Status runPipeline(const PipelineInputs& in, ElevationInfo* elevation, PipelineFigures* figures) {
  Pipeline pipeline(in, elevation);
  return pipeline.run(figures);
}

}  // namespace clipstream
