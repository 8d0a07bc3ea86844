// Georeferencing of tiler inputs: GeoTIFF tags or a world file beside the
// image, turned into the store's GDAL-order affine transform (pixel
// corners) plus a CRS string.
//
// Thread-safe: free functions with no shared state.
#pragma once

#include <clipstream/store/geotiff.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <optional>
#include <string>

namespace clipstream {

// Finds georeferencing for the image at `path`: GeoTIFF tags first (for
// TIFF files), then a world file next to it (.wld, then the three-letter
// convention .tfw/.jgw/.pgw, then ext + "w"). A .prj beside the image
// supplies the CRS when the tags do not. out->present is false when nothing
// is found; a world file that exists but does not parse is an error
// (kBadHeader naming the file).
Status findGeoReference(const std::string& path, GeoReference* out);

// Reads a world file: six numbers A D B E C F, where C/F locate the CENTRE
// of the top-left pixel. The result is shifted to the pixel corner.
Status readWorldFile(const std::string& path, GeoReference* out);

// Reads ModelPixelScale/ModelTiepoint/ModelTransformation and the
// GeoKeyDirectory from the first IFD of a TIFF or BigTIFF. out->present is
// false when the file has no such tags. Malformed tags are an error.
Status readGeoTiffTags(const std::string& path, GeoReference* out);

// What a TIFF says about the heights it holds (ElevationTags: geotiff.h).
// Empty for files that are not TIFFs or carry none of these. Malformed
// GeoTIFF tags are an error as for readGeoTiffTags.
Status readElevationTags(const std::string& path, ElevationTags* out);

}  // namespace clipstream
