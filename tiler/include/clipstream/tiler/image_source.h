// Where the tiler's level-0 pixels come from: an image file (TIFF, JPEG and
// PNG through the tiler's own readers on libtiff, libjpeg-turbo and libpng;
// other image formats through OpenImageIO; URLs, VRTs, JPEG 2000, geodata
// formats and reprojection through GDAL), or a procedural image computed on
// demand. Either way the
// source hands out rows already converted to the store's pixel format, so
// the pyramid code never sees input pixel types.
//
// Thread rule: one ImageSource is used by one thread at a time (the tiler's
// reader thread). Different sources are independent.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace clipstream {

// What a decoder read itself about where the data lies and what its
// samples mean. GDAL's reader fills it; for the others `present` stays
// false and the tiler reads the file's GeoTIFF tags or world file
// (findGeoReference, readElevationTags in georef.h).
struct SourceMetadata {
  bool present = false;
  GeoReference geo;
  bool has_nodata = false;
  double nodata = 0.0;  // may be NaN
  std::optional<HeightUnits> units;
};

// What the input looked like before conversion, for summaries and docs.
struct SourceInfo {
  uint64_t width_px = 0;
  uint64_t height_px = 0;
  uint32_t input_channels = 0;
  std::string input_type;        // "uint8", "uint16", "int16", "float", "half", "synthetic"
  std::string decoder;           // "libtiff", "libjpeg", "libpng", "openimageio", "synthetic", "mosaic"
  bool tiled = false;            // true when the file stores tiles (region reads are cheap)
  bool sequential_only = false;  // true when rows must be read top to bottom (e.g. JPEG)
  uint64_t file_bytes = 0;       // size of the input file, 0 for synthetic input
  PixelFormat format = PixelFormat::kRGB8;  // format rows are delivered in
  uint64_t clamped_samples = 0;  // samples clamped by the conversion so far
  std::vector<std::string> warnings;  // what the user should know about the input
  SourceMetadata metadata;
  // Set when GDAL's warper reprojected the input: "from -> to, resampling".
  std::string reprojection;
};

class ImageSource {
 public:
  virtual ~ImageSource() = default;

  // Size, format and provenance; valid after a successful open.
  virtual const SourceInfo& info() const = 0;

  // Reads rows [y0, y0 + rows) and columns [x0, x0 + width) of the image
  // into `dst` (row r starts at dst + r * dst_stride bytes), converted to
  // info().format. The caller owns `dst`. Reading rows in increasing order
  // is fastest; going back up may re-decode the file from the start.
  // Errors: kIo / kTruncated / kCorruptTile-like decoder failures, with the
  // file name and the decoder's message.
  virtual Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width,
                          uint8_t* dst, size_t dst_stride) = 0;
};

// Which decoder reads an image file.
enum class ImageReader {
  // The tiler's own readers for the TIFF, JPEG and PNG files they cover
  // (tiled and striped TIFF and BigTIFF of 8/16-bit integer or 32/64-bit
  // float samples, any compression libtiff has; grey and colour JPEG,
  // baseline or progressive; 8/16-bit grey, grey+alpha, RGB and RGBA PNG);
  // GDAL for URLs, /vsi paths, VRTs and JPEG 2000; OpenImageIO for the other
  // image formats; GDAL for what OpenImageIO cannot open.
  kAuto,
  kOpenImageIO,  // OpenImageIO for every file (for comparison)
  kGdal,         // GDAL for every file (for comparison)
};

struct ImageReadOptions {
  ImageReader reader = ImageReader::kAuto;
  // Threads decoding a TIFF's strips or tiles at once (the calling thread
  // is one of them); 0 = all cores. Other formats decode on the caller.
  unsigned decode_threads = 0;
  // The memory the caller may spend, 0 = no bound. A progressive JPEG
  // holds every DCT coefficient of the image until its last scan (2 bytes
  // a sample); when they would take more than a quarter of this, they are
  // kept in a temporary file in $TMPDIR (else /tmp) instead, a few MB of
  // them in memory at a time.
  uint64_t memory_budget_bytes = 0;
  // Reprojection by GDAL's warper (the input is then read through GDAL):
  // the target CRS as GDAL takes it (EPSG:n, WKT, a PROJ string), or "auto"
  // for the UTM zone of a geographic input's centre; empty = as stored. The
  // grid is GDAL's suggestion (gdalwarp's default: the input's extent, and
  // its resolution along the diagonal), unless target_resolution > 0.
  std::string target_crs;
  std::string resampling = "bilinear";  // near, bilinear, cubic, cubicspline, lanczos, average, mode
  double target_resolution = 0.0;       // pixel size in target CRS units; 0 = GDAL's
};

// Opens an image file and decides its conversion: 1 channel -> R8 (8-bit
// or float input) or R16 (16-bit input), 2 channels (grey + alpha) ->
// RGBA8, 3 -> RGB8, 4 -> RGBA8. `forced` overrides the target format.
// Fails with kNotFound, kIo (names the file and the decoder's error),
// kInvalidArgument (zero size) or kUnsupported (pixel type, channel count).
Status openImageFile(const std::string& path, std::optional<PixelFormat> forced,
                     std::unique_ptr<ImageSource>* out, const ImageReadOptions& read = {});

// A deterministic procedural image of width_px x height_px whose pixels are
// a pure function of (x, y) (see syntheticPixel). No memory beyond the
// object itself; any region can be read in any order.
Status makeSyntheticSource(uint64_t width_px, uint64_t height_px, PixelFormat format,
                           std::unique_ptr<ImageSource>* out);

// The synthetic image's pixel at (x, y) in `format`, written to `out`
// (bytesPerPixel(format) bytes). Textured noise plus coordinate bits, so it
// compresses roughly like an orthophoto rather than like a flat colour.
void syntheticPixel(uint64_t x, uint64_t y, PixelFormat format, uint8_t* out);

}  // namespace clipstream
