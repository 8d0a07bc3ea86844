// Elevation stores from a tiler input: the choice, the checks of the height
// options against the samples, and the input reopened for its native
// heights (elevation_input.h).
#include "elevation_input.h"

#include <clipstream/tiler/georef.h>

#include <cmath>
#include <cstdio>

namespace clipstream {
namespace {

// How a DEM's samples are read and stored.
struct HeightPlan {
  PixelFormat native = PixelFormat::kF32;  // the samples as the file holds them
  PixelFormat stored = PixelFormat::kF32;  // the store's format
};

// The checks of the options against a single-band DEM whose samples are of
// `first`'s type, and the formats that follow from them.
Status planHeights(const TilerOptions& o, const SourceInfo& first, HeightPlan* out) {
  const std::string& type = first.input_type;
  const bool int16 = type == "int16", uint16 = type == "uint16";
  if (first.input_channels != 1) {
    return Status::error(ErrorCode::kUnsupported,
                         o.input_path + ": " + std::to_string(first.input_channels) +
                             " channels; an elevation store needs a single-band DEM");
  }
  // R16 is both a grey colour format and a height format: in an elevation
  // store it means quantised or unsigned 16-bit heights.
  const bool height_format = o.format && (*o.format == PixelFormat::kI16 || *o.format == PixelFormat::kR16 ||
                                          *o.format == PixelFormat::kF32);
  if (o.format && !height_format) {
    return Status::error(ErrorCode::kInvalidArgument,
                         std::string("--format ") + pixelFormatName(*o.format) +
                             " is a colour format; elevation stores hold I16, R16 or F32");
  }
  if (o.filter != DownsampleFilter::kBox || o.linear_light) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--filter and --linear-light are for colour: heights are decimated "
                         "(every other sample), never filtered like colour");
  }
  const PixelFormat native = int16 ? PixelFormat::kI16 : uint16 ? PixelFormat::kR16 : PixelFormat::kF32;
  const bool integer = int16 || uint16 || type == "uint8";
  if (integer && o.height_step > 0.0) {
    return Status::error(ErrorCode::kInvalidArgument,
                         o.input_path + ": integer heights (" + type +
                             ") are stored exactly; --height-step is for floating-point DEMs");
  }
  PixelFormat stored = o.height_step > 0.0 ? PixelFormat::kR16 : native;
  if (height_format) {
    const bool widen = *o.format == PixelFormat::kF32;
    if (*o.format != stored && !widen) {
      return Status::error(ErrorCode::kInvalidArgument,
                           std::string("--format ") + pixelFormatName(*o.format) + " cannot hold " +
                               type + " heights " +
                               (o.height_step > 0.0 ? "quantised (R16 does)"
                                : stored == PixelFormat::kF32
                                    ? "exactly (use F32)"
                                    : "exactly (use " + std::string(pixelFormatName(stored)) + " or F32)"));
    }
    stored = *o.format;
  }
  // A no-data value no sample of an integer DEM can hold (NaN included)
  // would turn no-data off without a word.
  if (integer && o.nodata) {
    const double lo = int16 ? -32768.0 : 0.0, hi = int16 ? 32767.0 : uint16 ? 65535.0 : 255.0;
    if (*o.nodata < lo || *o.nodata > hi || *o.nodata != std::floor(*o.nodata)) {
      char text[160];
      std::snprintf(text, sizeof text, "--nodata %.9g: no %s sample can hold it (whole numbers %.0f to %.0f)",
                    *o.nodata, type.c_str(), lo, hi);
      return Status::error(ErrorCode::kInvalidArgument, o.input_path + ": " + text);
    }
  }
  out->native = native;
  out->stored = stored;
  return okStatus();
}

// --height-step: the heights' range (one pass over `source`) gives the
// quantisation's offset; kInvalidArgument when 65536 steps do not span it.
Status quantise(const TilerOptions& o, ImageSource* source, HeightConversion* conversion) {
  double lo = 0.0, hi = 0.0;
  Status s = scanHeightRange(source, *conversion, &lo, &hi);
  if (!s) return Status::error(s.code, o.input_path + ": " + s.message);
  conversion->scale = o.height_step;
  conversion->offset = std::floor(lo / o.height_step) * o.height_step;
  if ((hi - conversion->offset) / o.height_step > 65535.0) {
    return Status::error(ErrorCode::kInvalidArgument,
                         o.input_path + ": heights " + std::to_string(lo) + " to " +
                             std::to_string(hi) + " need more than 65536 steps of " +
                             std::to_string(o.height_step) + "; use --height-step " +
                             std::to_string((hi - conversion->offset) / 65535.0) +
                             " or more, or store them exactly");
  }
  return okStatus();
}

// The store's description of its heights: the conversion, and the units
// from the options, else the file's tags, else metres (assumed).
ElevationInfo elevationInfo(const TilerOptions& o, const HeightConversion& conversion,
                            const ElevationTags& tags) {
  ElevationInfo elevation;
  elevation.present = true;
  elevation.scale = conversion.scale;
  elevation.quantised = o.height_step > 0.0;
  elevation.offset = conversion.offset;
  elevation.has_nodata = conversion.has_nodata;
  elevation.nodata = conversion.nodata;
  if (o.vertical_units) {
    elevation.units = *o.vertical_units;
    elevation.units_assumed = false;
  } else if (tags.units) {
    elevation.units = *tags.units;
    elevation.units_assumed = false;
  } else {
    elevation.units = HeightUnits::kMetre;
    elevation.units_assumed = true;
  }
  return elevation;
}

}  // namespace

bool wantsElevation(const TilerOptions& o, const SourceInfo& first, const GeoReference& geo) {
  const std::string& type = first.input_type;
  const bool int16 = type == "int16", uint16 = type == "uint16";
  const bool floating = type == "float" || type == "half" || type == "double";
  const bool forced_height = o.format && !isColourFormat(*o.format);
  switch (o.layer) {
    case LayerKind::kColour: return false;
    case LayerKind::kElevation: return true;
    case LayerKind::kAuto:
      return forced_height || (!o.format && first.input_channels == 1 &&
                               (int16 || ((uint16 || floating) && geo.present)));
  }
  return false;
}

Status inputTags(const SourceInfo& info, const std::string& tags_path, ElevationTags* out) {
  const SourceMetadata& meta = info.metadata;
  if (!meta.present) return readElevationTags(tags_path, out);
  *out = ElevationTags{};
  out->has_nodata = meta.has_nodata;
  out->nodata = meta.nodata;
  out->units = meta.units;
  return okStatus();
}

Status openElevation(const TilerOptions& o, const GeoReference& geo, const std::string& tags_path,
                     const ReopenHeights& reopen_input, std::unique_ptr<ImageSource>* source,
                     HeightSource** heights, ElevationInfo* elevation,
                     std::vector<std::string>* warnings) {
  if (!wantsElevation(o, (*source)->info(), geo)) {
    if (o.height_step > 0.0) {
      return Status::error(ErrorCode::kInvalidArgument,
                           o.input_path + ": --height-step applies to elevation stores, and this "
                                          "input is tiled as colour (use --layer elevation)");
    }
    return okStatus();
  }
  HeightPlan plan;
  Status s = planHeights(o, (*source)->info(), &plan);
  if (!s) return s;
  ElevationTags tags;
  s = inputTags((*source)->info(), tags_path, &tags);
  if (!s) return s;
  HeightConversion conversion;
  conversion.stored = plan.stored;
  conversion.has_nodata = o.nodata.has_value() || tags.has_nodata;
  conversion.nodata = o.nodata.value_or(tags.nodata);

  // The reader for native samples (the file is opened again: cheap, and
  // it starts from the top).
  const PixelFormat native_format = plan.stored == PixelFormat::kF32 || o.height_step > 0.0
                                        ? PixelFormat::kF32
                                        : plan.native;
  auto reopen = [&]() {
    source->reset();
    return reopen_input(native_format, conversion, source);
  };
  s = reopen();
  if (!s) return s;
  if (o.height_step > 0.0) {
    s = quantise(o, source->get(), &conversion);
    if (!s) return s;
    s = reopen();
    if (!s) return s;
  }
  auto wrapped = std::make_unique<HeightSource>(std::move(*source), conversion);
  *heights = wrapped.get();
  *source = std::move(wrapped);
  *elevation = elevationInfo(o, conversion, tags);
  if (!geo.present) {
    warnings->push_back(o.input_path +
                        ": the DEM has no georeference; a scene will stretch it over the "
                        "colour layer's extent");
  }
  return okStatus();
}

}  // namespace clipstream
