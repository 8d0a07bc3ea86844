// Private: whether a tiler input becomes an elevation store, and if so the
// input opened again delivering its native height samples behind a
// HeightSource (no-data fill, quantisation). See docs/tiler.md, "Elevation
// stores (DEMs)", and docs/terrain.md.
//
// Thread rule: free functions; any thread. openElevation() reads the input
// on the calling thread.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>
#include <clipstream/tiler/georef.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/tiler.h>

#include "height_source.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

// Whether an input first opened as `first` becomes an elevation store:
// LayerKind, else a height format asked for by --format, else (kAuto, no
// --format) a single-band int16 input, or a single-band uint16 or
// floating-point one that is georeferenced.
bool wantsElevation(const TilerOptions& o, const SourceInfo& first, const GeoReference& geo);

// What the input says of its samples' no-data value and unit: what its
// decoder read itself (GDAL: SourceInfo::metadata), else the tags of the
// file at `tags_path` (readElevationTags). Its errors.
Status inputTags(const SourceInfo& info, const std::string& tags_path, ElevationTags* out);

// Opens the input again delivering native samples in `native`;
// `conversion` says the no-data value (a mosaic fills its gaps with it).
using ReopenHeights = std::function<Status(PixelFormat native, const HeightConversion& conversion,
                                           std::unique_ptr<ImageSource>* out)>;

// Decides whether the input in *source becomes an elevation store
// (wantsElevation) and, if so, checks the options against its samples,
// reads the no-data value and units (inputTags() of `tags_path`),
// reopens it through `reopen_input` (twice when --height-step must scan the
// heights' range first) and replaces *source by a HeightSource over it;
// *heights then points into *source and *elevation describes the store. A
// DEM without georeference adds a warning. Left alone for a colour store.
// Errors name the input: kInvalidArgument (an option that does not fit the
// samples), kUnsupported (more than one band), and the reader's errors.
Status openElevation(const TilerOptions& o, const GeoReference& geo, const std::string& tags_path,
                     const ReopenHeights& reopen_input, std::unique_ptr<ImageSource>* source,
                     HeightSource** heights, ElevationInfo* elevation,
                     std::vector<std::string>* warnings);

}  // namespace clipstream
