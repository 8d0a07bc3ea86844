// Mosaics: many georeferenced sheets (an orthophoto delivery) read as one
// image, placed by their georeferences (docs/tiler.md, "Mosaics").
//
// Thread rule: openMosaic() is a free function; the source it makes is used
// by one thread at a time, as every ImageSource.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/tiler/image_source.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace clipstream {

// Largest list file read (a million sheets of 60-byte paths).
constexpr uint64_t kMaxMosaicListBytes = uint64_t(64) << 20;

struct MosaicInfo {
  GeoReference geo;                 // of the mosaic's top-left corner
  std::vector<std::string> sheets;  // paths as opened, in list order
  uint64_t gap_px = 0;              // level-0 pixels no sheet covers (filled)
};

// Opens the mosaic named by the list file at `list_path`: one image path a
// line (relative paths are relative to the list's folder; blank lines and
// lines starting with '#' are skipped), or a GDAL VRT whose bands are simple
// sources drawing whole files unscaled (its sources become the list; other
// VRTs are kUnsupported, naming the line). Each sheet is opened once here to
// read its size, pixel type and georeference (GeoTIFF tags, world file,
// .prj; as findGeoReference) and closed again; while tiling, a sheet is
// opened when a strip first reaches it and closed once strips have passed
// below it, so only the sheets under one strip are open at a time.
//
// Every sheet must be georeferenced without rotation, with the first
// sheet's pixel size and CRS text, on its pixel grid (offsets whole pixels),
// and of its channel count and pixel type. The mosaic is the bounding box
// of the sheets; pixels no sheet covers take `fill` in every channel except
// alpha, which is 0 (transparent; with RGB sheets, ask for RGBA8 to get an
// alpha channel). Where sheets overlap, the later one in the list wins.
// `forced` is the store format and `read` the readers' options as for
// openImageFile.
//
// Errors name the list (and line) or the sheet: kNotFound / kIo (the list
// or a sheet), kInvalidArgument (an empty list, a sheet without a
// georeference, another pixel size, CRS, channel count or pixel type, off
// the grid, a fill value the format cannot hold), kUnsupported (rotated
// sheets), and openImageFile's errors for a sheet.
Status openMosaic(const std::string& list_path, std::optional<PixelFormat> forced, uint32_t fill,
                  std::unique_ptr<ImageSource>* out, MosaicInfo* info,
                  const ImageReadOptions& read = {});

// The same mosaic of DEM sheets delivering native height samples in
// `native` (I16, R16 or F32, as openImageFile with that format), with gaps
// holding `gap_height` (the no-data value, NaN allowed for F32), so that the
// elevation path fills them like any no-data sample. The checks and errors
// are openMosaic's.
Status openHeightMosaic(const std::string& list_path, PixelFormat native, double gap_height,
                        std::unique_ptr<ImageSource>* out, MosaicInfo* info,
                        const ImageReadOptions& read = {});

}  // namespace clipstream
