// The boundary between the tiler and its GDAL module. Like OpenImageIO's
// (oiio_module.h), GDAL and the ~200 libraries it links are loaded with
// dlopen on the first input that needs them (image_source.cpp), so runs on
// the formats the tiler reads itself start as fast and as small as before.
// The module exports one C-linkage entry point with this signature.
#pragma once

#include <clipstream/tiler/image_source.h>

#include <memory>
#include <optional>
#include <string>

namespace clipstream {

inline constexpr const char* kGdalModuleFileName = "libclipstream_tiler_gdal.so";
inline constexpr const char* kGdalModuleSymbol = "clipstreamTilerOpenGdal";

// Same contract as openImageFile(), for anything GDAL opens: a file, a
// /vsi path, a URL (http:// and https:// go through /vsicurl/) or a GDAL
// connection string such as NETCDF:"file.nc":variable. The source's
// info().metadata carries the georeference, no-data value and height unit
// GDAL read. Results through pointers because the symbol has C linkage.
using OpenGdalFn = void (*)(const std::string* path, const std::optional<PixelFormat>* forced,
                            const ImageReadOptions* read, std::unique_ptr<ImageSource>* out,
                            Status* status);

// Whether `path` is an http://, https:// or ftp:// URL (GDAL reads them
// through /vsicurl/).
inline bool isUrl(const std::string& path) {
  for (const char* scheme : {"http://", "https://", "ftp://"}) {
    if (path.rfind(scheme, 0) == 0) return true;
  }
  return false;
}

// Whether `path` is a name only GDAL opens: an http(s) or ftp URL, a /vsi
// path, or a driver's connection string (NETCDF:"f.nc":var). Checked by
// openImageFile() when no file has that name. Defined in image_source.cpp.
bool isGdalName(const std::string& path);

}  // namespace clipstream
