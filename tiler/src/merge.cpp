// The merge of a sharded run's partial stores into the whole store
// (mergeShards, shard.h; the bands are planShard's, shard_plan.cpp). It copies the
// shards' payloads through the store's reader and writer and builds the
// coarse levels with the tiler's own PyramidBuilder, so its tiles are the
// single run's by construction (docs/tiler.md, "Sharded runs").
#include <clipstream/tiler/shard.h>

#include <clipstream/store/output_file.h>
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

Status mergeImpl(const MergeOptions& o, MergeSummary* summary) {
  const auto start = Clock::now();
  *summary = MergeSummary{};
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
  auto cancelled = [&] {
    return o.cancel != nullptr && o.cancel->load(std::memory_order_relaxed) != 0;
  };

  // Open every part and check that they are the shards 1..N of one run.
  std::vector<Part> parts;
  for (const std::string& p : o.input_paths) {
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
    parts.push_back(std::move(part));
  }
  const StoreInfo& first = parts[0].reader->info();
  const uint32_t count = first.shard.count;
  std::vector<const Part*> by_index(size_t(count) + 1, nullptr);
  for (const Part& part : parts) {
    const StoreInfo& info = part.reader->info();
    const std::string diff = runDifference(first, info);
    if (!diff.empty()) {
      return Status::error(ErrorCode::kInvalidArgument,
                           part.path + " (" + shardName(info.shard) + ") is not from the run of " +
                               parts[0].path + ": " + diff);
    }
    const Part*& slot = by_index[info.shard.index];
    if (slot != nullptr) {
      return Status::error(ErrorCode::kInvalidArgument, slot->path + " and " + part.path +
                                                            " are both " + shardName(info.shard));
    }
    slot = &part;
  }
  std::string missing;
  for (uint32_t k = 1; k <= count; ++k) {
    if (by_index[k] == nullptr) missing += (missing.empty() ? "" : ", ") + std::to_string(k);
  }
  if (!missing.empty()) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "shard" + std::string(missing.find(',') == std::string::npos ? " " : "s ") +
                             missing + " of " + std::to_string(count) + " missing (" +
                             std::to_string(parts.size()) + " partial stores given)");
  }

  const uint64_t width = first.shard.full_width_px;
  const uint64_t height = first.shard.full_height_px;
  const uint32_t tile = first.geometry.tile_px;
  PyramidGeometry geometry;
  if (!makePyramidGeometry(width, height, tile, first.geometry.format, &geometry)) {
    return Status::error(ErrorCode::kBadHeader,
                         parts[0].path + ": shard record: no pyramid for the whole image");
  }
  // Each part must be exactly the band planShard() gives it now: the
  // partition is the contract between tile and merge.
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
  const uint32_t levels = geometry.levelCount();
  const uint32_t owned = first.shard.owned_levels;
  const uint32_t a = owned - 1;
  const uint32_t bpp = bytesPerPixel(geometry.format);
  const Downsampler downsampler(first.encoding.filter, first.encoding.linear_light, geometry.format);
  const uint64_t wa = geometry.levels[a].width_px;
  if (owned < levels) {
    const uint64_t need = PyramidBuilder::bufferBytes(geometry, downsampler, wa, levels - a) +
                          uint64_t(tile) * wa * bpp + (uint64_t(16) << 20);
    if (need > o.memory_budget_bytes) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "--memory-mb " + std::to_string(o.memory_budget_bytes >> 20) +
                               " is too small to build the coarse levels from level " +
                               std::to_string(a) + " (" + std::to_string(wa) +
                               " px wide): needs about " + std::to_string((need >> 20) + 1) + " MB");
    }
  }

  WriterOptions wopt;
  wopt.encoding = first.encoding;
  wopt.geo = first.geo;
  wopt.fsync = o.fsync;
  wopt.replace = o.overwrite;
  wopt.payload_order = o.payload_order;
  std::unique_ptr<TileStoreWriter> writer;
  if (Status s = TileStoreWriter::create(o.output_path, geometry, wopt, &writer); !s) return s;

  uint64_t total = 0;
  for (const LevelInfo& l : geometry.levels) total += uint64_t(l.tiles_x) * l.tiles_y;
  uint64_t done = 0;
  if (o.progress) o.progress(0, total);
  auto tick = [&] {
    ++done;
    if (o.progress && (done % 256 == 0 || done == total)) o.progress(done, total);
  };

  // Levels 0..a: every payload as it is, at its place in the whole grid.
  for (uint32_t k = 1; k <= count; ++k) {
    const Part& part = *by_index[k];
    const StoreInfo& info = part.reader->info();
    for (uint32_t l = 0; l < owned; ++l) {
      const uint32_t dy = uint32_t(info.shard.y0_px / (uint64_t(tile) << l));
      const LevelInfo& li = info.geometry.levels[l];
      for (uint32_t y = 0; y < li.tiles_y; ++y) {
        if (cancelled()) return Status::error(ErrorCode::kCancelled, "interrupted");
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
          if (Status s = writer->write(std::move(e)); !s) return s;
          ++summary->copied_tiles;
          tick();
        }
      }
    }
  }

  // Levels a+1..: built from level a, read back tile row by tile row.
  if (owned < levels) {
    Status sink_status;
    auto tile_sink = [&](const TileKey& key, std::vector<uint8_t>&& pixels) {
      if (!sink_status) return;
      EncodedTile e;
      sink_status = encodeTile(geometry, wopt.encoding, key, pixels, &e);
      if (sink_status) sink_status = writer->write(std::move(e));
      ++summary->built_tiles;
      tick();
    };
    RegionSpec region;
    region.first_level = a;
    region.last_level = levels - 1;
    region.emit_first = false;
    PyramidBuilder builder(geometry, downsampler, region, tile_sink);
    const LevelInfo& la = geometry.levels[a];
    std::vector<uint8_t> strip(size_t(tile) * wa * bpp);
    std::vector<uint8_t> pixels(geometry.tileBytes());
    uint32_t k = 1;
    for (uint32_t ty = 0; ty < la.tiles_y; ++ty) {
      if (cancelled()) return Status::error(ErrorCode::kCancelled, "interrupted");
      // The band holding this tile row (bands are in order, each at least
      // one tile row of level a).
      while (k < count && uint64_t(ty) * tile >= (by_index[k + 1]->reader->info().shard.y0_px >> a)) ++k;
      const Part& part = *by_index[k];
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
  }
  if (Status s = writer->finish(); !s) return s;
  writer.reset();

  summary->width_px = width;
  summary->height_px = height;
  summary->format = geometry.format;
  summary->shards = count;
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
