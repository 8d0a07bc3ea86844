// The GDAL side of the tiler's image sources, built as a separate module
// (gdal_module.h says why): URLs, /vsi paths, VRTs, JPEG 2000, HDF and
// NetCDF subdatasets and every other raster GDAL reads that the tiler's own
// readers and OpenImageIO do not. Rows come from GDALDatasetRasterIO in the
// file's sample type and are converted by pixel_convert.h, shared with the
// other readers, so the same samples give the same bytes whoever decodes
// them. This file must not use symbols from clipstream_store: the module
// links GDAL only.
#include "gdal_module.h"
#include <clipstream/store/geotiff.h>
#include "pixel_convert.h"

#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <cpl_vsi.h>
#include <gdal.h>
#include <gdal_utils.h>
#include <ogr_srs_api.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

namespace clipstream {
namespace {

using namespace pixel_convert;

// One RasterIO call never asks for more than this many bytes of native
// samples, whatever the image width.
constexpr size_t kMaxScratchBytes = size_t(8) << 20;

// GDAL's block cache (GDAL_CACHEMAX): a quarter of the caller's budget, at
// least 64 MB, at most 1 GB. Rows are read in strips of the pipeline's
// height while a file's blocks may be taller (a COG's 512-row tiles): a
// band of blocks across the whole width must stay cached between strips,
// or each strip would fetch and decode the band again.
constexpr uint64_t kMinCacheBytes = uint64_t(64) << 20;
constexpr uint64_t kMaxCacheBytes = uint64_t(1) << 30;

// The messages GDAL reports on this thread while one is installed: the
// first failure (what the user sees) and a count of the rest.
class ErrorCollector {
 public:
  ErrorCollector() { CPLPushErrorHandlerEx(&ErrorCollector::handle, this); }
  ~ErrorCollector() { CPLPopErrorHandler(); }
  ErrorCollector(const ErrorCollector&) = delete;
  ErrorCollector& operator=(const ErrorCollector&) = delete;

  // The first failure, else the first warning, else `fallback`.
  std::string message(const char* fallback) const {
    return decoderMessage(!m_failure.empty() ? m_failure : m_warning, fallback);
  }
  bool failed() const { return !m_failure.empty(); }

 private:
  static void CPL_STDCALL handle(CPLErr level, CPLErrorNum, const char* text) {
    auto* self = static_cast<ErrorCollector*>(CPLGetErrorHandlerUserData());
    if (self == nullptr || text == nullptr) return;
    std::string& slot = level >= CE_Failure ? self->m_failure : level == CE_Warning ? self->m_warning
                                                                                    : self->m_ignored;
    if (slot.empty()) {
      slot = text;
    } else if (&slot != &self->m_ignored) {
      slot += "\n";
      slot += text;  // counted by decoderMessage as "and N more"
    }
  }

  std::string m_failure, m_warning, m_ignored;
};

// Process-wide GDAL settings, once: drivers and a block cache within the
// budget. GDAL reads .aux.xml side-car files and writes one on close only
// when something it saves changed (statistics, metadata): the tiler
// changes none, so nothing is written beside an input (tested).
void initialiseGdal(uint64_t budget_bytes) {
  static std::once_flag once;
  std::call_once(once, [budget_bytes] {
    GDALAllRegister();
    const uint64_t quarter = budget_bytes > 0 ? budget_bytes / 4 : kMaxCacheBytes;
    GDALSetCacheMax64(GIntBig(std::clamp(quarter, kMinCacheBytes, kMaxCacheBytes)));
  });
}

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

// What GDAL opens for `path`: http(s) and ftp URLs through /vsicurl/,
// anything else as given.
std::string gdalName(const std::string& path) { return isUrl(path) ? "/vsicurl/" + path : path; }

// The CRS as the store keeps it: "EPSG:n" when the whole CRS is one EPSG
// code (as the GeoTIFF reader writes it), else its WKT.
std::string crsText(GDALDatasetH ds) {
  OGRSpatialReferenceH srs = GDALGetSpatialRef(ds);
  if (srs == nullptr) return {};
  OGRSpatialReferenceH copy = OSRClone(srs);
  std::string text;
  if (OSRGetAuthorityName(copy, nullptr) == nullptr) OSRAutoIdentifyEPSG(copy);
  const char* authority = OSRGetAuthorityName(copy, nullptr);
  const char* code = OSRGetAuthorityCode(copy, nullptr);
  if (authority != nullptr && code != nullptr && EQUAL(authority, "EPSG")) {
    text = std::string("EPSG:") + code;
  } else {
    char* wkt = nullptr;
    if (OSRExportToWkt(copy, &wkt) == OGRERR_NONE && wkt != nullptr) text = wkt;
    CPLFree(wkt);
  }
  OSRDestroySpatialReference(copy);
  return text;
}

class GdalSource final : public ImageSource {
 public:
  // `ds` is read; `underlying` (may be null) is the file a warped `ds`
  // reads from, closed after it.
  GdalSource(std::string path, GDALDatasetH ds, GDALDatasetH underlying, SourceInfo info, SampleKind kind,
             GDALDataType read_type, std::vector<std::array<uint8_t, 4>> palette)
      : m_path(std::move(path)),
        m_ds(ds),
        m_underlying(underlying),
        m_info(std::move(info)),
        m_kind(kind),
        m_read_type(read_type),
        m_palette(std::move(palette)) {}
  ~GdalSource() override {
    GDALClose(m_ds);
    if (m_underlying != nullptr) GDALClose(m_underlying);
  }

  const SourceInfo& info() const override { return m_info; }

  // RGBA8 rows come out premultiplied (for alpha the warper added).
  void setPremultiply(bool on) { m_premultiply = on; }

  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    if (y0 + rows > m_info.height_px || x0 + width > m_info.width_px) {
      return Status::error(ErrorCode::kOutOfRange, m_path + ": row request outside the image");
    }
    ErrorCollector errors;
    const uint32_t nch = m_info.input_channels;
    // A palette file is read as its indices (one band) and expanded to RGB(A).
    const int bands = m_palette.empty() ? int(nch) : 1;
    const size_t sample = size_t(GDALGetDataTypeSizeBytes(m_read_type));
    const size_t read_pixel = sample * size_t(bands);
    const size_t read_row = read_pixel * width;
    const uint32_t chunk =
        uint32_t(std::clamp<size_t>(kMaxScratchBytes / std::max<size_t>(read_row, 1), 1, rows));
    const bool fast_copy = m_palette.empty() && m_kind == SampleKind::kU8 &&
                           formatChannels(m_info.format) == nch;
    for (uint32_t done = 0; done < rows;) {
      const uint32_t n = std::min(chunk, rows - done);
      m_scratch.resize(read_row * n);
      const CPLErr e = GDALDatasetRasterIOEx(m_ds, GF_Read, int(x0), int(y0 + done), int(width), int(n),
                                             m_scratch.data(), int(width), int(n), m_read_type, bands, nullptr,
                                             GSpacing(read_pixel), GSpacing(read_row), GSpacing(sample), nullptr);
      if (e != CE_None || errors.failed()) {
        return Status::error(ErrorCode::kIo, m_path + ": cannot read rows " + std::to_string(y0 + done) +
                                                 "-" + std::to_string(y0 + done + n - 1) + ": " +
                                                 errors.message("GDAL failed"));
      }
      for (uint32_t r = 0; r < n; ++r) {
        const uint8_t* src = m_scratch.data() + size_t(r) * read_row;
        if (!m_palette.empty()) src = expand(src, width);
        uint8_t* out = dst + size_t(done + r) * dst_stride;
        convertNativeRow(m_kind, src, nch, width, m_info.format, fast_copy, out, &m_info.clamped_samples);
        if (m_premultiply) premultiply(out, width);
      }
      done += n;
    }
    return okStatus();
  }

 private:
  // Colour times alpha, for the alpha the warper added: its edges are
  // partial (resampled coverage), and the renderer and the filters take
  // colour as premultiplied (docs/decisions.md D293).
  void premultiply(uint8_t* rgba, uint64_t width) const {
    if (m_info.format != PixelFormat::kRGBA8) return;
    for (uint64_t x = 0; x < width; ++x, rgba += 4) {
      const uint32_t a = rgba[3];
      for (int c = 0; c < 3; ++c) rgba[c] = uint8_t((rgba[c] * a + 127) / 255);
    }
  }

  // One row of palette indices (uint16) as RGB or RGBA bytes.
  const uint8_t* expand(const uint8_t* indices, uint64_t width) {
    const uint32_t nch = m_info.input_channels;
    m_expanded.resize(size_t(width) * nch);
    for (uint64_t x = 0; x < width; ++x) {
      uint16_t i;
      std::memcpy(&i, indices + 2 * x, 2);
      static constexpr std::array<uint8_t, 4> kOutside = {0, 0, 0, 0};
      const std::array<uint8_t, 4>& c = i < m_palette.size() ? m_palette[i] : kOutside;
      std::memcpy(m_expanded.data() + x * nch, c.data(), nch);
    }
    return m_expanded.data();
  }

  std::string m_path;
  GDALDatasetH m_ds;
  GDALDatasetH m_underlying;
  SourceInfo m_info;
  SampleKind m_kind;
  GDALDataType m_read_type;
  std::vector<std::array<uint8_t, 4>> m_palette;  // empty unless the file is paletted
  bool m_premultiply = false;
  std::vector<uint8_t> m_scratch, m_expanded;
};

// Closes a dataset on every early return of openGdal.
struct DatasetCloser {
  GDALDatasetH ds = nullptr;
  ~DatasetCloser() {
    if (ds != nullptr) GDALClose(ds);
  }
};

// A spatial reference that is destroyed with its holder.
struct Srs {
  OGRSpatialReferenceH h = OSRNewSpatialReference(nullptr);
  ~Srs() { OSRDestroySpatialReference(h); }
  Srs() { OSRSetAxisMappingStrategy(h, OAMS_TRADITIONAL_GIS_ORDER); }
  Srs(const Srs&) = delete;
  Srs& operator=(const Srs&) = delete;
};

// "EPSG:n (name)" for the summary.
std::string describeSrs(OGRSpatialReferenceH srs) {
  const char* authority = OSRGetAuthorityName(srs, nullptr);
  const char* code = OSRGetAuthorityCode(srs, nullptr);
  const char* name = OSRGetName(srs);
  std::string text = authority != nullptr && code != nullptr ? std::string(authority) + ":" + code : "";
  if (name != nullptr) text += text.empty() ? name : std::string(" (") + name + ")";
  return text.empty() ? "a CRS without a name" : text;
}

// The CRS the input's georeference is in: its transform's, else its
// ground control points'.
OGRSpatialReferenceH sourceSrs(GDALDatasetH src) {
  OGRSpatialReferenceH srs = GDALGetSpatialRef(src);
  return srs != nullptr ? srs : GDALGetGCPSpatialRef(src);
}

// The coordinate system of the raster file at `path` into `dst` (--t-srs
// FILE: reproject onto another layer's CRS, the DEM's for a texture).
Status crsOfRaster(const std::string& path, Srs* dst) {
  GDALDatasetH ds = GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr);
  if (ds == nullptr)
    return Status::error(ErrorCode::kInvalidArgument,
                         "--t-srs " + path + ": not a raster GDAL reads (for a tile store, give the CRS "
                                             "clipstream-info shows)");
  OGRSpatialReferenceH srs = sourceSrs(ds);
  Status status = okStatus();
  if (srs == nullptr) {
    status = Status::error(ErrorCode::kInvalidArgument, "--t-srs " + path + ": has no coordinate system");
  } else {
    char* wkt = nullptr;
    OSRExportToWkt(srs, &wkt);
    if (wkt == nullptr || OSRSetFromUserInput(dst->h, wkt) != OGRERR_NONE)
      status = Status::error(ErrorCode::kInvalidArgument, "--t-srs " + path + ": its coordinate system cannot be read");
    CPLFree(wkt);
  }
  GDALClose(ds);
  return status;
}

// The target CRS of --t-srs into `dst`: as GDAL takes it, a raster file's, or "auto": the
// WGS 84 UTM zone of a geographic input's centre (a projected input stays
// as it is: *keep set).
Status targetSrs(const std::string& path, GDALDatasetH src, const std::string& text, Srs* dst, bool* keep) {
  *keep = false;
  OGRSpatialReferenceH from = sourceSrs(src);
  if (from == nullptr) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + ": has no coordinate system to reproject from (--t-srs)");
  }
  if (text != "auto") {
    VSIStatBufL stat;
    if (VSIStatL(text.c_str(), &stat) == 0 && VSI_ISREG(stat.st_mode)) {
      // A raster file: its coordinate system (the DEM a texture must lie on).
      return crsOfRaster(text, dst);
    }
    if (OSRSetFromUserInput(dst->h, text.c_str()) != OGRERR_NONE) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "--t-srs '" + text + "' is not a coordinate system GDAL knows "
                                                "(EPSG:n, WKT, a PROJ string, a raster file, or auto)");
    }
    return okStatus();
  }
  if (!OSRIsGeographic(from)) {
    *keep = true;
    return okStatus();
  }
  double gt[6];
  if (GDALGetGeoTransform(src, gt) != CE_None) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + ": --t-srs auto needs a georeference (ground control points alone do not "
                                "say where the middle is); give a CRS");
  }
  // The centre and the corners in longitude and latitude, whatever the
  // axis order of the CRS.
  const double w = GDALGetRasterXSize(src), h = GDALGetRasterYSize(src);
  double xs[5] = {0.5 * w, 0, w, 0, w}, ys[5] = {0.5 * h, 0, 0, h, h};
  for (int i = 0; i < 5; ++i) {
    const double px = xs[i], py = ys[i];
    xs[i] = gt[0] + gt[1] * px + gt[2] * py;
    ys[i] = gt[3] + gt[4] * px + gt[5] * py;
  }
  Srs lonlat;
  OSRSetWellKnownGeogCS(lonlat.h, "WGS84");
  OGRSpatialReferenceH from_gis = OSRClone(from);
  OSRSetAxisMappingStrategy(from_gis, OAMS_TRADITIONAL_GIS_ORDER);
  OGRCoordinateTransformationH ct = OCTNewCoordinateTransformation(from_gis, lonlat.h);
  const bool moved = ct != nullptr && OCTTransform(ct, 5, xs, ys, nullptr);
  if (ct != nullptr) OCTDestroyCoordinateTransformation(ct);
  OSRDestroySpatialReference(from_gis);
  const double x = xs[0] - 360.0 * std::floor((xs[0] + 180.0) / 360.0), y = ys[0];  // longitude in [-180, 180)
  if (!moved || !(std::abs(y) <= 84.0)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + ": --t-srs auto picks a UTM zone, and the input's centre is not between "
                                "84 degrees south and north; give a CRS");
  }
  // A zone is 6 degrees wide; beyond a few zones either side UTM's scale
  // error grows past what a terrain view should show.
  const double west = std::min(xs[1], xs[3]), east = std::max(xs[2], xs[4]);
  if (!(east - west <= 18.0) || std::max({std::abs(ys[1]), std::abs(ys[2]), std::abs(ys[3]), std::abs(ys[4])}) > 84.0) {
    char message[200];
    std::snprintf(message, sizeof message,
                  ": --t-srs auto picks one UTM zone, and the input spans %.1f degrees of longitude "
                  "(at most 18) or reaches past 84 degrees of latitude; give a CRS",
                  east - west);
    return Status::error(ErrorCode::kInvalidArgument, path + message);
  }
  const int zone = std::min(int(std::floor((x + 180.0) / 6.0)) + 1, 60);
  OSRImportFromEPSG(dst->h, (y >= 0 ? 32600 : 32700) + zone);
  OSRSetAxisMappingStrategy(dst->h, OAMS_TRADITIONAL_GIS_ORDER);
  return okStatus();
}

// The input reprojected by GDAL's warper, as gdalwarp would write it (same
// grid, same no-data handling), as a virtual dataset read block by block:
// nothing is held whole. An RGB input gains an alpha band, transparent
// where no input pixel lands.
Status warp(const std::string& path, GDALDatasetH src, const ImageReadOptions& read, GDALDatasetH* out,
            std::string* description, bool* alpha_added) {
  *out = nullptr;
  *alpha_added = false;
  Srs dst;
  bool keep = false;
  Status s = targetSrs(path, src, read.target_crs, &dst, &keep);
  if (!s) return s;
  OGRSpatialReferenceH from = sourceSrs(src);
  const bool gcps = GDALGetSpatialRef(src) == nullptr;
  if ((keep || OSRIsSame(from, dst.h)) && read.target_resolution <= 0 && !gcps) {
    *description = describeSrs(from) + (keep ? " kept (already projected; --t-srs auto reprojects "
                                               "geographic inputs only)"
                                             : " kept (the input is in it already)");
    return okStatus();
  }
  if (keep) {  // --t-res asked for in the input's own projected CRS
    OSRDestroySpatialReference(dst.h);
    dst.h = OSRClone(from);
  }
  char* wkt = nullptr;
  OSRExportToWkt(dst.h, &wkt);
  const std::string target_wkt = wkt != nullptr ? wkt : "";
  CPLFree(wkt);
  const uint64_t memory = std::clamp<uint64_t>(read.memory_budget_bytes / 8, uint64_t(16) << 20,
                                               uint64_t(256) << 20);
  std::vector<std::string> args = {"-of", "VRT", "-t_srs", target_wkt, "-r", read.resampling,
                                   "-wm", std::to_string(memory >> 20)};
  if (read.target_resolution > 0) {
    char res[64];
    std::snprintf(res, sizeof res, "%.17g", read.target_resolution);
    args.insert(args.end(), {"-tr", res, res});
  }
  // Where no input pixel lands: the input's no-data value if it has one;
  // else alpha for 8-bit images (every value is a colour), and for
  // heights a no-data value no sample holds, so the collar is filled like
  // any void rather than drawn as a cliff down to 0.
  const int bands = GDALGetRasterCount(src);
  GDALRasterBandH first = GDALGetRasterBand(src, 1);
  int has_nodata = 0;
  GDALGetRasterNoDataValue(first, &has_nodata);
  const GDALDataType type = GDALGetRasterDataType(first);
  const bool has_alpha = GDALGetRasterColorInterpretation(GDALGetRasterBand(src, bands)) == GCI_AlphaBand;
  if (!has_nodata && !has_alpha && GDALGetRasterColorTable(first) == nullptr) {
    if (bands == 1 && type == GDT_Int16) {
      args.insert(args.end(), {"-dstnodata", "-32768"});
    } else if (bands == 1 && (type == GDT_Float32 || type == GDT_Float64)) {
      args.insert(args.end(), {"-dstnodata", "nan"});
    } else if (bands == 1 || bands == 3) {
      args.push_back("-dstalpha");
      *alpha_added = true;
    }
  }
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  GDALWarpAppOptions* options = GDALWarpAppOptionsNew(argv.data(), nullptr);
  if (options == nullptr) return Status::error(ErrorCode::kInvalidArgument, "--t-srs: GDAL refused the warp options");
  int usage_error = 0;
  ErrorCollector errors;
  GDALDatasetH warped = GDALWarp("", nullptr, 1, &src, options, &usage_error);
  GDALWarpAppOptionsFree(options);
  if (warped == nullptr) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + ": cannot reproject to " + describeSrs(dst.h) + ": GDAL: " +
                             errors.message("the warp failed"));
  }
  *out = warped;
  *description = describeSrs(from) + " -> " + describeSrs(dst.h) + ", " + read.resampling;
  return okStatus();
}

// The subdatasets a container (HDF, NetCDF) lists instead of bands, for the
// error that asks for one.
std::string subdatasetList(GDALDatasetH ds) {
  char** md = GDALGetMetadata(ds, "SUBDATASETS");
  std::string list;
  int shown = 0, total = 0;
  for (char** p = md; p != nullptr && *p != nullptr; ++p) {
    const std::string entry = *p;
    const size_t eq = entry.find('=');
    if (eq == std::string::npos || entry.find("_NAME=") == std::string::npos) continue;
    ++total;
    if (shown < 8) {
      list += (shown == 0 ? " " : ", ") + entry.substr(eq + 1);
      ++shown;
    }
  }
  if (total > shown) list += " and " + std::to_string(total - shown) + " more";
  return list;
}

// The file opened (and, for --t-srs, the warped dataset over it: *ds
// then reads *underlying).
struct Opened {
  DatasetCloser underlying;  // closed after the warped dataset over it: declared first
  DatasetCloser ds;
  std::string reprojection;
  bool alpha_added = false;
};

Status openDataset(const std::string& path, const ImageReadOptions& read, Opened* out) {
  ErrorCollector errors;
  const std::string name = gdalName(path);
  const bool remote = startsWith(name, "/vsicurl") || startsWith(name, "/vsis3") ||
                      startsWith(name, "/vsigs") || startsWith(name, "/vsiaz") || startsWith(name, "/vsiadls") ||
                      startsWith(name, "/vsioss") || startsWith(name, "/vsiswift");
  // A remote file's folder is not listed for side-car files: one request
  // saved, and servers that refuse listings do not fail the open.
  if (remote) CPLSetThreadLocalConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", "EMPTY_DIR");
  // Drivers read their decode threads at open (GTiff's NUM_THREADS).
  const std::string threads = read.decode_threads == 0 ? "ALL_CPUS" : std::to_string(read.decode_threads);
  CPLSetThreadLocalConfigOption("GDAL_NUM_THREADS", threads.c_str());
  out->ds.ds = GDALOpenEx(name.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR, nullptr,
                          nullptr, nullptr);
  CPLSetThreadLocalConfigOption("GDAL_NUM_THREADS", nullptr);
  if (remote) CPLSetThreadLocalConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", nullptr);
  if (out->ds.ds == nullptr) {
    return Status::error(ErrorCode::kIo,
                         path + ": cannot open image: GDAL: " + errors.message("not a raster GDAL can read"));
  }
  if (read.target_crs.empty() || GDALGetRasterCount(out->ds.ds) == 0) return okStatus();
  GDALDatasetH warped = nullptr;
  Status w = warp(path, out->ds.ds, read, &warped, &out->reprojection, &out->alpha_added);
  if (!w) return w;
  if (warped != nullptr) {
    out->underlying.ds = out->ds.ds;
    out->ds.ds = warped;
  }
  return okStatus();
}

// How the bands are read: their sample kind, the type RasterIO converts
// to, a name for the summary, the channels delivered, and the palette of
// a paletted band (which becomes RGB, or RGBA when an entry is not opaque).
struct BandLayout {
  SampleKind kind = SampleKind::kU8;
  GDALDataType read_type = GDT_Byte;
  std::string type_name;
  uint32_t channels = 0;
  std::vector<std::array<uint8_t, 4>> palette;
};

Status bandLayout(const std::string& path, GDALDatasetH ds, BandLayout* out) {
  const int bands = GDALGetRasterCount(ds);
  if (bands == 0) {
    const std::string subdatasets = subdatasetList(ds);
    if (!subdatasets.empty()) {
      return Status::error(ErrorCode::kUnsupported,
                           path + ": holds several rasters; name one as the input:" + subdatasets);
    }
    return Status::error(ErrorCode::kUnsupported, path + ": GDAL finds no raster band in it");
  }
  GDALRasterBandH first = GDALGetRasterBand(ds, 1);
  const GDALDataType type = GDALGetRasterDataType(first);
  for (int b = 2; b <= bands; ++b) {
    if (GDALGetRasterDataType(GDALGetRasterBand(ds, b)) != type) {
      return Status::error(ErrorCode::kUnsupported,
                           path + ": its bands hold different sample types; make them one "
                                  "(gdal_translate -ot)");
    }
  }
  GDALColorTableH table = GDALGetRasterColorTable(first);
  if (bands == 1 && table != nullptr && GDALGetRasterColorInterpretation(first) == GCI_PaletteIndex &&
      (type == GDT_Byte || type == GDT_UInt16) && GDALGetPaletteInterpretation(table) == GPI_RGB) {
    const int entries = GDALGetColorEntryCount(table);
    out->palette.resize(size_t(std::max(entries, 0)));
    for (int i = 0; i < entries; ++i) {
      const GDALColorEntry* c = GDALGetColorEntry(table, i);
      auto clamp = [](short v) { return uint8_t(std::clamp<int>(v, 0, 255)); };
      out->palette[size_t(i)] = {clamp(c->c1), clamp(c->c2), clamp(c->c3), clamp(c->c4)};
    }
  }
  const bool translucent =
      std::any_of(out->palette.begin(), out->palette.end(), [](const auto& c) { return c[3] != 255; });
  out->channels = out->palette.empty() ? uint32_t(bands) : translucent ? 4u : 3u;
  if (out->channels > 4) {
    return Status::error(ErrorCode::kUnsupported,
                         path + ": " + std::to_string(bands) +
                             " bands; only 1 (grey), 2 (grey+alpha), 3 (RGB), 4 (RGBA) are supported "
                             "(pick bands with gdal_translate -b or a VRT)");
  }
  switch (type) {
    case GDT_Byte: out->kind = SampleKind::kU8, out->read_type = GDT_Byte, out->type_name = "uint8"; break;
    case GDT_UInt16: out->kind = SampleKind::kU16, out->read_type = GDT_UInt16, out->type_name = "uint16"; break;
    case GDT_Int16: out->kind = SampleKind::kI16, out->read_type = GDT_Int16, out->type_name = "int16"; break;
    case GDT_UInt32: out->kind = SampleKind::kF32, out->read_type = GDT_Float32, out->type_name = "uint32"; break;
    case GDT_Int32: out->kind = SampleKind::kF32, out->read_type = GDT_Float32, out->type_name = "int32"; break;
    case GDT_Float32: out->kind = SampleKind::kF32, out->read_type = GDT_Float32, out->type_name = "float"; break;
    case GDT_Float64: out->kind = SampleKind::kF32, out->read_type = GDT_Float32, out->type_name = "double"; break;
    default:
      return Status::error(ErrorCode::kUnsupported,
                           path + ": sample type " + GDALGetDataTypeName(type) +
                               " is not supported (8/16/32-bit integers and 32/64-bit floats are)");
  }
  if (!out->palette.empty()) {
    out->kind = SampleKind::kU8;
    out->read_type = GDT_UInt16;  // the indices; expanded to bytes per row
    out->type_name = "uint8 palette";
  }
  return okStatus();
}

// What GDAL says of where the data lies and what its samples mean.
void readMetadata(const std::string& path, GDALDatasetH ds, SourceInfo* info) {
  SourceMetadata& meta = info->metadata;
  meta.present = true;
  double gt[6];
  if (GDALGetGeoTransform(ds, gt) == CE_None && !(gt[0] == 0 && gt[1] == 1 && gt[2] == 0 && gt[3] == 0 &&
                                                  gt[4] == 0 && gt[5] == 1)) {
    meta.geo.present = true;
    std::copy(gt, gt + 6, meta.geo.transform);
    meta.geo.crs = crsText(ds);
  } else if (GDALGetGCPCount(ds) > 0) {
    info->warnings.push_back(path + ": placed by ground control points, which the tiler does not use "
                                    "as they are; it is tiled without a georeference (--t-srs warps by them)");
  }
  GDALRasterBandH first = GDALGetRasterBand(ds, 1);
  int has_nodata = 0;
  const double nodata = GDALGetRasterNoDataValue(first, &has_nodata);
  meta.has_nodata = has_nodata != 0;
  meta.nodata = nodata;
  meta.units = heightUnitsFromText(GDALGetRasterUnitType(first));
}

Status openGdal(const std::string& path, std::optional<PixelFormat> forced, const ImageReadOptions& read,
                std::unique_ptr<ImageSource>* out) {
  out->reset();
  initialiseGdal(read.memory_budget_bytes);
  Opened opened;
  Status s = openDataset(path, read, &opened);
  if (!s) return s;
  GDALDatasetH ds = opened.ds.ds;
  BandLayout layout;
  s = bandLayout(path, ds, &layout);
  if (!s) return s;
  const int width = GDALGetRasterXSize(ds), height = GDALGetRasterYSize(ds);
  if (width <= 0 || height <= 0) {
    return Status::error(ErrorCode::kInvalidArgument, path + ": image size " + std::to_string(width) + "x" +
                                                          std::to_string(height) + " is empty");
  }
  SourceInfo info;
  info.width_px = uint64_t(width);
  info.height_px = uint64_t(height);
  info.input_channels = layout.channels;
  info.input_type = layout.type_name;
  GDALDatasetH file = opened.underlying.ds != nullptr ? opened.underlying.ds : ds;
  GDALDriverH driver = GDALGetDatasetDriver(file);
  info.decoder = std::string("gdal ") + (driver != nullptr ? GDALGetDriverShortName(driver) : "?") +
                 (opened.underlying.ds != nullptr ? ", warped" : "");
  int block_w = 0, block_h = 0;
  GDALGetBlockSize(GDALGetRasterBand(ds, 1), &block_w, &block_h);
  info.tiled = block_w < width;
  info.sequential_only = false;
  VSIStatBufL st;
  if (VSIStatL(gdalName(path).c_str(), &st) == 0 && VSI_ISREG(st.st_mode)) info.file_bytes = uint64_t(st.st_size);
  info.format = forced ? *forced : defaultFormat(layout.channels, layout.kind);
  readMetadata(path, ds, &info);
  info.reprojection = opened.reprojection;
  auto source = std::make_unique<GdalSource>(path, ds, opened.underlying.ds, std::move(info), layout.kind,
                                             layout.read_type, std::move(layout.palette));
  source->setPremultiply(opened.alpha_added);
  *out = std::move(source);
  opened.ds.ds = opened.underlying.ds = nullptr;  // the source owns them now
  return okStatus();
}

}  // namespace
}  // namespace clipstream

extern "C" __attribute__((visibility("default"))) void clipstreamTilerOpenGdal(
    const std::string* path, const std::optional<clipstream::PixelFormat>* forced,
    const clipstream::ImageReadOptions* read, std::unique_ptr<clipstream::ImageSource>* out,
    clipstream::Status* status) {
  *status = clipstream::openGdal(*path, *forced, *read, out);
}
