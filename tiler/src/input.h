// Private: the tiler's input as one ImageSource, from the options: the
// procedural image, a mosaic of sheets, or one file read by the decoder its
// first bytes call for (image_source.h); then, for a DEM, reopened for its
// native heights (elevation_input.h) and, for --relief, shaded
// (relief_source.h). The sharded band is cut later (shard_run.h).
//
// Thread rule: free functions; any thread. They open and read the input on
// the calling thread; the source they hand out is then used by one thread
// at a time (the pipeline's reader thread).
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/mosaic.h>
#include <clipstream/tiler/tiler.h>

#include "height_source.h"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace clipstream {

// An opened input, ready for the pipeline.
struct TilerInput {
  std::unique_ptr<ImageSource> source;
  GeoReference geo;               // the input's (a relief's pixels are relief_scale times smaller)
  MosaicInfo mosaic;              // sheets and gaps of a mosaic; empty otherwise
  HeightSource* heights = nullptr;  // inside `source` for an elevation store, else null
  ElevationInfo elevation;        // present for an elevation store
  // A colour input's no-data value, drawn transparent (nodata_alpha.h).
  std::optional<double> transparent_nodata;
};

// How the tiler's options read image files: the reader, TIFF decode
// threads and the budget a progressive JPEG stays within.
ImageReadOptions imageReadOptions(const TilerOptions& o);

// The input as the options name it, opened once to look at it: the
// synthetic image, a mosaic (refused when a sheet is the output file), or a
// file with its georeference (findGeoReference). A height format asked for
// by --format is left to openElevation (the first open delivers the default
// conversion). Errors: openImageFile's, openMosaic's, findGeoReference's.
Status openInputImage(const TilerOptions& o, TilerInput* out);

// The whole input side of a run: openInputImage(), then an elevation store
// when the input is one (openElevation), then a relief when
// o.relief_scale > 0 (heights read exactly, then shaded: a colour store,
// `heights` null). Warnings about the input are appended to `warnings`.
// Errors name the input; *out is not to be used after one.
Status openInput(const TilerOptions& o, TilerInput* out, std::vector<std::string>* warnings);

}  // namespace clipstream
