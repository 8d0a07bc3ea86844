// clipstream-tile: builds a tile store from an image. Thin: argument
// parsing, signal handling and the summary; the work is in the tiler library (tiler.h).
#include <clipstream/cli/cli.h>
#include <clipstream/cli/progress.h>
#include <clipstream/cli/store_json.h>
#include <clipstream/util/output_file.h>
#include <clipstream/tiler/shard.h>
#include <clipstream/tiler/tiler.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>

namespace {

std::atomic<int> g_cancel{0};

// Parses "WIDTHxHEIGHT" (decimal digits, 'x' or 'X'). Returns "" or what is wrong.
std::string parseSize(const std::string& text, uint64_t* width, uint64_t* height) {
  const size_t sep = text.find_first_of("xX");
  bool too_large = false;
  auto number = [&](const std::string& digits, uint64_t* out) {
    if (digits.empty()) return false;
    uint64_t v = 0;
    for (char c : digits) {
      if (c < '0' || c > '9') return false;
      if (v > clipstream::kMaxSyntheticSidePx) too_large = true;
      else v = v * 10 + uint64_t(c - '0');
    }
    *out = v;
    if (v > clipstream::kMaxSyntheticSidePx) too_large = true;
    return true;
  };
  if (sep == std::string::npos || !number(text.substr(0, sep), width) ||
      !number(text.substr(sep + 1), height)) {
    return "is not WIDTHxHEIGHT (e.g. 8192x4096)";
  }
  if (too_large) {
    return "is too large: at most " + std::to_string(clipstream::kMaxSyntheticSidePx) +
           " px on a side";
  }
  return {};
}

// Parses "K/N" (decimal digits) for --shard. Returns "" or what is wrong.
std::string parseShard(const std::string& text, uint32_t* index, uint32_t* count) {
  const size_t sep = text.find('/');
  auto number = [](const std::string& digits, uint32_t* out) {
    if (digits.empty() || digits.size() > 9) return false;
    uint64_t v = 0;
    for (char c : digits) {
      if (c < '0' || c > '9') return false;
      v = v * 10 + uint64_t(c - '0');
    }
    *out = uint32_t(v);
    return true;
  };
  if (sep == std::string::npos || !number(text.substr(0, sep), index) ||
      !number(text.substr(sep + 1), count)) {
    return "is not K/N (e.g. 2/4: the second of four shards)";
  }
  if (*count == 0 || *count > clipstream::kMaxShards || *index == 0 || *index > *count) {
    return "needs 1 <= K <= N <= " + std::to_string(clipstream::kMaxShards);
  }
  return {};
}

std::string megabytes(uint64_t bytes) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.1f MB", double(bytes) / (1024.0 * 1024.0));
  return text;
}

nlohmann::json toJson(const clipstream::TilerSummary& s, const std::string& input,
                      const std::string& output) {
  nlohmann::json j;
  j["input"] = input;
  j["output"] = output;
  j["width_px"] = s.width_px;
  j["height_px"] = s.height_px;
  j["pixel_format"] = clipstream::pixelFormatName(s.format);
  j["input_type"] = s.input_type;
  j["decoder"] = s.decoder;
  j["reprojection"] = s.reprojection.empty() ? nlohmann::json() : nlohmann::json(s.reprojection);
  j["transparent_nodata"] = s.transparent_nodata ? nlohmann::json(*s.transparent_nodata) : nlohmann::json();
  j["input_channels"] = s.input_channels;
  j["levels"] = s.levels;
  j["tiles"] = s.tiles;
  j["constant_tiles"] = s.constant_tiles;
  j["input_bytes"] = s.input_bytes;
  j["raw_bytes"] = s.raw_bytes;
  j["output_bytes"] = s.output_bytes;
  j["clamped_samples"] = s.clamped_samples;
  j["panel_px"] = s.panel_px;
  j["panels"] = s.panels;
  j["memory_budget_bytes"] = s.memory_budget_bytes;
  j["peak_rss_bytes"] = s.peak_rss_bytes;
  j["wall_s"] = s.wall_s;
  j["read_s"] = s.read_s;
  j["build_s"] = s.build_s;
  j["encode_s"] = s.encode_s;
  j["megapixels_per_s"] = s.wall_s > 0 ? double(s.width_px * s.height_px) / 1e6 / s.wall_s : 0.0;
  j["georeference"] = clipstream::cli::georeferenceJson(s.geo);
  j["layer"] = clipstream::cli::layerName(s.elevation);
  j["relief_scale"] = s.relief_scale > 0 ? nlohmann::json(s.relief_scale) : nlohmann::json();
  if (s.elevation.present) j["elevation"] = clipstream::cli::elevationJson(s.elevation);
  if (s.mosaic_sheets > 0) {
    j["mosaic_sheets"] = s.mosaic_sheets;
    j["gap_px"] = s.gap_px;
  }
  if (s.shard.present) j["shard"] = clipstream::cli::shardJson(s.shard);
  j["warnings"] = s.warnings;
  return j;
}

// The command line as given, before it is checked: each option's variable,
// holding its default until parse().
struct Args {
  std::vector<std::string> positional;
  std::string synthetic, format_text, filter_text, json_path, layer_text = "auto", nodata_text, units_text;
  double height_step = 0.0;
  uint32_t tile_px = 128;
  int zstd_level = 1;
  unsigned threads = 0;
  uint64_t memory_mb = 256;
  bool no_predictor = false, linear_light = false, quiet = false, force = false, no_fsync = false;
  std::string mosaic_list;
  uint32_t fill = 0;
  bool relief = false;
  uint32_t relief_scale = 4;
  CLI::Option* relief_scale_option = nullptr;
  std::string reader_text = "auto";
  std::string t_srs, resampling = "bilinear";
  double t_res = 0.0;
  std::string shard_text;
  std::string order_text;
};

// Declares every option and the footer, in the order --help lists them,
// each bound to its variable in *args (which must outlive the parse).
void addOptions(CLI::App& app, Args* args) {
  using namespace clipstream;
  Args& a = *args;
  app.add_option("INPUT OUTPUT", a.positional,
                 "input image and output store (only OUTPUT with --synthetic or --mosaic)")
      ->required()
      ->expected(1, 2);
  app.add_option("--synthetic", a.synthetic, "procedural input of WxH pixels instead of a file");
  app.add_option("--mosaic", a.mosaic_list,
                 "input: a list file of georeferenced sheets (one path a line) or a VRT of simple "
                 "sources, tiled as one image; "
                 "later sheets win where they overlap");
  app.add_option("--fill", a.fill,
                 "mosaic: value of every channel but alpha (alpha 0) where no sheet covers "
                 "(0..255, 0..65535 for R16)")
      ->transform(cli::wholeInRange(0, 65535));
  app.add_option("--format", a.format_text,
                 "force the store format: R8, R16, RGB8, RGBA8 (colour), I16, R16, F32 (heights)");
  app.add_option("--layer", a.layer_text,
                 "colour, elevation, or auto (default: elevation for a single-band int16 input, or "
                 "uint16/float with a georeference)");
  app.add_option("--height-step", a.height_step,
                 "elevation: store float heights as R16 steps of this size (error <= step/2); "
                 "default: exactly (F32)")
      ->transform(cli::inRange(0.0, kMaxHeightStep));
  app.add_flag("--relief", a.relief,
               "draw the input DEM as a shaded colour relief (RGB8: height tint and hillshade lit "
               "from the north-west) instead of storing its heights");
  a.relief_scale_option =
      app.add_option("--relief-scale", a.relief_scale, "with --relief: pixels per DEM sample along each axis (1..64)")
          ->capture_default_str()
          ->transform(cli::wholeInRange(1, kMaxReliefScale));
  app.add_option("--nodata", a.nodata_text,
                 "the no-data value (overrides the file's): elevation: filled ('nan' for float DEMs); "
                 "an 8-bit grey or RGB image: transparent");
  app.add_option("--vertical-units", a.units_text, "elevation: metre, foot or us-foot (overrides the file's)");
  app.add_option("--tile-size", a.tile_px, "tile edge in pixels (power of two, 16..4096)")
      ->transform(cli::wholeInRange(kMinTilePx, kMaxTilePx));
  app.add_option("--zstd-level", a.zstd_level, "zstd compression level (1..22)")
      ->transform(cli::wholeInRange(1, 22));
  app.add_flag("--no-predictor", a.no_predictor, "store tiles without the left-delta predictor");
  app.add_option("--filter", a.filter_text, "downsampling filter: box (default) or lanczos3");
  app.add_flag("--linear-light", a.linear_light, "with lanczos3: filter in linear light (sRGB input)");
  app.add_option("--reader", a.reader_text,
                 "auto (default: the tiler's own readers for the TIFF, JPEG and PNG files they "
                 "cover; GDAL for URLs, VRTs and JPEG 2000; OpenImageIO for the other image "
                 "formats; GDAL for what OpenImageIO cannot read), openimageio or gdal (every file)");
  app.add_option("--t-srs", a.t_srs,
                 "reproject the input to this CRS with GDAL's warper (EPSG:n, WKT, a PROJ string, "
                 "a raster file's CRS; auto: the UTM zone of a geographic input's centre)");
  app.add_option("--resampling", a.resampling,
                 "with --t-srs: near, bilinear (default), cubic, cubicspline, lanczos, average or mode");
  app.add_option("--t-res", a.t_res,
                 "with --t-srs: pixel size in the target CRS's units (default: GDAL's choice, as gdalwarp)")
      ->transform(cli::inRange(0.0, 1e12));
  app.add_option("--threads", a.threads, "encoder threads, and TIFF decode threads (default: all cores)")
      ->transform(cli::wholeInRange(0, kMaxThreads));
  app.add_option("--memory-mb", a.memory_mb, "bound on peak memory in MiB")
      ->transform(cli::wholeInRange(int64_t(kMinMemoryBudgetBytes >> 20), int64_t(1) << 30));
  app.add_flag("--quiet,-q", a.quiet, "no progress bar and no summary");
  app.add_flag("--force,-f", a.force, "overwrite an existing OUTPUT (a regular file, never the input)");
  app.add_option("--json-summary", a.json_path, "also write the summary as JSON to this file ('-' = stdout)");
  app.add_flag("--no-fsync", a.no_fsync, "skip the final fsync (faster, for scratch outputs)");
  app.add_option("--shard", a.shard_text,
                 "K/N: tile only the K-th of N bands into a partial store for clipstream-merge");
  app.add_option("--payload-order", a.order_text,
                 "where tiles lie in each level: curve (index pages along a Hilbert curve, tiles "
                 "of a page in Morton order: fewer range requests over HTTP) or written (row by "
                 "row); default " + std::string(payloadOrderName(TilerOptions{}.payload_order)));
  app.footer(
      "Exit codes: 0 success, 1 failure (nothing left behind), 2 command-line mistake,\n"
      "128+N stopped by signal N (INT, TERM, HUP; temporaries removed). docs/cli.md.");
}

// The input and output: a mosaic list, a synthetic size or an input file,
// with the name the summary gives the input. Returns "" or the mistake.
std::string toInput(const CLI::App& app, const Args& a, clipstream::TilerOptions* options,
                    std::string* input_name) {
  if (app.count("--fill") > 0 && a.mosaic_list.empty()) return "--fill applies to --mosaic";
  if (!a.synthetic.empty() && !a.mosaic_list.empty()) return "give --synthetic or --mosaic, not both";
  if (!a.mosaic_list.empty()) {
    if (a.positional.size() != 1) return "with --mosaic give only OUTPUT";
    if (a.positional[0].empty()) return "OUTPUT must not be empty";
    options->input_path = a.mosaic_list;
    options->mosaic = true;
    options->fill = a.fill;
    options->output_path = a.positional[0];
    *input_name = "mosaic " + a.mosaic_list;
  } else if (!a.synthetic.empty()) {
    if (a.positional.size() != 1) return "with --synthetic give only OUTPUT";
    if (a.positional[0].empty()) return "OUTPUT must not be empty";
    const std::string problem =
        parseSize(a.synthetic, &options->synthetic_width_px, &options->synthetic_height_px);
    if (!problem.empty()) return "--synthetic '" + a.synthetic + "' " + problem;
    options->output_path = a.positional[0];
    *input_name = "synthetic " + a.synthetic;
  } else {
    if (a.positional.size() != 2) return "need INPUT and OUTPUT (or --synthetic WxH OUTPUT)";
    if (a.positional[0].empty() || a.positional[1].empty()) return "INPUT and OUTPUT must not be empty";
    options->input_path = a.positional[0];
    options->output_path = a.positional[1];
    *input_name = a.positional[0];
  }
  return {};
}

// The layer and what goes with it: the store format, colour or elevation,
// the relief, and the elevation's no-data value and units. Returns "" or
// the mistake.
std::string toLayer(const Args& a, clipstream::TilerOptions* options) {
  using namespace clipstream;
  if (!a.format_text.empty()) {
    options->format = cli::parsePixelFormat(a.format_text);
    if (!options->format) {
      return "--format '" + a.format_text + "' is not R8, R16, RGB8, RGBA8, I16 or F32";
    }
  }
  if (a.layer_text == "auto") {
    options->layer = LayerKind::kAuto;
  } else if (a.layer_text == "colour" || a.layer_text == "color") {
    options->layer = LayerKind::kColour;
  } else if (a.layer_text == "elevation") {
    options->layer = LayerKind::kElevation;
  } else {
    return "--layer '" + a.layer_text + "' is not auto, colour or elevation";
  }
  if (!a.filter_text.empty() && options->layer == LayerKind::kElevation) {
    return "--filter is for colour: heights are decimated, never filtered";
  }
  options->height_step = a.height_step;
  if (a.relief_scale_option->count() > 0 && !a.relief) return "--relief-scale goes with --relief";
  options->relief_scale = a.relief ? a.relief_scale : 0;
  if (!a.nodata_text.empty()) {
    char* end = nullptr;
    const double v = std::strtod(a.nodata_text.c_str(), &end);
    if (end == a.nodata_text.c_str() || *end != '\0' || std::isinf(v)) {
      return "--nodata '" + a.nodata_text + "' is not a finite number or nan";
    }
    options->nodata = v;
  }
  if (!a.units_text.empty()) {
    if (a.units_text == "metre" || a.units_text == "meter" || a.units_text == "m") {
      options->vertical_units = HeightUnits::kMetre;
    } else if (a.units_text == "foot" || a.units_text == "ft") {
      options->vertical_units = HeightUnits::kFoot;
    } else if (a.units_text == "us-foot" || a.units_text == "ftUS") {
      options->vertical_units = HeightUnits::kUsSurveyFoot;
    } else {
      return "--vertical-units '" + a.units_text + "' is not metre, foot or us-foot";
    }
  }
  return {};
}

// The encoding and the run: filter, tile size, zstd, predictor, reader,
// threads, memory, output rules, payload order and shard. Returns "" or
// the mistake.
std::string toEncoding(const Args& a, clipstream::TilerOptions* options) {
  using namespace clipstream;
  if (a.filter_text.empty() || a.filter_text == "box") {
    options->filter = DownsampleFilter::kBox;
  } else if (a.filter_text == "lanczos3") {
    options->filter = DownsampleFilter::kLanczos3;
  } else {
    return "--filter '" + a.filter_text + "' is not box or lanczos3";
  }
  options->tile_px = a.tile_px;
  options->zstd_level = a.zstd_level;
  options->predictor = !a.no_predictor;
  options->linear_light = a.linear_light;
  options->threads = a.threads;
  if (a.reader_text == "auto") {
    options->reader = ImageReader::kAuto;
  } else if (a.reader_text == "openimageio") {
    options->reader = ImageReader::kOpenImageIO;
  } else if (a.reader_text == "gdal") {
    options->reader = ImageReader::kGdal;
  } else {
    return "--reader '" + a.reader_text + "' is not auto, openimageio or gdal";
  }
  options->target_crs = a.t_srs;
  options->resampling = a.resampling;
  options->target_resolution = a.t_res;
  options->memory_budget_bytes = a.memory_mb << 20;
  options->overwrite = a.force;
  options->fsync = !a.no_fsync;
  if (!a.order_text.empty()) {
    const std::optional<PayloadOrder> order = cli::parsePayloadOrder(a.order_text);
    if (!order) return "--payload-order must be curve or written";
    options->payload_order = *order;
  }
  if (!a.shard_text.empty()) {
    const std::string problem = parseShard(a.shard_text, &options->shard_index, &options->shard_count);
    if (!problem.empty()) return "--shard '" + a.shard_text + "' " + problem;
  }
  return {};
}

// The parsed command line as the tiler's options, checked as the tiler
// checks them (validateOptions), in the order the mistakes are reported.
// Returns "" or the mistake; progress and cancel are left to the caller.
std::string toOptions(const CLI::App& app, const Args& a, clipstream::TilerOptions* options,
                      std::string* input_name) {
  std::string problem = toInput(app, a, options, input_name);
  if (problem.empty()) problem = toLayer(a, options);
  if (problem.empty()) problem = toEncoding(a, options);
  if (problem.empty()) {
    if (clipstream::Status s = clipstream::validateOptions(*options); !s) problem = s.message;
  }
  return problem;
}

// Checks the --json-summary file now, not after the work: it follows the
// output rule too (a regular file named by the user may be replaced) and
// must be neither the input nor the output. Returns nullopt to go on, or
// the exit code.
std::optional<int> checkJsonSummaryPath(const CLI::App& app, const std::string& json_path,
                                        const clipstream::TilerOptions& options,
                                        const clipstream::OutputOptions& json_options) {
  using namespace clipstream;
  if (json_path.empty() || json_path == "-") return std::nullopt;
  // The same file now (links included) or the same path once the store exists.
  const auto canonical = [](const std::string& p) {
    std::error_code ec;
    return std::filesystem::weakly_canonical(p, ec).string();
  };
  if (sameFile(json_path, options.output_path) || canonical(json_path) == canonical(options.output_path) ||
      (!options.input_path.empty() && sameFile(json_path, options.input_path))) {
    return cli::usageError(app, "--json-summary " + json_path + " is the input or the output");
  }
  if (Status s = checkOutputPath(json_path, json_options); !s) {
    cli::printError(app, "--json-summary: " + s.toString());
    return cli::kExitFailure;
  }
  return std::nullopt;
}

// The summary on stdout: one line for the run, then one for each of the
// georeference, relief, mosaic, shard, elevation and clamping that apply.
void printSummary(const clipstream::TilerSummary& summary, const clipstream::TilerOptions& options,
                  const std::string& input_name) {
  using namespace clipstream;
  const double mp = double(summary.width_px * summary.height_px) / 1e6;
  std::printf(
      "%s: %llux%llu %s -> %s: %u levels, %llu tiles (%llu constant), %.1f MP/s, input %s, "
      "output %s, ratio %.2f:1 (raw/output), peak RSS %s, wall %.2f s\n",
      printableText(input_name, 300).c_str(), (unsigned long long)summary.width_px,
      (unsigned long long)summary.height_px, pixelFormatName(summary.format),
      printableText(options.output_path, 300).c_str(), summary.levels, (unsigned long long)summary.tiles,
      (unsigned long long)summary.constant_tiles, summary.wall_s > 0 ? mp / summary.wall_s : 0.0,
      megabytes(summary.input_bytes).c_str(), megabytes(summary.output_bytes).c_str(),
      summary.output_bytes ? double(summary.raw_bytes) / double(summary.output_bytes) : 0.0,
      megabytes(summary.peak_rss_bytes).c_str(), summary.wall_s);
  if (summary.transparent_nodata) {
    std::printf("no-data: pixels whose every channel is %g are transparent (alpha 0, RGBA8)\n",
                *summary.transparent_nodata);
  }
  if (!summary.reprojection.empty()) {
    std::printf("reprojected: %s\n", printableText(summary.reprojection, 600).c_str());
  }
  if (summary.geo.present) {
    const double* t = summary.geo.transform;
    std::printf("georeference: origin (%.6f, %.6f), pixel (%.6g, %.6g), rotation (%.6g, %.6g), CRS %s\n",
                t[0], t[3], t[1], t[5], t[2], t[4],
                summary.geo.crs.empty() ? "(unknown)" : printableText(summary.geo.crs, 300).c_str());
  }
  if (options.relief_scale > 0) {
    std::printf("relief: shaded from the DEM's heights, %u px per sample\n", options.relief_scale);
  }
  if (summary.mosaic_sheets > 0) {
    std::printf("mosaic: %llu sheets, %llu px covered by none (filled with %u, alpha 0)\n",
                (unsigned long long)summary.mosaic_sheets, (unsigned long long)summary.gap_px,
                options.fill);
  }
  if (summary.shard.present) {
    const ShardInfo& sh = summary.shard;
    std::printf("shard %u/%u: rows %llu..%llu of %llux%llu, levels 0..%u (clipstream-merge "
                "joins the parts)\n",
                sh.index, sh.count, (unsigned long long)sh.y0_px,
                (unsigned long long)(sh.y0_px + summary.height_px),
                (unsigned long long)sh.full_width_px, (unsigned long long)sh.full_height_px,
                sh.owned_levels - 1);
  }
  if (summary.elevation.present) {
    const ElevationInfo& e = summary.elevation;
    std::printf("elevation: heights %.2f to %.2f %s%s, %s, %llu no-data samples filled",
                e.min_height, e.max_height, heightUnitsName(e.units),
                e.units_assumed ? " (assumed: the file does not say)" : "",
                e.quantised ? "quantised" : "stored exactly",
                (unsigned long long)e.filled_samples);
    if (e.quantised) std::printf(" (step %.4g: error <= %.4g, largest %.4g)", e.scale, e.scale / 2, e.max_error);
    std::printf("\n");
  }
  if (summary.clamped_samples > 0) {
    std::printf("note: %llu input samples were outside the output range and clamped\n",
                (unsigned long long)summary.clamped_samples);
  }
}

}  // namespace

// The program in its steps: declare and parse the options, turn them into
// the tiler's options, check the summary file's path, tile with signals
// caught, then report (warnings, summary, JSON).
int main(int argc, char** argv) {
  using namespace clipstream;
  CLI::App app{"Builds a clipstream tile store (full mip pyramid) from an image, out of core.",
               "clipstream-tile"};
  Args args;
  addOptions(app, &args);
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;

  TilerOptions options;
  std::string input_name;
  // The bar is made at the first report, when the image size is known, and
  // ended below whatever the outcome so a message starts on a fresh line.
  std::unique_ptr<cli::ProgressBar> bar;
  if (!args.quiet && cli::progressEnabledByDefault()) {
    options.progress = [&bar](uint64_t done_px, uint64_t total_px) {
      if (!bar) bar = std::make_unique<cli::ProgressBar>("tiling", total_px, true, "px");
      bar->update(done_px);
    };
  }
  options.cancel = &g_cancel;
  if (std::string problem = toOptions(app, args, &options, &input_name); !problem.empty()) {
    return cli::usageError(app, problem);
  }
  OutputOptions json_options;
  json_options.existing = ExistingOutput::kReplaceRegular;
  json_options.fsync = options.fsync;
  if (std::optional<int> code = checkJsonSummaryPath(app, args.json_path, options, json_options)) {
    return *code;
  }

  cli::installSignalHandlers(&g_cancel);

  TilerSummary summary;
  const Status status = tileImage(options, &summary);
  if (bar) bar->finish();
  if (!status) {
    if (status.code == ErrorCode::kCancelled) {
      std::cerr << "clipstream-tile: stopped by signal " << g_cancel.load() << "; nothing was written\n";
      return cli::kExitSignalBase + g_cancel.load();
    }
    cli::printError(app, status.toString());
    return cli::kExitFailure;
  }

  for (const std::string& w : summary.warnings) cli::printError(app, "warning: " + w);
  if (!args.quiet) printSummary(summary, options, input_name);
  if (!args.json_path.empty()) {
    const std::string text = toJson(summary, input_name, options.output_path).dump(2) + "\n";
    if (args.json_path == "-") {
      std::fputs(text.c_str(), stdout);
    } else if (Status s = writeOutputFile(args.json_path, text, json_options); !s) {
      cli::printError(app, "--json-summary: " + s.toString() + " (the store " + options.output_path +
                               " was written)");
      return cli::kExitFailure;
    }
  }
  return cli::finish(app, cli::kExitOk);
}
