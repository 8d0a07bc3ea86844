// GeoTIFF tags: the georeference (ModelPixelScale, ModelTiepoint,
// ModelTransformation and the GeoKeyDirectory) and GDAL's no-data and unit
// tags of a TIFF's first IFD, parsed from its bytes (OpenImageIO 2.4 does
// not report them as metadata). Every offset and count is checked against
// the file size. One parser for the tiler's inputs (georef.h) and the
// Cloud-Optimized GeoTIFFs the streamer reads directly (cog.h).
#include <clipstream/store/geotiff.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

namespace clipstream {
namespace {

constexpr uint16_t kTagModelPixelScale = 33550;
constexpr uint16_t kTagModelTiepoint = 33922;
constexpr uint16_t kTagModelTransformation = 34264;
constexpr uint16_t kTagGeoKeyDirectory = 34735;
constexpr uint16_t kTagGdalMetadata = 42112;  // GDAL's XML metadata (ASCII)
constexpr uint16_t kTagGdalNodata = 42113;    // GDAL's no-data value (ASCII)
constexpr uint16_t kKeyVerticalUnits = 4099;
constexpr uint64_t kMaxAsciiTagBytes = 1u << 20;
constexpr uint16_t kKeyModelType = 1024;
constexpr uint16_t kKeyRasterType = 1025;
constexpr uint16_t kKeyGeographicType = 2048;
constexpr uint16_t kKeyProjectedCsType = 3072;
constexpr uint16_t kUserDefined = 32767;
constexpr uint64_t kMaxTagValues = 1u << 16;  // far beyond any real GeoTIFF tag

class TiffBytes {
 public:
  TiffBytes(const TiffByteReader& read, uint64_t size, bool big_endian)
      : m_read(read), m_size(size), m_be(big_endian) {}

  bool read(uint64_t offset, void* dst, size_t n) {
    if (offset > m_size || n > m_size - offset) return false;
    return m_read(offset, dst, n);
  }
  uint64_t decode(const uint8_t* p, int n) const {
    uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= uint64_t(p[m_be ? n - 1 - i : i]) << (8 * i);
    return v;
  }
  double decodeDouble(const uint8_t* p) const {
    const uint64_t bits = decode(p, 8);
    double d;
    std::memcpy(&d, &bits, 8);
    return d;
  }

 private:
  const TiffByteReader& m_read;
  uint64_t m_size;
  bool m_be;
};

Status bad(const std::string& path, const std::string& what) {
  return Status::error(ErrorCode::kBadHeader, path + ": malformed GeoTIFF tags: " + what);
}

// Heights' unit from an EPSG linear unit code (GDAL's UNITTYPE text: heightUnitsFromText()).
std::optional<HeightUnits> unitsFromEpsg(uint32_t code) {
  if (code == 9001) return HeightUnits::kMetre;
  if (code == 9002) return HeightUnits::kFoot;
  if (code == 9003) return HeightUnits::kUsSurveyFoot;
  return std::nullopt;
}

// The UNITTYPE item of GDAL's metadata XML (band 0), if any.
std::string gdalUnitType(const std::string& xml) {
  const std::string role = "role=\"unittype\"";
  const size_t at = xml.find(role);
  if (at == std::string::npos) return {};
  const size_t open = xml.find('>', at);
  const size_t close = xml.find('<', open == std::string::npos ? at : open);
  if (open == std::string::npos || close == std::string::npos) return {};
  return xml.substr(open + 1, close - open - 1);
}

// The first IFD's entry table, as read by readFirstIfd().
struct IfdTable {
  bool tiff = false;        // false: the file is no TIFF, so it has no tags
  bool big_endian = false;  // "MM" byte order
  bool big = false;         // BigTIFF: 8-byte counts and offsets, 20-byte entries
  uint64_t entries = 0;
  std::vector<uint8_t> bytes;  // entries * entry size

  size_t entrySize() const { return big ? 20 : 12; }
};

// Reads the header and the first IFD's entry table. A file that is not a
// TIFF is no error: table->tiff stays false.
Status readFirstIfd(const std::string& path, const TiffByteReader& read, uint64_t size,
                    IfdTable* table) {
  uint8_t head[16] = {};
  const size_t head_bytes = size_t(std::min<uint64_t>(size, 16));
  if (head_bytes < 8) return okStatus();  // too short for a TIFF: no tags
  if (!read(0, head, head_bytes)) return Status::error(ErrorCode::kIo, path + ": cannot read header");
  bool be;
  if (head[0] == 'I' && head[1] == 'I') {
    be = false;
  } else if (head[0] == 'M' && head[1] == 'M') {
    be = true;
  } else {
    return okStatus();  // not a TIFF: no tags
  }
  TiffBytes tb(read, size, be);
  const uint64_t magic = tb.decode(head + 2, 2);
  const bool big = magic == 43;
  if (magic != 42 && !big) return okStatus();
  table->tiff = true;
  table->big_endian = be;
  table->big = big;
  const uint64_t ifd = big ? tb.decode(head + 8, 8) : tb.decode(head + 4, 4);
  uint8_t count_bytes[8];
  if (!tb.read(ifd, count_bytes, big ? 8 : 2)) return bad(path, "first IFD offset past end of file");
  table->entries = tb.decode(count_bytes, big ? 8 : 2);
  if (table->entries > 4096) return bad(path, "IFD entry count " + std::to_string(table->entries));
  table->bytes.resize(table->entries * table->entrySize());
  if (!tb.read(ifd + (big ? 8 : 2), table->bytes.data(), table->bytes.size())) {
    return bad(path, "IFD truncated");
  }
  return okStatus();
}

// The values of the georeferencing tags, as the file stores them.
struct GeoTagValues {
  std::vector<double> scale, tiepoint, matrix;
  std::vector<uint16_t> keys;  // the GeoKeyDirectory
};

// GDAL's metadata or no-data tag (ASCII) at entry `e`, into `elevation`. A
// malformed one is ignored: it only adds information.
void readGdalTag(TiffBytes& tb, const uint8_t* e, bool big, uint16_t tag, uint16_t type,
                 uint64_t count, ElevationTags* elevation) {
  if (type != 2 || count == 0 || count > kMaxAsciiTagBytes) return;
  std::string text(count, '\0');
  const size_t inline_bytes = big ? 8 : 4;
  if (count <= inline_bytes) {
    std::memcpy(text.data(), e + (big ? 12 : 8), count);
  } else if (!tb.read(big ? tb.decode(e + 12, 8) : tb.decode(e + 8, 4), text.data(), count)) {
    return;
  }
  text.resize(std::strlen(text.c_str()));
  if (tag == kTagGdalNodata) {
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (end != text.c_str()) {
      elevation->has_nodata = true;
      elevation->nodata = v;  // may be nan, as GDAL writes it
    }
  } else if (auto units = heightUnitsFromText(gdalUnitType(text))) {
    elevation->units = units;
  }
}

// A GeoTIFF tag (DOUBLE values, or SHORT for the key directory) at entry
// `e`, appended to its vector of `values`.
Status readGeoTag(const std::string& path, TiffBytes& tb, const uint8_t* e, bool big, uint16_t tag,
                  uint16_t type, uint64_t count, GeoTagValues* values) {
  const int elem = type == 12 ? 8 : type == 3 ? 2 : 0;  // DOUBLE or SHORT
  if (elem == 0 || count == 0 || count > kMaxTagValues) {
    return bad(path, "tag " + std::to_string(tag) + " has type " + std::to_string(type) +
                         " and count " + std::to_string(count));
  }
  std::vector<uint8_t> bytes(count * elem);
  const size_t inline_bytes = big ? 8 : 4;
  if (bytes.size() <= inline_bytes) {
    std::memcpy(bytes.data(), e + (big ? 12 : 8), bytes.size());
  } else {
    const uint64_t off = big ? tb.decode(e + 12, 8) : tb.decode(e + 8, 4);
    if (!tb.read(off, bytes.data(), bytes.size())) {
      return bad(path, "tag " + std::to_string(tag) + " values lie past the end of the file");
    }
  }
  if (tag == kTagGeoKeyDirectory) {
    if (type != 3) return bad(path, "GeoKeyDirectory is not SHORT");
    for (uint64_t k = 0; k < count; ++k) values->keys.push_back(uint16_t(tb.decode(bytes.data() + 2 * k, 2)));
  } else {
    if (type != 12) return bad(path, "tag " + std::to_string(tag) + " is not DOUBLE");
    std::vector<double>& dst = tag == kTagModelPixelScale ? values->scale
                               : tag == kTagModelTiepoint ? values->tiepoint
                                                          : values->matrix;
    for (uint64_t k = 0; k < count; ++k) dst.push_back(tb.decodeDouble(bytes.data() + 8 * k));
  }
  return okStatus();
}

// Walks the IFD's entries: GDAL's tags go into `elevation`, the GeoTIFF
// tags into `values`; other tags are skipped.
Status readTags(const std::string& path, TiffBytes& tb, const IfdTable& table,
                ElevationTags* elevation, GeoTagValues* values) {
  const bool big = table.big;
  for (uint64_t i = 0; i < table.entries; ++i) {
    const uint8_t* e = table.bytes.data() + i * table.entrySize();
    const uint16_t tag = uint16_t(tb.decode(e, 2));
    if (tag != kTagModelPixelScale && tag != kTagModelTiepoint && tag != kTagModelTransformation &&
        tag != kTagGeoKeyDirectory && tag != kTagGdalMetadata && tag != kTagGdalNodata) {
      continue;
    }
    const uint16_t type = uint16_t(tb.decode(e + 2, 2));
    const uint64_t count = big ? tb.decode(e + 4, 8) : tb.decode(e + 4, 4);
    if (tag == kTagGdalMetadata || tag == kTagGdalNodata) {
      readGdalTag(tb, e, big, tag, type, count, elevation);
      continue;
    }
    if (Status s = readGeoTag(path, tb, e, big, tag, type, count, values); !s) return s;
  }
  return okStatus();
}

// The GeoKeys this parser uses, with GeoTIFF's defaults.
struct GeoKeys {
  uint32_t model_type = 0, raster_type = 1, projected = 0, geographic = 0;
};

// GeoKeys: header (version, revision, minor, count) then 4 shorts per key;
// only keys stored inline (location 0) are needed here. The vertical units
// key goes into `elevation`.
Status readGeoKeys(const std::string& path, const std::vector<uint16_t>& keys, GeoKeys* out,
                   ElevationTags* elevation) {
  if (keys.size() < 4) return okStatus();
  const uint64_t nkeys = keys[3];
  if (4 + nkeys * 4 > keys.size()) return bad(path, "GeoKeyDirectory shorter than its key count");
  for (uint64_t k = 0; k < nkeys; ++k) {
    const uint16_t* key = &keys[4 + k * 4];
    if (key[1] != 0 || key[2] != 1) continue;
    if (key[0] == kKeyModelType) out->model_type = key[3];
    if (key[0] == kKeyRasterType) out->raster_type = key[3];
    if (key[0] == kKeyProjectedCsType) out->projected = key[3];
    if (key[0] == kKeyGeographicType) out->geographic = key[3];
    if (key[0] == kKeyVerticalUnits) {
      if (auto units = unitsFromEpsg(key[3])) elevation->units = units;
    }
  }
  return okStatus();
}

// The pixel-to-world transform the tags give (a matrix, else a pixel scale
// and a tie point), moved to the pixel corner for PixelIsPoint rasters.
// Returns false when the file has neither.
bool transformOf(const GeoTagValues& v, const GeoKeys& keys, double t[6]) {
  if (v.matrix.size() >= 16) {
    t[0] = v.matrix[3], t[1] = v.matrix[0], t[2] = v.matrix[1];
    t[3] = v.matrix[7], t[4] = v.matrix[4], t[5] = v.matrix[5];
  } else if (v.scale.size() >= 2 && v.tiepoint.size() >= 6) {
    const double i = v.tiepoint[0], j = v.tiepoint[1], x = v.tiepoint[3], y = v.tiepoint[4];
    t[1] = v.scale[0];
    t[5] = -v.scale[1];
    t[0] = x - i * v.scale[0];
    t[3] = y + j * v.scale[1];
  } else {
    return false;  // no transform tags
  }
  if (keys.raster_type == 2) {
    // PixelIsPoint: tie points name pixel centres; move to the corner as GDAL does.
    t[0] -= 0.5 * t[1] + 0.5 * t[2];
    t[3] -= 0.5 * t[4] + 0.5 * t[5];
  }
  return true;
}

}  // namespace

Status parseGeoTiffTags(const std::string& name, uint64_t size, const TiffByteReader& read,
                        GeoReference* out, ElevationTags* elevation) {
  *out = GeoReference{};
  *elevation = ElevationTags{};
  IfdTable table;
  if (Status s = readFirstIfd(name, read, size, &table); !s || !table.tiff) return s;
  TiffBytes tb(read, size, table.big_endian);
  GeoTagValues values;
  if (Status s = readTags(name, tb, table, elevation, &values); !s) return s;
  GeoKeys keys;
  if (Status s = readGeoKeys(name, values.keys, &keys, elevation); !s) return s;

  double t[6] = {0, 1, 0, 0, 0, 1};
  if (!transformOf(values, keys, t)) return okStatus();
  out->present = true;
  std::memcpy(out->transform, t, sizeof(t));
  if (keys.model_type == 1 && keys.projected != 0 && keys.projected != kUserDefined) {
    out->crs = "EPSG:" + std::to_string(keys.projected);
  } else if (keys.model_type == 2 && keys.geographic != 0 && keys.geographic != kUserDefined) {
    out->crs = "EPSG:" + std::to_string(keys.geographic);
  }
  return okStatus();
}

}  // namespace clipstream
