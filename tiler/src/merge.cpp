// The merge of a sharded run's partial stores into the whole store
// (mergeShards, shard.h; the bands are planShard's, shard_plan.cpp). It copies the
// shards' payloads through the store's reader and writer and builds the
// coarse levels with the tiler's own PyramidBuilder, so its tiles are the
// single run's by construction (docs/tiler.md, "Sharded runs").
#include <clipstream/tiler/shard.h>

#include <clipstream/util/output_file.h>
#include <clipstream/tiler/downsample.h>

#include "pyramid_builder.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <memory>

namespace clipstream {

namespace {

using Clock = std::chrono::steady_clock;

std::string shardName(const ShardInfo& s) {
  return "shard " + std::to_string(s.index) + "/" + std::to_string(s.count);
}

// A tile's failure names the file it came from (the reader's payload
// errors name only the tile).
Status inFile(const std::string& path, Status s) {
  if (!s && s.message.rfind(path, 0) != 0) s.message = path + ": " + s.message;
  return s;
}

// The first way `b` differs from `a` in what the whole store depends on,
// or "" when they are shards of one run.
std::string runDifference(const StoreInfo& a, const StoreInfo& b) {
  if (a.shard.count != b.shard.count) {
    return "it is one of " + std::to_string(b.shard.count) + " shards, not " +
           std::to_string(a.shard.count);
  }
  if (a.shard.full_width_px != b.shard.full_width_px ||
      a.shard.full_height_px != b.shard.full_height_px) {
    return "its image is " + std::to_string(b.shard.full_width_px) + "x" +
           std::to_string(b.shard.full_height_px) + ", not " +
           std::to_string(a.shard.full_width_px) + "x" + std::to_string(a.shard.full_height_px);
  }
  if (a.geometry.tile_px != b.geometry.tile_px) return "its tile size differs";
  if (a.geometry.format != b.geometry.format) {
    return std::string("its pixel format is ") + pixelFormatName(b.geometry.format) + ", not " +
           pixelFormatName(a.geometry.format);
  }
  const StoreEncoding& ea = a.encoding;
  const StoreEncoding& eb = b.encoding;
  if (ea.compression != eb.compression || ea.zstd_level != eb.zstd_level ||
      ea.predictor != eb.predictor) {
    return "its encoding (compression, zstd level or predictor) differs";
  }
  if (ea.filter != eb.filter || ea.linear_light != eb.linear_light) return "its filter differs";
  if (a.elevation.present != b.elevation.present) return "one is an elevation store";
  if (a.geo.present != b.geo.present || a.geo.crs != b.geo.crs ||
      std::memcmp(a.geo.transform, b.geo.transform, sizeof(a.geo.transform)) != 0) {
    return "its georeference differs";
  }
  if (a.shard.owned_levels != b.shard.owned_levels) return "it holds a different number of levels";
  if (a.shard.fingerprint != b.shard.fingerprint) {
    return "it was made from a different input or with different options (run fingerprints differ)";
  }
  return {};
}

struct Part {
  std::string path;
  std::unique_ptr<TileStoreReader> reader;
};

// The parts at their shard numbers: [k] is shard k (1..N), [0] is unused.
// The pointers are into the vector of parts, which must outlive them.
using PartsByIndex = std::vector<const Part*>;

// Checks the paths before anything is opened: at least one input, an
// output that is none of them and is free (or, with overwrite, a regular
// file that may be replaced).
Status checkPaths(const MergeOptions& o) {
  if (o.input_paths.empty()) {
    return Status::error(ErrorCode::kInvalidArgument, "no partial stores to merge");
  }
  if (o.output_path.empty()) return Status::error(ErrorCode::kInvalidArgument, "no output path");
  for (const std::string& p : o.input_paths) {
    if (sameFile(p, o.output_path)) {
      return Status::error(ErrorCode::kInvalidArgument,
                           o.output_path + " is the input " + p + "; refusing to overwrite it");
    }
  }
  OutputOptions out_options;
  out_options.existing = o.overwrite ? ExistingOutput::kReplaceRegular : ExistingOutput::kRefuse;
  if (Status s = checkOutputPath(o.output_path, out_options); !s) {
    if (s.code == ErrorCode::kAlreadyExists) s.message = o.output_path + " (use --force to overwrite)";
    return s;
  }
  return okStatus();
}

// Opens every input, in the order given, and checks that each is a partial
// store of colour (elevation runs are never sharded).
Status openParts(const std::vector<std::string>& paths, std::vector<Part>* parts) {
  for (const std::string& p : paths) {
    Part part;
    part.path = p;
    if (Status s = TileStoreReader::open(p, &part.reader); !s) return s;
    const StoreInfo& info = part.reader->info();
    if (!info.shard.present) {
      return Status::error(ErrorCode::kInvalidArgument,
                           p + " is not a partial store (it has no shard record; clipstream-tile "
                               "--shard K/N makes them)");
    }
    if (info.elevation.present) {
      return Status::error(ErrorCode::kUnsupported,
                           p + ": elevation stores are not sharded (clipstream-tile refuses them)");
    }
    parts->push_back(std::move(part));
  }
  return okStatus();
}

// Puts each part at its shard number, checking that the parts are the
// shards 1..N of the first part's run: each from that run, none twice,
// none missing.
Status indexParts(const std::vector<Part>& parts, PartsByIndex* by_index) {
  const StoreInfo& first = parts[0].reader->info();
  const uint32_t count = first.shard.count;
  by_index->assign(size_t(count) + 1, nullptr);
  for (const Part& part : parts) {
    const StoreInfo& info = part.reader->info();
    const std::string diff = runDifference(first, info);
    if (!diff.empty()) {
      return Status::error(ErrorCode::kInvalidArgument,
                           part.path + " (" + shardName(info.shard) + ") is not from the run of " +
                               parts[0].path + ": " + diff);
    }
    const Part*& slot = (*by_index)[info.shard.index];
    if (slot != nullptr) {
      return Status::error(ErrorCode::kInvalidArgument, slot->path + " and " + part.path +
                                                            " are both " + shardName(info.shard));
    }
    slot = &part;
  }
  std::string missing;
  for (uint32_t k = 1; k <= count; ++k) {
    if ((*by_index)[k] == nullptr) missing += (missing.empty() ? "" : ", ") + std::to_string(k);
  }
  if (!missing.empty()) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "shard" + std::string(missing.find(',') == std::string::npos ? " " : "s ") +
                             missing + " of " + std::to_string(count) + " missing (" +
                             std::to_string(parts.size()) + " partial stores given)");
  }
  return okStatus();
}

// Checks that each part is exactly the band planShard() gives it now: the
// partition is the contract between tile and merge.
Status checkBands(const PartsByIndex& by_index, uint64_t width, uint64_t height, uint32_t tile) {
  const uint32_t count = uint32_t(by_index.size() - 1);
  for (uint32_t k = 1; k <= count; ++k) {
    const Part& part = *by_index[k];
    const StoreInfo& info = part.reader->info();
    ShardPlan plan;
    Status s = planShard(width, height, tile, k, count, &plan);
    if (!s || plan.y0_px != info.shard.y0_px || plan.height_px != info.geometry.height_px ||
        info.shard.x0_px != 0 || info.geometry.width_px != width ||
        plan.owned_levels != info.shard.owned_levels) {
      return Status::error(ErrorCode::kBadHeader,
                           part.path + ": " + shardName(info.shard) +
                               " does not hold the band this run's partition gives it");
    }
  }
  return okStatus();
}

// Checks that the memory budget holds the buffers that build levels a+1..
// from level a: the builder's rows, one strip of level a and a margin.
Status checkCoarseBudget(const PyramidGeometry& geometry, const Downsampler& downsampler,
                         uint32_t a, uint64_t budget_bytes) {
  const uint32_t levels = geometry.levelCount();
  const uint64_t tile = geometry.tile_px;
  const uint64_t wa = geometry.levels[a].width_px;
  const uint64_t need = PyramidBuilder::bufferBytes(geometry, downsampler, wa, levels - a) +
                        tile * wa * bytesPerPixel(geometry.format) + (uint64_t(16) << 20);
  if (need > budget_bytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--memory-mb " + std::to_string(budget_bytes >> 20) +
                             " is too small to build the coarse levels from level " +
                             std::to_string(a) + " (" + std::to_string(wa) +
                             " px wide): needs about " + std::to_string((need >> 20) + 1) + " MB");
  }
  return okStatus();
}

// What the copy and the build share: the options, the parts, the whole
// store's geometry and writer, the summary's counts and the progress.
// Thread rule: one thread, the caller of mergeShards().
struct MergeRun {
  const MergeOptions& options;
  const PartsByIndex& by_index;
  const PyramidGeometry& geometry;
  TileStoreWriter& writer;
  MergeSummary& summary;
  uint64_t total_tiles = 0;
  uint64_t done_tiles = 0;

  bool cancelled() const {
    return options.cancel != nullptr && options.cancel->load(std::memory_order_relaxed) != 0;
  }
  // One more tile written: progress every 256 tiles and at the last.
  void tick() {
    ++done_tiles;
    if (options.progress && (done_tiles % 256 == 0 || done_tiles == total_tiles)) {
      options.progress(done_tiles, total_tiles);
    }
  }
};

// Levels 0..owned-1: every payload as it is, at its place in the whole grid.
Status copyOwnedLevels(MergeRun& run, uint32_t owned) {
  const uint32_t count = uint32_t(run.by_index.size() - 1);
  const uint32_t tile = run.geometry.tile_px;
  for (uint32_t k = 1; k <= count; ++k) {
    const Part& part = *run.by_index[k];
    const StoreInfo& info = part.reader->info();
    for (uint32_t l = 0; l < owned; ++l) {
      const uint32_t dy = uint32_t(info.shard.y0_px / (uint64_t(tile) << l));
      const LevelInfo& li = info.geometry.levels[l];
      for (uint32_t y = 0; y < li.tiles_y; ++y) {
        if (run.cancelled()) return Status::error(ErrorCode::kCancelled, "interrupted");
        for (uint32_t x = 0; x < li.tiles_x; ++x) {
          RawTile raw;
          if (Status s = part.reader->readRaw(TileKey{l, x, y}, &raw); !s) {
            return inFile(part.path, std::move(s));
          }
          EncodedTile e;
          e.key = TileKey{l, x, y + dy};
          e.location = raw.location;
          e.location.offset = 0;
          e.payload = std::move(raw.payload);
          if (Status s = run.writer.write(std::move(e)); !s) return s;
          ++run.summary.copied_tiles;
          run.tick();
        }
      }
    }
  }
  return okStatus();
}

// Levels a+1..: built from level a, read back from the parts tile row by
// tile row, and encoded with the run's encoding.
Status buildCoarseLevels(MergeRun& run, uint32_t a, const Downsampler& downsampler,
                         const StoreEncoding& encoding) {
  const PyramidGeometry& geometry = run.geometry;
  const uint32_t count = uint32_t(run.by_index.size() - 1);
  const uint32_t tile = geometry.tile_px;
  const uint32_t bpp = bytesPerPixel(geometry.format);
  const uint64_t wa = geometry.levels[a].width_px;
  Status sink_status;
  auto tile_sink = [&](const TileKey& key, std::vector<uint8_t>&& pixels) {
    if (!sink_status) return;
    EncodedTile e;
    sink_status = encodeTile(geometry, encoding, key, pixels, &e);
    if (sink_status) sink_status = run.writer.write(std::move(e));
    ++run.summary.built_tiles;
    run.tick();
  };
  RegionSpec region;
  region.first_level = a;
  region.last_level = geometry.levelCount() - 1;
  region.emit_first = false;
  PyramidBuilder builder(geometry, downsampler, region, tile_sink);
  const LevelInfo& la = geometry.levels[a];
  std::vector<uint8_t> strip(size_t(tile) * wa * bpp);
  std::vector<uint8_t> pixels(geometry.tileBytes());
  uint32_t k = 1;
  for (uint32_t ty = 0; ty < la.tiles_y; ++ty) {
    if (run.cancelled()) return Status::error(ErrorCode::kCancelled, "interrupted");
    // The band holding this tile row (bands are in order, each at least
    // one tile row of level a).
    while (k < count && uint64_t(ty) * tile >= (run.by_index[k + 1]->reader->info().shard.y0_px >> a)) ++k;
    const Part& part = *run.by_index[k];
    const uint32_t local_y = ty - uint32_t((part.reader->info().shard.y0_px >> a) / tile);
    const uint64_t rows = std::min<uint64_t>(tile, la.height_px - uint64_t(ty) * tile);
    for (uint32_t x = 0; x < la.tiles_x; ++x) {
      if (Status s = part.reader->readTile(TileKey{a, x, local_y}, &pixels); !s) {
        return inFile(part.path, std::move(s));
      }
      const uint64_t cols = std::min<uint64_t>(tile, wa - uint64_t(x) * tile);
      for (uint64_t r = 0; r < rows; ++r) {
        std::memcpy(strip.data() + (r * wa + uint64_t(x) * tile) * bpp,
                    pixels.data() + r * tile * bpp, size_t(cols) * bpp);
      }
    }
    builder.appendRows(strip.data(), size_t(wa) * bpp, rows);
    if (!sink_status) return sink_status;
  }
  if (!builder.complete()) {
    return Status::error(ErrorCode::kInvalidArgument, "coarse levels incomplete (internal error)");
  }
  return okStatus();
}

// The merge in its steps: check the paths, open the parts and check they
// are one run's shards in the bands its partition gives them, check the
// budget, then write the whole store (copied levels, built levels) and
// fill the summary.
Status mergeImpl(const MergeOptions& o, MergeSummary* summary) {
  const auto start = Clock::now();
  *summary = MergeSummary{};
  if (Status s = checkPaths(o); !s) return s;
  std::vector<Part> parts;
  if (Status s = openParts(o.input_paths, &parts); !s) return s;
  PartsByIndex by_index;
  if (Status s = indexParts(parts, &by_index); !s) return s;

  const StoreInfo& first = parts[0].reader->info();
  const uint64_t width = first.shard.full_width_px;
  const uint64_t height = first.shard.full_height_px;
  const uint32_t tile = first.geometry.tile_px;
  PyramidGeometry geometry;
  if (!makePyramidGeometry(width, height, tile, first.geometry.format, &geometry)) {
    return Status::error(ErrorCode::kBadHeader,
                         parts[0].path + ": shard record: no pyramid for the whole image");
  }
  if (Status s = checkBands(by_index, width, height, tile); !s) return s;
  const uint32_t levels = geometry.levelCount();
  const uint32_t owned = first.shard.owned_levels;
  const uint32_t a = owned - 1;
  const Downsampler downsampler(first.encoding.filter, first.encoding.linear_light, geometry.format);
  if (owned < levels) {
    if (Status s = checkCoarseBudget(geometry, downsampler, a, o.memory_budget_bytes); !s) return s;
  }

  WriterOptions wopt;
  wopt.encoding = first.encoding;
  wopt.geo = first.geo;
  wopt.fsync = o.fsync;
  wopt.replace = o.overwrite;
  wopt.payload_order = o.payload_order;
  std::unique_ptr<TileStoreWriter> writer;
  if (Status s = TileStoreWriter::create(o.output_path, geometry, wopt, &writer); !s) return s;

  MergeRun run{o, by_index, geometry, *writer, *summary};
  for (const LevelInfo& l : geometry.levels) run.total_tiles += uint64_t(l.tiles_x) * l.tiles_y;
  if (o.progress) o.progress(0, run.total_tiles);
  if (Status s = copyOwnedLevels(run, owned); !s) return s;
  if (owned < levels) {
    if (Status s = buildCoarseLevels(run, a, downsampler, wopt.encoding); !s) return s;
  }
  if (Status s = writer->finish(); !s) return s;
  writer.reset();

  summary->width_px = width;
  summary->height_px = height;
  summary->format = geometry.format;
  summary->shards = first.shard.count;
  summary->levels = levels;
  summary->merged_levels = owned;
  std::error_code ec;
  summary->output_bytes = std::filesystem::file_size(o.output_path, ec);
  summary->geo = first.geo;
  summary->wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  return okStatus();
}

}  // namespace

Status mergeShards(const MergeOptions& options, MergeSummary* summary) {
  try {
    return mergeImpl(options, summary);
  } catch (const std::bad_alloc&) {
    return Status::error(ErrorCode::kOutOfMemory, "an allocation failed while merging");
  }
}

}  // namespace clipstream
