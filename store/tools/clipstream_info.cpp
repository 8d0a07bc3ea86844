// clipstream-info: prints what a tile store (or a COG, as the programs
// stream it) holds and, with --verify, decodes every tile. Thin: all format knowledge lives in clipstream_store.
#include <clipstream/cli/cli.h>
#include <clipstream/cli/progress.h>
#include <clipstream/cli/store_json.h>
#include <clipstream/store/cog.h>
#include <clipstream/store/tile_store.h>

#include <nlohmann/json.hpp>

#include <cinttypes>
#include <cstdio>
#include <string>

namespace {

using namespace clipstream;

// Exit codes: the programs' shared table (clipstream/cli/cli.h, docs/cli.md).
constexpr int kExitOk = cli::kExitOk;
constexpr int kExitOpenFailed = cli::kExitFailure;
constexpr int kExitCorrupt = cli::kExitCorrupt;

const char* compressionName(Compression compression) {
  return compression == Compression::kZstd ? "zstd" : "none";
}
const char* predictorName(Predictor predictor) {
  return predictor == Predictor::kLeftDelta ? "left-delta" : "none";
}

std::string humanBytes(uint64_t bytes) {
  char text[32];
  if (bytes >= (uint64_t(1) << 30)) {
    std::snprintf(text, sizeof(text), "%.2f GiB", double(bytes) / double(uint64_t(1) << 30));
  } else if (bytes >= (uint64_t(1) << 20)) {
    std::snprintf(text, sizeof(text), "%.2f MiB", double(bytes) / double(uint64_t(1) << 20));
  } else if (bytes >= 1024) {
    std::snprintf(text, sizeof(text), "%.1f KiB", double(bytes) / 1024.0);
  } else {
    std::snprintf(text, sizeof(text), "%" PRIu64 " B", bytes);
  }
  return text;
}

double ratio(uint64_t raw, uint64_t stored) {
  return stored == 0 ? 0.0 : double(raw) / double(stored);
}

// Text form of raw/stored; "-" when nothing is stored (all tiles constant).
std::string ratioText(uint64_t raw, uint64_t stored) {
  if (stored == 0) return "-";
  char text[32];
  std::snprintf(text, sizeof(text), "%.2f", ratio(raw, stored));
  return text;
}

// "level L tile (x, y): <problem>", without repeating the key the status
// message may already start with.
std::string problemLine(const TileStoreReader::Problem& problem) {
  const std::string key = "level " + std::to_string(problem.key.level) + " tile (" +
                          std::to_string(problem.key.x) + ", " + std::to_string(problem.key.y) +
                          ")";
  std::string message = problem.status.message;
  if (message.rfind(key + ": ", 0) == 0) message = message.substr(key.size() + 2);
  return key + ": " + errorCodeName(problem.status.code) + ": " + message;
}

// The georeference lines of the text report (a store's or a COG's).
void printGeoReference(const GeoReference& geo) {
  if (geo.present) {
    const double* t = geo.transform;
    std::printf("georeference origin (%.10g, %.10g), pixel size (%.10g, %.10g), rotation (%.10g, %.10g)\n",
                t[0], t[3], t[1], t[5], t[2], t[4]);
    std::printf("CRS          %s\n", geo.crs.empty() ? "(none)" : printableText(geo.crs).c_str());
  } else {
    std::printf("georeference none\n");
  }
}

void printText(const std::string& path, const StoreInfo& info,
               const std::vector<LevelStats>* stats) {
  const PyramidGeometry& g = info.geometry;
  std::printf("store        %s\n", path.c_str());
  std::printf("version      %u\n", info.format_version);
  std::printf("file size    %" PRIu64 " bytes (%s)\n", info.file_bytes,
              humanBytes(info.file_bytes).c_str());
  std::printf("image        %" PRIu64 " x %" PRIu64 " px, %s\n", g.width_px, g.height_px,
              pixelFormatName(g.format));
  std::printf("tile size    %u px\n", g.tile_px);
  std::printf("levels       %u\n", g.levelCount());
  if (info.encoding.compression == Compression::kZstd) {
    std::printf("compression  zstd level %d\n", info.encoding.zstd_level);
  } else {
    std::printf("compression  none\n");
  }
  std::printf("predictor    %s\n", predictorName(info.encoding.predictor));
  std::printf("filter       %s%s\n", downsampleFilterName(info.encoding.filter),
              info.encoding.linear_light ? " (linear light)" : "");
  printGeoReference(info.geo);
  if (info.elevation.present) {
    const ElevationInfo& e = info.elevation;
    std::printf("layer        elevation\n");
    std::printf("heights      %.10g to %.10g %s%s\n", e.min_height, e.max_height,
                heightUnitsName(e.units), e.units_assumed ? " (assumed: the input did not say)" : "");
    if (g.format != PixelFormat::kF32) {
      std::printf("height rule  offset %.10g + scale %.10g x sample\n", e.offset, e.scale);
    }
    if (e.quantised) {
      std::printf("precision    quantised in steps of %.6g: error <= %.6g %s (largest measured %.6g)\n",
                  e.scale, e.scale / 2, heightUnitsName(e.units), e.max_error);
    } else {
      std::printf("precision    exact (lossless)\n");
    }
    if (e.has_nodata) {
      std::printf("no-data      %.10g in the input; %" PRIu64 " samples filled from their neighbours\n",
                  e.nodata, e.filled_samples);
    } else {
      std::printf("no-data      none declared; %" PRIu64 " NaN samples filled\n", e.filled_samples);
    }
  } else {
    std::printf("layer        colour\n");
  }
  if (info.shard.present) {
    const ShardInfo& sh = info.shard;
    std::printf("partial      shard %u/%u of a %" PRIu64 "x%" PRIu64 " image: band at (%" PRIu64
                ", %" PRIu64 "), levels 0..%u; clipstream-merge joins the shards\n",
                sh.index, sh.count, sh.full_width_px, sh.full_height_px, sh.x0_px, sh.y0_px,
                sh.owned_levels - 1);
  }
  if (stats == nullptr) return;
  std::printf("\nlevel\twidth_px\theight_px\ttiles\tconstant_tiles\tstored_bytes\traw_bytes\tratio\n");
  LevelStats total;
  for (uint32_t l = 0; l < stats->size(); ++l) {
    const LevelStats& s = (*stats)[l];
    std::printf("%u\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64
                "\t%s\n",
                l, g.levels[l].width_px, g.levels[l].height_px, s.tiles, s.constant_tiles,
                s.stored_bytes, s.raw_bytes, ratioText(s.raw_bytes, s.stored_bytes).c_str());
    total.tiles += s.tiles;
    total.constant_tiles += s.constant_tiles;
    total.stored_bytes += s.stored_bytes;
    total.raw_bytes += s.raw_bytes;
  }
  std::printf("total\t\t\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64 "\t%s\n", total.tiles,
              total.constant_tiles, total.stored_bytes, total.raw_bytes,
              ratioText(total.raw_bytes, total.stored_bytes).c_str());
}

nlohmann::json toJson(const std::string& path, const StoreInfo& info,
                      const std::vector<LevelStats>* stats) {
  const PyramidGeometry& g = info.geometry;
  nlohmann::json out;
  out["path"] = path;
  out["version"] = info.format_version;
  out["file_bytes"] = info.file_bytes;
  out["width_px"] = g.width_px;
  out["height_px"] = g.height_px;
  out["tile_px"] = g.tile_px;
  out["pixel_format"] = pixelFormatName(g.format);
  out["levels"] = g.levelCount();
  out["compression"] = compressionName(info.encoding.compression);
  out["zstd_level"] = info.encoding.zstd_level;
  out["predictor"] = predictorName(info.encoding.predictor);
  out["filter"] = downsampleFilterName(info.encoding.filter);
  out["linear_light"] = info.encoding.linear_light;
  out["georeference"] = cli::georeferenceJson(info.geo);
  out["layer"] = cli::layerName(info.elevation);
  if (info.elevation.present) out["elevation"] = cli::elevationJson(info.elevation);
  if (info.shard.present) out["shard"] = cli::shardJson(info.shard);
  if (stats != nullptr) {
    nlohmann::json levels = nlohmann::json::array();
    for (uint32_t l = 0; l < stats->size(); ++l) {
      const LevelStats& s = (*stats)[l];
      levels.push_back({{"level", l},
                        {"width_px", g.levels[l].width_px},
                        {"height_px", g.levels[l].height_px},
                        {"tiles_x", g.levels[l].tiles_x},
                        {"tiles_y", g.levels[l].tiles_y},
                        {"tiles", s.tiles},
                        {"constant_tiles", s.constant_tiles},
                        {"stored_bytes", s.stored_bytes},
                        {"raw_bytes", s.raw_bytes},
                        {"ratio", ratio(s.raw_bytes, s.stored_bytes)}});
    }
    out["level_stats"] = levels;
  }
  return out;
}

// --tiles: one line (or JSON object) per tile in level, row, column order,
// with what the index records of it: a constant's value, or the stored
// payload's size and checksum; in an elevation store its height bounds and
// geometric error. Two stores holding the same tiles list the same, however
// their files lay the payloads out. Reads only index pages.
Status listTiles(const TileStoreReader& reader, bool json, nlohmann::json* out) {
  const StoreInfo& info = reader.info();
  const bool heights = info.elevation.present;
  const uint32_t pixel_bytes = bytesPerPixel(info.geometry.format);
  nlohmann::json tiles = nlohmann::json::array();
  for (uint32_t l = 0; l < info.geometry.levelCount(); ++l) {
    const LevelInfo& level = info.geometry.levels[l];
    for (uint32_t y = 0; y < level.tiles_y; ++y)
      for (uint32_t x = 0; x < level.tiles_x; ++x) {
        TileLocation loc;
        if (Status st = reader.locate({l, x, y}, &loc); !st) return st;
        std::string value;
        for (uint32_t i = 0; loc.constant && i < pixel_bytes && i < sizeof loc.constant_pixel; ++i) {
          char hex[3];
          std::snprintf(hex, sizeof hex, "%02x", loc.constant_pixel[i]);
          value += hex;
        }
        if (json) {
          nlohmann::json t = {{"level", l}, {"x", x}, {"y", y}};
          if (loc.constant) t["constant"] = value;
          else t["stored_bytes"] = loc.stored_bytes, t["checksum"] = loc.checksum;
          if (heights) t["min_height"] = loc.min_height, t["max_height"] = loc.max_height, t["error"] = loc.error;
          tiles.push_back(std::move(t));
          continue;
        }
        if (loc.constant) std::printf("tile %u %u %u constant %s", l, x, y, value.c_str());
        else std::printf("tile %u %u %u stored %u checksum %08x", l, x, y, loc.stored_bytes, loc.checksum);
        if (heights) std::printf(" heights %.9g %.9g error %.9g", loc.min_height, loc.max_height, loc.error);
        std::printf("\n");
      }
  }
  if (json) (*out)["tiles"] = std::move(tiles);
  return okStatus();
}

// --verify: reads, checks and decodes every tile on `threads` threads with a
// progress bar, then reports it as text or into *json_out. False when a
// tile failed.
bool verifyStore(const TileStoreReader& reader, bool json, unsigned threads, nlohmann::json* json_out) {
  std::fflush(stdout);  // the table before the progress line on a terminal
  constexpr size_t kMaxProblems = 1000;
  uint64_t total_tiles = 0;
  for (const LevelInfo& level : reader.geometry().levels) {
    total_tiles += uint64_t(level.tiles_x) * level.tiles_y;
  }
  cli::ProgressBar bar("verify", total_tiles, cli::progressEnabledByDefault(), "tiles");
  std::vector<TileStoreReader::Problem> problems;
  const Status verify_status = reader.verifyAll(
      &problems, kMaxProblems, [&](uint64_t done, uint64_t) { bar.update(done); }, threads);
  bar.finish();
  std::vector<std::string> lines;
  for (const auto& problem : problems) lines.push_back(problemLine(problem));
  if (json) {
    (*json_out)["verify"] = {{"ok", verify_status.ok()},
                             {"tiles", total_tiles},
                             {"message", verify_status.ok() ? "" : verify_status.message},
                             {"problems", lines}};
  } else {
    if (verify_status) {
      std::printf("\nverify: OK (%" PRIu64 " tiles)\n", total_tiles);
    } else {
      std::printf("\nverify: FAILED: %s\n", verify_status.message.c_str());
      for (const std::string& line : lines) std::printf("%s\n", line.c_str());
      if (problems.size() >= kMaxProblems) {
        std::printf("(only the first %zu problems are listed)\n", kMaxProblems);
      }
    }
  }
  return verify_status.ok();
}

}  // namespace

// A Cloud-Optimized GeoTIFF, as the programs stream it (CogReader): its
// size, internal tiles, compression, which pyramid levels it stores and
// which are built, its georeference; with --verify, every pyramid tile read
// and decoded. Returns the exit code.
int describeCog(const CogReader& cog, const std::string& path, bool json, bool verify) {
  const StoreInfo& info = cog.info();
  const PyramidGeometry& g = info.geometry;
  const CogLayout& layout = cog.layout();
  uint64_t failed = 0, tiles = 0;
  std::vector<std::string> problems;
  if (verify) {
    std::vector<uint8_t> pixels(g.tileBytes());
    for (uint32_t l = 0; l < g.levelCount(); ++l)
      for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
        for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
          uint64_t bytes = 0;
          ++tiles;
          if (Status s = cog.readTile({l, x, y}, pixels, &bytes); !s) {
            if (++failed <= 100) problems.push_back(errorCodeName(s.code) + std::string(": ") + s.message);
          }
        }
  }
  if (json) {
    nlohmann::json out;
    out["path"] = path;
    out["kind"] = "cog";
    out["file_bytes"] = info.file_bytes;
    out["width_px"] = g.width_px;
    out["height_px"] = g.height_px;
    out["pixel_format"] = pixelFormatName(g.format);
    out["tile_px"] = g.tile_px;
    out["internal_tile_px"] = layout.internal_tile_px;
    out["compression"] = layout.compression;
    nlohmann::json levels = nlohmann::json::array();
    for (uint32_t l = 0; l < g.levelCount(); ++l)
      levels.push_back({{"level", l}, {"width_px", g.levels[l].width_px}, {"height_px", g.levels[l].height_px},
                        {"tiles", uint64_t(g.levels[l].tiles_x) * g.levels[l].tiles_y},
                        {"stored", bool(layout.stored_levels[l])}});
    out["levels"] = levels;
    out["georeference"] = cli::georeferenceJson(info.geo);
    if (verify) out["verify"] = {{"tiles", tiles}, {"failed", failed}, {"problems", problems}};
    std::printf("%s\n", out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
  } else {
    std::printf("COG          %s\n", path.c_str());
    std::printf("file size    %" PRIu64 " bytes (%s)\n", info.file_bytes, humanBytes(info.file_bytes).c_str());
    std::printf("image        %" PRIu64 " x %" PRIu64 " px, %s\n", g.width_px, g.height_px, pixelFormatName(g.format));
    std::printf("tiles        %u px inside the file, streamed as %u px\n", layout.internal_tile_px, g.tile_px);
    std::printf("compression  %s\n", layout.compression.c_str());
    printGeoReference(info.geo);
    std::printf("\nlevel\twidth_px\theight_px\ttiles\tin_file\n");
    for (uint32_t l = 0; l < g.levelCount(); ++l)
      std::printf("%u\t%" PRIu64 "\t%" PRIu64 "\t%" PRIu64 "\t%s\n", l, g.levels[l].width_px, g.levels[l].height_px,
                  uint64_t(g.levels[l].tiles_x) * g.levels[l].tiles_y,
                  layout.stored_levels[l] ? "yes" : "no: built from the level below");
    if (verify) {
      std::printf("\nverify       %" PRIu64 " of %" PRIu64 " tiles read and decoded\n", tiles - failed, tiles);
      for (const std::string& p : problems) std::printf("  %s\n", p.c_str());
    }
  }
  return failed > 0 ? kExitCorrupt : kExitOk;
}

int main(int argc, char** argv) {
  CLI::App app{"Describe a clipstream tile store and optionally verify every tile.",
               "clipstream-info"};
  std::string path;
  bool verify = false;
  bool json = false;
  unsigned threads = 0;
  app.add_option("STORE", path, "tile store file or http(s):// URL")->required();
  app.add_flag("--verify", verify, "read, check and decode every tile");
  app.add_flag("--json", json, "print JSON on stdout instead of text");
  bool tiles = false;
  app.add_flag("--tiles", tiles,
               "list every tile: a constant's value, or its stored size and checksum (and an elevation "
               "store's height bounds), from the index only");
  app.add_option("--threads", threads, "verification threads (0 = all cores)")
      ->transform(cli::wholeInRange(0, 1024));
  RemoteOptions remote;
  cli::addRemoteOptions(app, &remote);
  app.footer(
      "Exit codes:\n"
      "  0  success (and, with --verify, every tile verified)\n"
      "  1  the store could not be opened (missing, not a regular file, unreadable, bad header),\n"
      "     or standard output could not be written\n"
      "  2  command-line mistake\n"
      "  3  corruption found (an index page or a tile failed its checks)\n"
      "Progress is drawn on stderr when it is a terminal; CLIPSTREAM_PROGRESS=0/1 overrides.");
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;
  cli::installSignalHandlers();

  std::unique_ptr<TileStoreReader> reader;
  Status status = TileStoreReader::open(path, remote, &reader);
  if (!status && status.code == ErrorCode::kBadMagic) {
    // Not a store: a Cloud-Optimized GeoTIFF is described as streamed.
    std::unique_ptr<CogReader> cog;
    const Status opened = CogReader::open(path, remote, &cog);
    if (opened.code != ErrorCode::kBadMagic) {
      if (!opened) {
        cli::printError(app, "cannot open COG: " + opened.toString());
        return kExitOpenFailed;
      }
      if (tiles) return cli::usageError(app, "--tiles lists a store's index; a COG has none");
      const int code = describeCog(*cog, displayStorePath(path), json, verify);
      const int finished = cli::finish(app, code);
      return finished == cli::kExitFailure && code == kExitCorrupt ? kExitCorrupt : finished;
    }
  }
  if (!status) {
    cli::printError(app, "cannot open store: " + status.toString());
    return kExitOpenFailed;
  }
  int exit_code = kExitOk;
  std::vector<LevelStats> stats;
  const Status stats_status = reader->levelStats(&stats);
  if (!stats_status) {
    cli::printError(app, "index: " + stats_status.toString());
    exit_code = kExitCorrupt;
  }
  const std::vector<LevelStats>* stats_ptr = stats_status ? &stats : nullptr;

  nlohmann::json json_out;
  if (json) {
    json_out = toJson(path, reader->info(), stats_ptr);
  } else {
    printText(path, reader->info(), stats_ptr);
  }

  if (tiles && exit_code == kExitOk) {
    if (!json) std::printf("\n");
    if (Status st = listTiles(*reader, json, &json_out); !st) {
      cli::printError(app, "index: " + st.toString());
      exit_code = kExitCorrupt;
    }
  }

  if (verify && !verifyStore(*reader, json, threads, &json_out)) exit_code = kExitCorrupt;
  if (reader->remoteStats().disk_cache_folders_refused > 0)
    std::fprintf(stderr,
                 "clipstream-info: warning: the disk cache did not cache this store: its sub-folder there is a "
                 "symlink or another user's, which the cache never follows nor writes; remove it, or give "
                 "--disk-cache a folder of your own\n");
  // The CRS text comes from the file and need not be valid UTF-8: replace
  // bad sequences instead of letting dump() throw.
  if (json) {
    std::printf("%s\n",
                json_out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
  }
  // A failed write of the report (a full disk, /dev/full) is a failure.
  const int code = cli::finish(app, exit_code);
  return code == cli::kExitFailure && exit_code == kExitCorrupt ? kExitCorrupt : code;
}
