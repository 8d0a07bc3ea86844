// Opening the tiler's input (input.h): which reader, the elevation path,
// the relief.
#include "input.h"

#include <clipstream/util/output_file.h>
#include <clipstream/tiler/georef.h>

#include "elevation_input.h"
#include "nodata_alpha.h"
#include "relief_source.h"

#include <cmath>
#include <cstdio>
#include <optional>

namespace clipstream {
namespace {

// The mosaic of DEM sheets again, as native heights: gaps hold the no-data
// value (NaN for float samples when the sheets declare none), so they are
// filled like any void.
ReopenHeights reopenMosaic(const TilerOptions& o, uint64_t gap_px) {
  return [&o, gap_px](PixelFormat native, const HeightConversion& conversion,
                      std::unique_ptr<ImageSource>* out) {
    double gap = conversion.has_nodata ? conversion.nodata : std::nan("");
    if (!conversion.has_nodata && native != PixelFormat::kF32) {
      if (gap_px > 0) {
        return Status::error(ErrorCode::kInvalidArgument,
                             o.input_path + ": the sheets leave " + std::to_string(gap_px) +
                                 " px uncovered and declare no no-data value to fill them "
                                 "with; give --nodata");
      }
      gap = 0.0;  // never read: no gaps
    }
    MosaicInfo again;
    return openHeightMosaic(o.input_path, native, gap, out, &again, imageReadOptions(o));
  };
}

// The file again, delivering its native samples.
ReopenHeights reopenFile(const TilerOptions& o) {
  return [&o](PixelFormat native, const HeightConversion&, std::unique_ptr<ImageSource>* out) {
    return openImageFile(o.input_path, native, out, imageReadOptions(o));
  };
}

// Replaces the source of heights by the shaded relief drawn from them
// (relief_source.h): a colour store, georeferenced like the DEM with pixels
// relief_scale times smaller.
Status makeRelief(const TilerOptions& o, GeoReference* geo, std::unique_ptr<ImageSource>* source,
                  ElevationInfo* elevation) {
  const SourceInfo& dem = (*source)->info();
  ReliefOptions relief;
  relief.scale = o.relief_scale;
  relief.metres_per_height = metresPerUnit(elevation->units);
  if (geo->present) {
    const double* t = geo->transform;
    const double latitude = t[3] + t[5] * double(dem.height_px) * 0.5;
    const CrsUnitMetres unit = metresPerCrsUnit(geo->crs, latitude);
    relief.sample_x_metres = std::hypot(t[1], t[4]) * unit.x;
    relief.sample_y_metres = std::hypot(t[2], t[5]) * unit.y;
    // A CRS unit not known here is taken as a metre (unit.assumed).
    for (int i : {1, 2, 4, 5}) geo->transform[i] /= double(o.relief_scale);
  }
  if (!(relief.sample_x_metres > 0.0) || !(relief.sample_y_metres > 0.0)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         o.input_path + ": the georeference gives samples no size; cannot shade it");
  }
  std::unique_ptr<ImageSource> shaded;
  Status s = ReliefSource::open(std::move(*source), relief, &shaded);
  if (!s) return Status::error(s.code, o.input_path + ": " + s.message);
  *source = std::move(shaded);
  *elevation = ElevationInfo{};
  return okStatus();
}

// A colour input's no-data value (--nodata, else what GDAL or the file's
// GDAL_NODATA tag says) as transparency: 8-bit grey or RGB inputs whose
// format was not forced to one without alpha become RGBA8.
Status makeNoDataTransparent(const TilerOptions& o, TilerInput* in, std::vector<std::string>* warnings) {
  const SourceInfo& info = in->source->info();
  std::optional<double> nodata = o.nodata;
  if (!nodata) {
    ElevationTags tags;
    Status s = inputTags(info, o.input_path, &tags);
    if (!s) return s;
    if (tags.has_nodata) nodata = tags.nodata;
  }
  if (!nodata) return okStatus();
  const bool eight_bit = info.input_type == "uint8";
  const bool forced_opaque = o.format && *o.format != PixelFormat::kRGBA8;
  if (info.input_channels == 2 || info.input_channels == 4 || forced_opaque) return okStatus();  // has or wants no alpha
  if (!eight_bit || !(*nodata >= 0.0 && *nodata <= 255.0 && *nodata == std::floor(*nodata))) {
    char text[160];
    std::snprintf(text, sizeof text,
                  ": no-data value %.9g stays opaque: only an 8-bit grey or RGB input's whole-number "
                  "no-data becomes transparent (this one is %s)",
                  *nodata, info.input_type.c_str());
    warnings->push_back(o.input_path + text);
    return okStatus();
  }
  in->source = std::make_unique<NoDataAlphaSource>(std::move(in->source), uint8_t(*nodata));
  in->transparent_nodata = *nodata;
  return okStatus();
}

// A DEM whose samples are not square on the ground (a geographic CRS away
// from the equator) is drawn stretched: says so, and what reprojects it.
void warnIfStretched(const TilerOptions& o, const TilerInput& in, std::vector<std::string>* warnings) {
  if (!in.geo.present) return;
  const double* t = in.geo.transform;
  const double latitude = t[3] + t[5] * double(in.source->info().height_px) * 0.5;
  const CrsUnitMetres unit = metresPerCrsUnit(in.geo.crs, latitude);
  const double x = std::hypot(t[1], t[4]) * unit.x, y = std::hypot(t[2], t[5]) * unit.y;
  if (unit.assumed || !(x > 0.0) || !(y > 0.0) || std::abs(x - y) <= 0.01 * std::max(x, y)) return;
  char text[200];
  std::snprintf(text, sizeof text,
                ": samples are %.2f x %.2f m on the ground (a geographic CRS), so terrain is drawn "
                "stretched %.0f %%; --t-srs auto reprojects it to its UTM zone",
                x, y, 100.0 * (std::max(x, y) / std::min(x, y) - 1.0));
  warnings->push_back(o.input_path + text);
}

}  // namespace

ImageReadOptions imageReadOptions(const TilerOptions& o) {
  ImageReadOptions read;
  read.reader = o.reader;
  read.decode_threads = o.threads;
  read.memory_budget_bytes = o.memory_budget_bytes;
  read.target_crs = o.target_crs;
  read.resampling = o.resampling;
  read.target_resolution = o.target_resolution;
  return read;
}

Status openInputImage(const TilerOptions& o, TilerInput* out) {
  const ImageReadOptions read = imageReadOptions(o);
  if (o.input_path.empty()) {
    return makeSyntheticSource(o.synthetic_width_px, o.synthetic_height_px,
                               o.format.value_or(PixelFormat::kRGB8), &out->source);
  }
  // A height format asked for by --format is the elevation path's to
  // choose; the first open only looks at the input (for a mosaic as for
  // one file).
  const bool height_format = o.format && !isColourFormat(*o.format);
  const std::optional<PixelFormat> first_format = height_format ? std::nullopt : o.format;
  if (!o.mosaic) {
    Status s = openImageFile(o.input_path, first_format, &out->source, read);
    if (!s) return s;
    const SourceMetadata& meta = out->source->info().metadata;
    if (meta.present) {
      out->geo = meta.geo;  // the decoder read it (GDAL)
      return okStatus();
    }
    return findGeoReference(o.input_path, &out->geo);
  }
  Status s = openMosaic(o.input_path, first_format, o.fill, &out->source, &out->mosaic, read);
  if (s) out->geo = out->mosaic.geo;
  for (const std::string& sheet : out->mosaic.sheets) {
    if (s && sameFile(sheet, o.output_path)) {
      s = Status::error(ErrorCode::kInvalidArgument,
                        o.output_path + " is the mosaic's sheet " + sheet +
                            " (the same file, maybe through a link); refusing to overwrite it");
    }
  }
  return s;
}

Status openInput(const TilerOptions& o, TilerInput* out, std::vector<std::string>* warnings) {
  Status s = openInputImage(o, out);
  if (!s) return s;
  // A relief is drawn from the input's heights: read them as for an
  // elevation store, exactly (F32), before shading.
  TilerOptions elevation_options = o;
  if (o.relief_scale > 0) {
    elevation_options.layer = LayerKind::kElevation;
    elevation_options.format = PixelFormat::kF32;
    elevation_options.filter = DownsampleFilter::kBox;
    elevation_options.linear_light = false;
  }
  if (o.mosaic) {
    s = openElevation(elevation_options, out->geo, out->mosaic.sheets.front(),
                      reopenMosaic(o, out->mosaic.gap_px), &out->source, &out->heights,
                      &out->elevation, warnings);
    if (!s) return s;
  } else if (!o.input_path.empty()) {
    s = openElevation(elevation_options, out->geo, o.input_path, reopenFile(o), &out->source,
                      &out->heights, &out->elevation, warnings);
    if (!s) return s;
  }
  if (out->elevation.present && o.target_crs.empty()) warnIfStretched(o, *out, warnings);
  if (!out->elevation.present && o.relief_scale == 0 && !o.mosaic && !o.input_path.empty()) {
    s = makeNoDataTransparent(o, out, warnings);
    if (!s) return s;
  }
  if (o.relief_scale > 0) {
    s = makeRelief(o, &out->geo, &out->source, &out->elevation);
    if (!s) return s;
    out->heights = nullptr;  // a colour store: no height statistics
  }
  return okStatus();
}

}  // namespace clipstream
