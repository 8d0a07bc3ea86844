// GeoTIFF tags: what a TIFF says of where it lies (the georeference) and of
// the heights it holds (GDAL's no-data tag, the vertical unit). One parser
// for the tiler's inputs (clipstream/tiler/georef.h) and for the
// Cloud-Optimized GeoTIFFs read directly as tile sources (cog.h).
//
// Thread-safe: pure functions (the reader callback is called on the
// caller's thread).
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>

namespace clipstream {

// What a TIFF says about the heights it holds: GDAL's no-data tag (42113),
// and the unit from the VerticalUnitsGeoKey or GDAL's UNITTYPE metadata.
struct ElevationTags {
  bool has_nodata = false;
  double nodata = 0.0;  // may be NaN
  std::optional<HeightUnits> units;
};

// Reads `n` bytes at `offset` of the file into `dst`; false on failure.
using TiffByteReader = std::function<bool(uint64_t offset, void* dst, size_t n)>;

// Reads ModelPixelScale / ModelTiepoint / ModelTransformation and the
// GeoKeyDirectory (CRS: "EPSG:n" of the projected or geographic type key),
// and GDAL's no-data and metadata tags, from the first IFD of the TIFF or
// BigTIFF of `size` bytes that `read` reads. Nothing found (not a TIFF, no
// such tags): *geo not present, *elevation empty. Malformed GeoTIFF tags:
// kBadHeader naming `name`.
Status parseGeoTiffTags(const std::string& name, uint64_t size, const TiffByteReader& read,
                        GeoReference* geo, ElevationTags* elevation);

// A height unit from the text files give it (GDAL's UNITTYPE, a band's
// unit type): "m", "metre", "meter(s)"; "ft", "foot", "feet"; "US survey
// foot", "ftUS", "us-ft"; any case. Anything else: unknown. Header-only and
// free of store symbols: the tiler's GDAL module links GDAL alone.
inline std::optional<HeightUnits> heightUnitsFromText(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (text == "m" || text == "metre" || text == "meter" || text == "metres" || text == "meters") {
    return HeightUnits::kMetre;
  }
  if (text == "ft" || text == "foot" || text == "feet") return HeightUnits::kFoot;
  if (text == "us survey foot" || text == "ftus" || text == "us-ft") return HeightUnits::kUsSurveyFoot;
  return std::nullopt;
}

}  // namespace clipstream
