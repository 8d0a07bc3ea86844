// Private: a DEM's height unit from the text files give it (GDAL's
// UNITTYPE, a band's unit type): one reading for the GeoTIFF reader
// (georef.cpp) and the GDAL module (gdal_source.cpp). Header-only and free
// of store symbols: the module links GDAL alone.
//
// Thread rule: a pure function; any thread.
#pragma once

#include <clipstream/store/tile_store.h>

#include <algorithm>
#include <cctype>
#include <optional>
#include <string>

namespace clipstream {

// "m", "metre", "meter(s)"; "ft", "foot", "feet"; "US survey foot",
// "ftUS", "us-ft"; any case. Anything else: unknown.
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
