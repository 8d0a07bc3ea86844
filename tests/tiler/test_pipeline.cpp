// The tiler's three-stage pipeline (tiler/src/pipeline.h) on its own,
// writing to a recorder instead of a store: every tile once, in the order
// the builders finish them (children before parents), level-0 pixels that
// are the source's, panels that give the tiles one panel gives, progress on
// the calling thread, and an error in any stage (reader, writer,
// cancellation) that stops the run with that error and without a hang.
#include "tiler_test_util.h"

#include "pipeline.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <future>
#include <map>
#include <mutex>
#include <set>
#include <thread>
#include <tuple>

namespace clipstream::test {
namespace {

constexpr uint32_t kTilePx = 32;

// What the pipeline wrote, in the order it wrote it. Thread-safe: write()
// from any number of threads; read the members after the run.
struct Recorder {
  std::mutex mutex;  // guards everything below
  std::vector<EncodedTile> tiles;
  size_t fail_at = SIZE_MAX;  // the write that fails (0-based), if any
  Status failure = Status::error(ErrorCode::kNoSpace, "disk full (test)");

  Status write(EncodedTile&& tile) {
    std::lock_guard lock(mutex);
    if (tiles.size() == fail_at) return failure;
    tiles.push_back(std::move(tile));
    return okStatus();
  }
};

// A source that fails at its first read of row `fail_row` or below it.
// Thread rule: one thread at a time, as every ImageSource.
class FailingSource final : public ImageSource {
 public:
  FailingSource(std::unique_ptr<ImageSource> inner, uint64_t fail_row)
      : m_inner(std::move(inner)), m_fail_row(fail_row) {}
  const SourceInfo& info() const override { return m_inner->info(); }
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    if (y0 + rows > m_fail_row) return Status::error(ErrorCode::kTruncated, "input.tif: cut short (test)");
    return m_inner->readRows(y0, rows, x0, width, dst, dst_stride);
  }

 private:
  std::unique_ptr<ImageSource> m_inner;
  uint64_t m_fail_row;
};

// One run's fixed parts: a synthetic RGB8 image, its pyramid, the box
// filter, zstd without predictor, and the one-panel layout unless a test
// sets another.
struct PipelineRun {
  std::unique_ptr<ImageSource> source;
  PyramidGeometry geometry;
  Downsampler downsampler{DownsampleFilter::kBox, false, PixelFormat::kRGB8};
  PanelLayout layout;
  StoreEncoding encoding;
  Recorder recorder;
  PipelineInputs in;

  PipelineRun(uint64_t w, uint64_t h, unsigned threads) {
    EXPECT_TRUE(makeSyntheticSource(w, h, PixelFormat::kRGB8, &source).ok());
    EXPECT_TRUE(makePyramidGeometry(w, h, kTilePx, PixelFormat::kRGB8, &geometry));
    layout.local_levels = geometry.levelCount();
    layout.panel_px = uint64_t(kTilePx) << (layout.local_levels - 1);
    encoding.compression = Compression::kZstd;
    encoding.zstd_level = 1;
    encoding.predictor = Predictor::kNone;
    encoding.filter = DownsampleFilter::kBox;
    in.source = source.get();
    in.geometry = &geometry;
    in.downsampler = &downsampler;
    in.layout = &layout;
    in.encoding = &encoding;
    in.threads = threads;
    in.write = [this](EncodedTile&& tile) { return recorder.write(std::move(tile)); };
  }

  // Panels of 2^(levels-1) tiles: the first `levels` levels built per block.
  void usePanels(uint32_t levels) {
    layout.local_levels = levels;
    layout.panel_px = uint64_t(kTilePx) << (levels - 1);
    layout.blocks_x = (geometry.width_px + layout.panel_px - 1) / layout.panel_px;
    layout.blocks_y = (geometry.height_px + layout.panel_px - 1) / layout.panel_px;
  }

  uint64_t pyramidTiles() const {
    uint64_t n = 0;
    for (const LevelInfo& l : geometry.levels) n += uint64_t(l.tiles_x) * l.tiles_y;
    return n;
  }

  // Runs the pipeline on another thread; a hang fails the test (after 60 s
  // the test binary aborts rather than wait for ever).
  Status run(PipelineFigures* figures, std::thread::id* caller = nullptr) {
    ElevationInfo colour;
    std::promise<Status> done;
    std::future<Status> result = done.get_future();
    std::thread t([&] {
      if (caller != nullptr) *caller = std::this_thread::get_id();
      done.set_value(runPipeline(in, &colour, figures));
    });
    if (result.wait_for(std::chrono::seconds(60)) != std::future_status::ready) {
      ADD_FAILURE() << "the pipeline did not return within 60 s";
      std::abort();
    }
    t.join();
    return result.get();
  }
};

std::string keyText(const TileKey& k) {
  return std::to_string(k.level) + "/" + std::to_string(k.x) + "/" + std::to_string(k.y);
}

TEST(Pipeline, WritesEveryTileOnceLevelZeroInRowOrderAndChildrenBeforeParents) {
  PipelineRun run(300, 200, 1);  // 10 x 7 tiles at level 0, 5 levels
  PipelineFigures figures;
  const Status s = run.run(&figures);
  ASSERT_TRUE(s.ok()) << s.toString();
  const std::vector<EncodedTile>& tiles = run.recorder.tiles;
  ASSERT_EQ(tiles.size(), run.pyramidTiles());
  EXPECT_EQ(figures.tiles, tiles.size());

  std::map<std::tuple<uint32_t, uint32_t, uint32_t>, size_t> position;
  std::vector<TileKey> level0;
  for (size_t i = 0; i < tiles.size(); ++i) {
    const TileKey& k = tiles[i].key;
    ASSERT_TRUE(run.geometry.contains(k)) << keyText(k);
    ASSERT_TRUE(position.emplace(std::make_tuple(k.level, k.x, k.y), i).second) << "twice: " << keyText(k);
    if (k.level == 0) level0.push_back(k);
  }
  // Level 0 comes tile row by tile row, left to right.
  for (size_t i = 0; i < level0.size(); ++i) {
    EXPECT_EQ(level0[i].y, i / run.geometry.levels[0].tiles_x) << i;
    EXPECT_EQ(level0[i].x, i % run.geometry.levels[0].tiles_x) << i;
  }
  // A coarser tile is written after each of the tiles it is made from.
  for (const auto& [key, at] : position) {
    const auto [level, x, y] = key;
    if (level == 0) continue;
    for (uint32_t cy = y * 2; cy < y * 2 + 2; ++cy) {
      for (uint32_t cx = x * 2; cx < x * 2 + 2; ++cx) {
        auto child = position.find(std::make_tuple(level - 1, cx, cy));
        if (child == position.end()) continue;  // past the edge of the level below
        EXPECT_LT(child->second, at) << level << "/" << x << "/" << y;
      }
    }
  }
}

// Level-0 tiles of `tiles` decoded, keyed by (x, y).
std::map<std::pair<uint32_t, uint32_t>, std::vector<uint8_t>> decodeLevel0(const PipelineRun& run,
                                                                         const std::vector<EncodedTile>& tiles) {
  std::map<std::pair<uint32_t, uint32_t>, std::vector<uint8_t>> out;
  for (const EncodedTile& t : tiles) {
    if (t.key.level != 0) continue;
    RawTile raw{t.key, t.location, t.payload};
    std::vector<uint8_t> pixels(run.geometry.tileBytes());
    EXPECT_TRUE(decodeTile(run.geometry, run.encoding, raw, pixels).ok());
    out[{t.key.x, t.key.y}] = std::move(pixels);
  }
  return out;
}

TEST(Pipeline, LevelZeroTilesHoldTheSourcesPixelsWithTheEdgeRepeated) {
  PipelineRun run(100, 70, 2);  // edges at 100 - 96 = 4 and 70 - 64 = 6 pixels into the last tiles
  run.usePanels(2);     // 64 px panels: the reader's block offsets matter
  PipelineFigures figures;
  ASSERT_TRUE(run.run(&figures).ok());
  const auto level0 = decodeLevel0(run, run.recorder.tiles);
  ASSERT_EQ(level0.size(), size_t(4 * 3));
  uint64_t bad = 0;
  for (const auto& [xy, pixels] : level0) {
    for (uint32_t ty = 0; ty < kTilePx; ++ty) {
      for (uint32_t tx = 0; tx < kTilePx; ++tx) {
        const uint64_t x = std::min<uint64_t>(uint64_t(xy.first) * kTilePx + tx, 99);
        const uint64_t y = std::min<uint64_t>(uint64_t(xy.second) * kTilePx + ty, 69);
        uint8_t want[3];
        syntheticPixel(x, y, PixelFormat::kRGB8, want);
        if (std::memcmp(want, pixels.data() + (size_t(ty) * kTilePx + tx) * 3, 3) != 0) ++bad;
      }
    }
  }
  EXPECT_EQ(bad, 0u);
}

TEST(Pipeline, PanelsGiveTheTilesOfOnePanel) {
  PipelineRun whole(500, 300, 3);
  PipelineFigures figures;
  ASSERT_TRUE(whole.run(&figures).ok());
  for (uint32_t local_levels : {1u, 2u, 3u}) {
    PipelineRun panels(500, 300, 3);
    panels.usePanels(local_levels);
    ASSERT_GT(panels.layout.blocks_x, 1u);
    ASSERT_TRUE(panels.run(&figures).ok());
    ASSERT_EQ(panels.recorder.tiles.size(), whole.recorder.tiles.size());
    std::map<std::string, const EncodedTile*> by_key;
    for (const EncodedTile& t : whole.recorder.tiles) by_key[keyText(t.key)] = &t;
    for (const EncodedTile& t : panels.recorder.tiles) {
      auto it = by_key.find(keyText(t.key));
      ASSERT_NE(it, by_key.end()) << keyText(t.key);
      EXPECT_EQ(t.location.constant, it->second->location.constant) << keyText(t.key);
      EXPECT_EQ(t.location.checksum, it->second->location.checksum)
          << keyText(t.key) << " with " << local_levels << " levels per panel";
      EXPECT_EQ(t.payload, it->second->payload) << keyText(t.key);
    }
  }
}

TEST(Pipeline, ProgressRunsOnTheCallingThreadFromZeroToEveryPixel) {
  PipelineRun run(300, 200, 2);
  std::vector<uint64_t> done;
  std::set<std::thread::id> threads;
  uint64_t total = 0;
  run.in.progress = [&](uint64_t done_px, uint64_t total_px) {
    done.push_back(done_px);
    threads.insert(std::this_thread::get_id());
    total = total_px;
  };
  PipelineFigures figures;
  std::thread::id caller;
  ASSERT_TRUE(run.run(&figures, &caller).ok());
  EXPECT_EQ(total, 300u * 200u);
  ASSERT_EQ(done.size(), 1u + 7u);  // the start, then one strip per tile row
  EXPECT_EQ(done.front(), 0u);
  EXPECT_EQ(done.back(), total);
  EXPECT_TRUE(std::is_sorted(done.begin(), done.end()));
  ASSERT_EQ(threads.size(), 1u);
  EXPECT_EQ(*threads.begin(), caller);
}

TEST(Pipeline, AReaderErrorStopsTheRunWithThatError) {
  for (unsigned threads : {1u, 4u}) {
    PipelineRun run(2000, 2000, threads);
    run.source = std::make_unique<FailingSource>(std::move(run.source), 640);
    run.in.source = run.source.get();
    PipelineFigures figures;
    figures.tiles = 12345;
    const Status s = run.run(&figures);
    EXPECT_EQ(s.code, ErrorCode::kTruncated) << threads;
    EXPECT_EQ(s.message, "input.tif: cut short (test)");
    EXPECT_LT(run.recorder.tiles.size(), run.pyramidTiles());
    EXPECT_EQ(figures.tiles, 12345u);  // left alone on failure
  }
}

TEST(Pipeline, AWriteErrorStopsEveryStageWithThatError) {
  for (unsigned threads : {1u, 4u}) {
    PipelineRun run(2000, 2000, threads);  // 63 x 63 level-0 tiles: many more than the queues hold
    run.recorder.fail_at = 5;
    PipelineFigures figures;
    const Status s = run.run(&figures);
    EXPECT_EQ(s.code, ErrorCode::kNoSpace) << threads;
    EXPECT_EQ(s.message, "disk full (test)");
    EXPECT_EQ(run.recorder.tiles.size(), 5u);  // the write that failed was the last
  }
}

// Counts the strips read. Thread rule: one thread at a time reads, as every
// ImageSource; reads() from any thread.
class CountingSource final : public ImageSource {
 public:
  explicit CountingSource(std::unique_ptr<ImageSource> inner) : m_inner(std::move(inner)) {}
  const SourceInfo& info() const override { return m_inner->info(); }
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    Status s = m_inner->readRows(y0, rows, x0, width, dst, dst_stride);
    m_reads.fetch_add(1);
    return s;
  }
  int reads() const { return m_reads.load(); }

 private:
  std::unique_ptr<ImageSource> m_inner;
  std::atomic<int> m_reads{0};
};

TEST(Pipeline, AnErrorInTheBuildingStageReleasesAReaderBlockedOnAFullPipeline) {
  // An allocation failure while building, simulated by the progress
  // callback (which runs on the building thread) once the reader has filled
  // every strip buffer and waits for one to come back: only the building
  // stage's abort can release it.
  PipelineRun run(2000, 2000, 2);
  auto counting = std::make_unique<CountingSource>(std::move(run.source));
  CountingSource* reads = counting.get();
  run.source = std::move(counting);
  run.in.source = run.source.get();
  run.in.progress = [&](uint64_t done_px, uint64_t) {
    if (done_px == 0) return;
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (reads->reads() < 3 && std::chrono::steady_clock::now() < give_up) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));  // let it block on the 4th buffer
    throw std::bad_alloc();
  };
  PipelineFigures figures;
  const Status s = run.run(&figures);
  EXPECT_EQ(s.code, ErrorCode::kOutOfMemory);
  EXPECT_EQ(s.message, "an allocation failed while building levels");
  EXPECT_EQ(reads->reads(), 3);  // one strip being built, two queued: the reader got no further
}

TEST(Pipeline, CancellingStopsTheRunAsInterrupted) {
  PipelineRun run(2000, 2000, 2);
  std::atomic<int> cancel{0};
  run.in.cancel = &cancel;
  run.in.progress = [&](uint64_t done_px, uint64_t) {
    if (done_px > 0) cancel = 2;  // as a SIGINT handler would, after the first strip
  };
  PipelineFigures figures;
  const Status s = run.run(&figures);
  EXPECT_EQ(s.code, ErrorCode::kCancelled);
  EXPECT_EQ(s.message, "interrupted");
  EXPECT_LT(run.recorder.tiles.size(), run.pyramidTiles());
}

}  // namespace
}  // namespace clipstream::test
