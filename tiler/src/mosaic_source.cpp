// A mosaic of georeferenced sheets as one ImageSource (mosaic.h): each read
// fills the requested rectangle with the gap value, then copies in, in list
// order, the part of every sheet that intersects it (so later sheets win).
// Sheets are opened on first use and closed once reads have passed below
// them, so memory follows the sheets under one strip, not the whole list.
#include <clipstream/tiler/mosaic.h>

#include <clipstream/tiler/georef.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <optional>
#include <sstream>

#include <libxml/parser.h>
#include <libxml/tree.h>
#include <sys/stat.h>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

// How far from a whole pixel a sheet's offset may be (rounding in world
// files written with 10 digits is far below this).
constexpr double kGridTolerancePx = 0.01;
// How much pixel sizes may differ, relative (the same rounding).
constexpr double kPixelSizeTolerance = 1e-9;

struct Sheet {
  std::string path;
  uint64_t x0 = 0, y0 = 0;  // in the mosaic
  uint64_t width = 0, height = 0;
  std::unique_ptr<ImageSource> source;  // open only while strips need it
};

std::string pixelSizeText(const GeoReference& g) {
  std::ostringstream ss;
  ss.precision(12);
  ss << "(" << g.transform[1] << ", " << g.transform[5] << ")";
  return ss.str();
}

bool samePixelSize(double a, double b) {
  return std::fabs(a - b) <= kPixelSizeTolerance * std::max(std::fabs(a), std::fabs(b));
}

// Pixels of [0, w) x [0, h) that no sheet covers: a sweep over the sheets'
// row edges, with the union of their column spans in each slab.
uint64_t gapPixels(const std::vector<Sheet>& sheets, uint64_t w, uint64_t h) {
  std::vector<uint64_t> ys;
  for (const Sheet& s : sheets) {
    ys.push_back(s.y0);
    ys.push_back(s.y0 + s.height);
  }
  std::sort(ys.begin(), ys.end());
  ys.erase(std::unique(ys.begin(), ys.end()), ys.end());
  uint64_t covered = 0;
  std::vector<std::pair<uint64_t, uint64_t>> spans;
  for (size_t i = 0; i + 1 < ys.size(); ++i) {
    spans.clear();
    for (const Sheet& s : sheets) {
      if (s.y0 <= ys[i] && s.y0 + s.height >= ys[i + 1]) spans.emplace_back(s.x0, s.x0 + s.width);
    }
    std::sort(spans.begin(), spans.end());
    uint64_t run_end = 0, width = 0;
    for (const auto& [a, b] : spans) {
      const uint64_t from = std::max(a, run_end);
      if (b > from) width += b - from;
      run_end = std::max(run_end, b);
    }
    covered += width * (ys[i + 1] - ys[i]);
  }
  return w * h - covered;
}

class MosaicSource final : public ImageSource {
 public:
  MosaicSource(std::vector<Sheet> sheets, SourceInfo info, PixelFormat format,
               std::vector<uint8_t> fill_pixel, const ImageReadOptions& read)
      : m_sheets(std::move(sheets)), m_info(std::move(info)), m_format(format),
        m_fill(std::move(fill_pixel)), m_read(read) {}

  const SourceInfo& info() const override {
    uint64_t clamped = m_closed_clamped;
    for (const Sheet& s : m_sheets) {
      if (s.source) clamped += s.source->info().clamped_samples;
    }
    m_info.clamped_samples = clamped;
    return m_info;
  }

  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    const size_t bpp = m_fill.size();
    for (uint32_t r = 0; r < rows; ++r) {
      uint8_t* row = dst + size_t(r) * dst_stride;
      for (uint64_t x = 0; x < width; ++x) std::memcpy(row + x * bpp, m_fill.data(), bpp);
    }
    const uint64_t y1 = y0 + rows, x1 = x0 + width;
    for (Sheet& s : m_sheets) {
      // Reads go down the image (a panel column at a time): a sheet whose
      // last row is above this read is not needed until the next panel
      // column comes back up, if ever.
      if (s.source && s.y0 + s.height <= y0) close(s);
      const uint64_t ix0 = std::max(x0, s.x0), ix1 = std::min(x1, s.x0 + s.width);
      const uint64_t iy0 = std::max(y0, s.y0), iy1 = std::min(y1, s.y0 + s.height);
      if (ix0 >= ix1 || iy0 >= iy1) continue;
      if (!s.source) {
        Status st = openImageFile(s.path, m_format, &s.source, m_read);
        if (!st) return st;
      }
      Status st = s.source->readRows(iy0 - s.y0, uint32_t(iy1 - iy0), ix0 - s.x0, ix1 - ix0,
                                     dst + size_t(iy0 - y0) * dst_stride + (ix0 - x0) * bpp,
                                     dst_stride);
      if (!st) return st;
      if (iy1 == s.y0 + s.height && ix1 == s.x0 + s.width) {
        // This read reached the sheet's last row and column: strips after
        // it lie below.
        close(s);
      }
    }
    return okStatus();
  }

 private:
  void close(Sheet& s) {
    m_closed_clamped += s.source->info().clamped_samples;
    s.source.reset();
  }

  std::vector<Sheet> m_sheets;
  mutable SourceInfo m_info;
  PixelFormat m_format;
  std::vector<uint8_t> m_fill;  // one pixel of the gap value
  ImageReadOptions m_read;
  uint64_t m_closed_clamped = 0;
};

// One sheet as the list names it. A VRT source also says which part of the
// file it uses and how large it is drawn, which must be all of it, unscaled.
struct ListEntry {
  std::string path;
  size_t line = 0;
  bool has_rects = false;
  double src[4] = {0, 0, 0, 0};  // SrcRect xOff, yOff, xSize, ySize
  double dst[2] = {0, 0};        // DstRect xSize, ySize
};

// A libxml2 element's text content, trimmed, and attributes.
std::string textOf(xmlNode* n) {
  xmlChar* c = xmlNodeGetContent(n);
  std::string t = c != nullptr ? reinterpret_cast<const char*>(c) : "";
  xmlFree(c);
  const size_t a = t.find_first_not_of(" \t\r\n"), b = t.find_last_not_of(" \t\r\n");
  return a == std::string::npos ? std::string() : t.substr(a, b - a + 1);
}
std::optional<std::string> attributeOf(xmlNode* n, const char* name) {
  xmlChar* v = xmlGetProp(n, reinterpret_cast<const xmlChar*>(name));
  if (v == nullptr) return std::nullopt;
  std::string t = reinterpret_cast<const char*>(v);
  xmlFree(v);
  return t;
}
bool named(xmlNode* n, const char* name) {
  return n->type == XML_ELEMENT_NODE && xmlStrcmp(n->name, reinterpret_cast<const xmlChar*>(name)) == 0;
}
std::string nameOf(xmlNode* n) { return reinterpret_cast<const char*>(n->name); }

// The sheets of a GDAL VRT of simple sources: each band's <SimpleSource>s,
// which must name the same files in every band, each file's band n feeding
// band n. Anything a VRT can do beyond placing whole files (other source
// kinds, derived bands, band reordering, cropping, scaling) is refused,
// naming its line. Parsed by libxml2: a malformed file is an error naming
// libxml2's first complaint and its line; no network, no external entities.
Status parseVrt(const std::string& path, const std::string& text, std::vector<ListEntry>* out) {
  const fs::path dir = fs::path(path).parent_path();
  auto refuse = [&](xmlNode* at, const std::string& what) {
    return Status::error(ErrorCode::kUnsupported,
                         path + " line " + std::to_string(xmlGetLineNo(at)) + ": " + what +
                             "; a mosaic takes a VRT of whole sheets (SimpleSource), else a list "
                             "file of the sheets");
  };
  auto malformed = [&](long line, const std::string& what) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + (line > 0 ? " line " + std::to_string(line) : std::string()) +
                             ": not a well-formed VRT: " + what);
  };
  if (text.size() > size_t(INT32_MAX)) return malformed(0, "too large");
  std::unique_ptr<xmlParserCtxt, void (*)(xmlParserCtxtPtr)> ctxt(xmlNewParserCtxt(), xmlFreeParserCtxt);
  if (!ctxt) return Status::error(ErrorCode::kOutOfMemory, path + ": cannot parse the VRT");
  // NONET: never fetch a DTD or entity from the network; entities are not
  // substituted (no XML_PARSE_NOENT), so none is read from a file either.
  std::unique_ptr<xmlDoc, void (*)(xmlDocPtr)> doc(
      xmlCtxtReadMemory(ctxt.get(), text.data(), int(text.size()), path.c_str(), nullptr,
                        XML_PARSE_NONET | XML_PARSE_NOERROR | XML_PARSE_NOWARNING),
      xmlFreeDoc);
  if (!doc || !ctxt->wellFormed) {
    const xmlError* e = xmlCtxtGetLastError(ctxt.get());
    std::string why = e != nullptr && e->message != nullptr ? e->message : "libxml2 cannot parse it";
    while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
    return malformed(e != nullptr ? e->line : 0, why);
  }
  xmlNode* root = xmlDocGetRootElement(doc.get());
  if (root == nullptr || !named(root, "VRTDataset")) {
    return malformed(root != nullptr ? xmlGetLineNo(root) : 0,
                     "the root element is <" + (root != nullptr ? nameOf(root) : std::string()) +
                         ">, not <VRTDataset>");
  }
  std::vector<ListEntry> first_band;
  uint32_t band = 0;
  for (xmlNode* b = root->children; b != nullptr; b = b->next) {
    if (!named(b, "VRTRasterBand")) continue;
    ++band;
    if (const auto sub = attributeOf(b, "subClass")) return refuse(b, "a " + *sub + " band");
    std::vector<ListEntry> sources;
    for (xmlNode* src = b->children; src != nullptr; src = src->next) {
      if (src->type != XML_ELEMENT_NODE) continue;
      const std::string kind = nameOf(src);
      if (kind.size() > 6 && kind.compare(kind.size() - 6, 6, "Source") == 0 && kind != "SimpleSource") {
        return refuse(src, kind + " is not a simple source");
      }
      if (kind != "SimpleSource") continue;  // ColorInterp, NoDataValue, ...: the sheets say
      ListEntry e;
      e.line = size_t(std::max(1L, xmlGetLineNo(src)));
      xmlNode *name = nullptr, *source_band = nullptr, *sr = nullptr, *dr = nullptr;
      for (xmlNode* c = src->children; c != nullptr; c = c->next) {
        if (named(c, "SourceFilename")) name = c;
        if (named(c, "SourceBand")) source_band = c;
        if (named(c, "SrcRect")) sr = c;
        if (named(c, "DstRect")) dr = c;
      }
      if (name == nullptr || textOf(name).empty()) return refuse(src, "a SimpleSource without a SourceFilename");
      const fs::path file(textOf(name));
      e.path = attributeOf(name, "relativeToVRT").value_or("0") == "1" && !file.is_absolute() && !dir.empty()
                   ? (dir / file).string()
                   : file.string();
      const std::string reads = source_band != nullptr ? textOf(source_band) : "1";
      if (reads != std::to_string(band)) {
        return refuse(src, "band " + std::to_string(band) + " reads band " + reads + " of " + e.path);
      }
      if (sr != nullptr && dr != nullptr) {
        auto number = [&](xmlNode* rect, const char* key, double* v) {
          const std::string t = attributeOf(rect, key).value_or("");
          char* end = nullptr;
          *v = std::strtod(t.c_str(), &end);
          return !t.empty() && end != nullptr && *end == '\0' && std::isfinite(*v);
        };
        const char* keys[] = {"xOff", "yOff", "xSize", "ySize"};
        for (int i = 0; i < 4; ++i) {
          if (!number(sr, keys[i], &e.src[i])) return refuse(sr, std::string("a SrcRect without a number ") + keys[i]);
        }
        if (!number(dr, "xSize", &e.dst[0]) || !number(dr, "ySize", &e.dst[1])) {
          return refuse(dr, "a DstRect without a number xSize and ySize");
        }
        e.has_rects = true;
      }
      sources.push_back(std::move(e));
    }
    if (band == 1) {
      first_band = std::move(sources);
    } else {
      bool same = sources.size() == first_band.size();
      for (size_t i = 0; same && i < sources.size(); ++i) same = sources[i].path == first_band[i].path;
      if (!same) return refuse(b, "band " + std::to_string(band) + " has other sources than band 1");
    }
  }
  *out = std::move(first_band);
  return okStatus();
}

Status readList(const std::string& list_path, std::vector<ListEntry>* out) {
  struct stat st{};
  if (::stat(list_path.c_str(), &st) != 0) {
    return Status::error(errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                         list_path + ": " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) {
    return Status::error(ErrorCode::kIo, list_path + ": the mosaic list is not a regular file");
  }
  if (uint64_t(st.st_size) > kMaxMosaicListBytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         list_path + ": a mosaic list larger than " +
                             std::to_string(kMaxMosaicListBytes >> 20) + " MB");
  }
  std::ifstream in(list_path, std::ios::binary);
  if (!in) return Status::error(ErrorCode::kIo, list_path + ": cannot open the mosaic list");
  const fs::path dir = fs::path(list_path).parent_path();
  {
    std::string text((std::istreambuf_iterator<char>(in)), {});
    if (in.bad()) return Status::error(ErrorCode::kIo, list_path + ": read failed");
    // XML (a VRT) starts with '<' after an optional UTF-8 byte order mark and
    // blanks (a declaration, a comment or the element); a list line is a path.
    size_t start = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
    start = text.find_first_not_of(" \t\r\n", start);
    if (start != std::string::npos && text[start] == '<') {
      Status s = parseVrt(list_path, text, out);
      if (!s) return s;
      if (out->empty()) {
        return Status::error(ErrorCode::kInvalidArgument,
                             list_path + ": the VRT has no SimpleSource, so no sheets");
      }
      return okStatus();
    }
    in.clear();
    in.seekg(0);
  }
  std::string line;
  size_t number = 0;
  while (std::getline(in, line)) {
    ++number;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) {
      line.pop_back();
    }
    size_t start = line.find_first_not_of(" \t");
    if (start == std::string::npos || line[start] == '#') continue;
    line = line.substr(start);
    if (line.find('\0') != std::string::npos) {
      return Status::error(ErrorCode::kInvalidArgument,
                           list_path + " line " + std::to_string(number) +
                               ": not a path (a NUL byte); is this a list of image paths?");
    }
    const fs::path p(line);
    ListEntry e;
    e.path = p.is_absolute() || dir.empty() ? p.string() : (dir / p).string();
    e.line = number;
    out->push_back(std::move(e));
  }
  if (in.bad()) return Status::error(ErrorCode::kIo, list_path + ": read failed");
  if (out->empty()) {
    return Status::error(ErrorCode::kInvalidArgument,
                         list_path + ": the mosaic list names no sheets (one image path a line)");
  }
  return okStatus();
}

// The gap pixel in the mosaic's format, or an error for a value it cannot hold.
using FillMaker = std::function<Status(PixelFormat, std::vector<uint8_t>*)>;

// Opens the sheet `entry` names (kept open in *src until the caller is done
// with its SourceInfo) and finds its georeference, checking that it is not
// the list itself, that a VRT uses all of it unscaled, and that it is
// georeferenced and north-up. `where` starts each message.
Status openSheet(const std::string& where, const ListEntry& entry, const struct stat* list_st,
                 std::optional<PixelFormat> forced, const ImageReadOptions& read,
                 std::unique_ptr<ImageSource>* src, GeoReference* geo) {
  const std::string& path = entry.path;
  if (struct stat st{}; list_st != nullptr && ::stat(path.c_str(), &st) == 0 &&
                        st.st_dev == list_st->st_dev && st.st_ino == list_st->st_ino) {
    return Status::error(ErrorCode::kInvalidArgument,
                         where + path + " is the mosaic list itself, not an image");
  }
  Status s = openImageFile(path, forced, src, read);
  if (!s) return Status::error(s.code, where + s.message);
  s = findGeoReference(path, geo);
  if (!s) return Status::error(s.code, where + s.message);
  const SourceInfo& si = (*src)->info();
  if (entry.has_rects &&
      (entry.src[0] != 0.0 || entry.src[1] != 0.0 || entry.src[2] != double(si.width_px) ||
       entry.src[3] != double(si.height_px) || entry.dst[0] != entry.src[2] ||
       entry.dst[1] != entry.src[3])) {
    return Status::error(ErrorCode::kUnsupported,
                         where + "the VRT draws part of " + path +
                             " or scales it (SrcRect / DstRect); a mosaic takes whole sheets "
                             "at their own resolution");
  }
  if (!geo->present) {
    return Status::error(ErrorCode::kInvalidArgument,
                         where + path + " has no georeference (no GeoTIFF tags, no world file "
                                        "beside it): a mosaic places sheets by them");
  }
  if (geo->transform[2] != 0.0 || geo->transform[4] != 0.0) {
    return Status::error(ErrorCode::kUnsupported,
                         where + path + " is rotated or sheared; mosaics take north-up sheets");
  }
  return okStatus();
}

// Checks that a later sheet (path, geo, si) matches the first one (first,
// first_geo, first_info): one pixel size, one CRS, one pixel type.
Status checkLikeFirst(const std::string& where, const std::string& path, const GeoReference& geo,
                      const SourceInfo& si, const std::string& first, const GeoReference& first_geo,
                      const SourceInfo& first_info) {
  if (!samePixelSize(geo.transform[1], first_geo.transform[1]) ||
      !samePixelSize(geo.transform[5], first_geo.transform[5])) {
    return Status::error(ErrorCode::kInvalidArgument,
                         where + path + ": pixel size " + pixelSizeText(geo) + " differs from " +
                             first + "'s " + pixelSizeText(first_geo) +
                             "; a mosaic needs one resolution (resample the sheets first)");
  }
  if (geo.crs != first_geo.crs) {
    return Status::error(ErrorCode::kInvalidArgument,
                         where + path + ": CRS '" + printableText(geo.crs, 80) +
                             "' differs from " + first + "'s '" +
                             printableText(first_geo.crs, 80) + "'; a mosaic needs one CRS");
  }
  if (si.input_channels != first_info.input_channels || si.input_type != first_info.input_type) {
    return Status::error(ErrorCode::kInvalidArgument,
                         where + path + " has " + std::to_string(si.input_channels) + " " +
                             si.input_type + " channels, " + first + " " +
                             std::to_string(first_info.input_channels) + " " +
                             first_info.input_type + "; a mosaic needs one pixel type");
  }
  return okStatus();
}

// The sheet's offset from the first sheet in whole pixels of the first
// sheet's grid, or an error when it lies off that grid. `first` names the
// first sheet.
Status gridOffset(const std::string& where, const std::string& path, const GeoReference& geo,
                  const GeoReference& first_geo, const std::string& first,
                  std::pair<int64_t, int64_t>* offset) {
  const double col = (geo.transform[0] - first_geo.transform[0]) / first_geo.transform[1];
  const double row = (geo.transform[3] - first_geo.transform[3]) / first_geo.transform[5];
  const double rcol = std::round(col), rrow = std::round(row);
  if (std::fabs(col - rcol) > kGridTolerancePx || std::fabs(row - rrow) > kGridTolerancePx ||
      std::fabs(rcol) > 1e15 || std::fabs(rrow) > 1e15) {
    return Status::error(ErrorCode::kInvalidArgument,
                         where + path + " is not on the pixel grid of " + first + " (offset " +
                             std::to_string(col) + ", " + std::to_string(row) + " pixels)");
  }
  *offset = {int64_t(rcol), int64_t(rrow)};
  return okStatus();
}

// The mosaic's extent: its top-left corner in whole pixels from the first
// sheet, and its size.
struct Extent {
  int64_t min_col = INT64_MAX, min_row = INT64_MAX;
  uint64_t width = 0, height = 0;
};

// The bounding box of the sheets at `offsets` (whole pixels from the first
// sheet); sets each sheet's x0, y0 in the mosaic from it.
Extent placeSheets(const std::vector<std::pair<int64_t, int64_t>>& offsets,
                   std::vector<Sheet>* sheets) {
  Extent e;
  int64_t max_col = INT64_MIN, max_row = INT64_MIN;
  for (size_t i = 0; i < sheets->size(); ++i) {
    e.min_col = std::min(e.min_col, offsets[i].first);
    e.min_row = std::min(e.min_row, offsets[i].second);
    max_col = std::max(max_col, offsets[i].first + int64_t((*sheets)[i].width));
    max_row = std::max(max_row, offsets[i].second + int64_t((*sheets)[i].height));
  }
  for (size_t i = 0; i < sheets->size(); ++i) {
    (*sheets)[i].x0 = uint64_t(offsets[i].first - e.min_col);
    (*sheets)[i].y0 = uint64_t(offsets[i].second - e.min_row);
  }
  e.width = uint64_t(max_col - e.min_col), e.height = uint64_t(max_row - e.min_row);
  return e;
}

// The sheets of the list, checked and placed relative to the first one,
// with what the mosaic's SourceInfo takes from them.
struct ListedSheets {
  std::vector<Sheet> sheets;
  std::vector<std::pair<int64_t, int64_t>> offsets;  // whole pixels from the first sheet
  SourceInfo first_info;
  GeoReference first_geo;
  uint64_t file_bytes = 0;
  bool sequential = false;
};

// Opens each sheet of the list in turn (closing it again: strips open them
// when they reach them) and checks that it fits the first one's grid.
Status readSheets(const std::string& list_path, const std::vector<ListEntry>& paths,
                  std::optional<PixelFormat> forced, const ImageReadOptions& read,
                  ListedSheets* out) {
  struct stat list_st{};
  const bool list_known = ::stat(list_path.c_str(), &list_st) == 0;
  std::vector<Sheet>& sheets = out->sheets;
  for (const ListEntry& entry : paths) {
    const std::string& path = entry.path;
    const std::string where = list_path + " line " + std::to_string(entry.line) + ": ";
    std::unique_ptr<ImageSource> src;
    GeoReference geo;
    Status s = openSheet(where, entry, list_known ? &list_st : nullptr, forced, read, &src, &geo);
    if (!s) return s;
    const SourceInfo& si = src->info();
    if (sheets.empty()) {
      out->first_info = si;
      out->first_geo = geo;
    } else {
      s = checkLikeFirst(where, path, geo, si, sheets[0].path, out->first_geo, out->first_info);
      if (!s) return s;
    }
    std::pair<int64_t, int64_t> offset;
    s = gridOffset(where, path, geo, out->first_geo, sheets.empty() ? path : sheets[0].path, &offset);
    if (!s) return s;
    out->offsets.push_back(offset);
    Sheet sheet;
    sheet.path = path;
    sheet.width = si.width_px;
    sheet.height = si.height_px;
    out->file_bytes += si.file_bytes;
    out->sequential = out->sequential || si.sequential_only;
    sheets.push_back(std::move(sheet));
    // src closes here: sheets are opened again when strips reach them.
  }
  return okStatus();
}

// The mosaic in its steps: read the list, open and check every sheet,
// place them, make the gap pixel, then the source and its MosaicInfo.
Status openMosaicImpl(const std::string& list_path, std::optional<PixelFormat> forced,
                      const FillMaker& make_fill, std::unique_ptr<ImageSource>* out,
                      MosaicInfo* mosaic, const ImageReadOptions& read) {
  *mosaic = MosaicInfo{};
  std::vector<ListEntry> paths;
  Status s = readList(list_path, &paths);
  if (!s) return s;
  ListedSheets listed;
  s = readSheets(list_path, paths, forced, read, &listed);
  if (!s) return s;
  std::vector<Sheet>& sheets = listed.sheets;
  const SourceInfo& first_info = listed.first_info;
  const GeoReference& first_geo = listed.first_geo;
  const Extent extent = placeSheets(listed.offsets, &sheets);
  const uint64_t width = extent.width, height = extent.height;

  const PixelFormat format = first_info.format;
  std::vector<uint8_t> fill_pixel(bytesPerPixel(format));
  s = make_fill(format, &fill_pixel);
  if (!s) return s;

  SourceInfo info;
  info.width_px = width;
  info.height_px = height;
  info.input_channels = first_info.input_channels;
  info.input_type = first_info.input_type;
  info.decoder = "mosaic of " + first_info.decoder;
  info.sequential_only = listed.sequential;
  info.file_bytes = listed.file_bytes;
  info.format = format;
  mosaic->gap_px = gapPixels(sheets, width, height);
  mosaic->geo = first_geo;
  mosaic->geo.transform[0] = first_geo.transform[0] + double(extent.min_col) * first_geo.transform[1];
  mosaic->geo.transform[3] = first_geo.transform[3] + double(extent.min_row) * first_geo.transform[5];
  for (const Sheet& sh : sheets) mosaic->sheets.push_back(sh.path);
  *out = std::make_unique<MosaicSource>(std::move(sheets), std::move(info), format,
                                        std::move(fill_pixel), read);
  return okStatus();
}

}  // namespace

Status openMosaic(const std::string& list_path, std::optional<PixelFormat> forced, uint32_t fill,
                  std::unique_ptr<ImageSource>* out, MosaicInfo* mosaic,
                  const ImageReadOptions& read) {
  return openMosaicImpl(list_path, forced, [fill](PixelFormat format, std::vector<uint8_t>* px) {
    const uint32_t max_fill = format == PixelFormat::kR16 ? 65535u : 255u;
    if (fill > max_fill) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "--fill " + std::to_string(fill) + " does not fit a " +
                               pixelFormatName(format) + " sample (0.." + std::to_string(max_fill) + ")");
    }
    if (format == PixelFormat::kR16) {
      (*px)[0] = uint8_t(fill & 0xff);
      (*px)[1] = uint8_t(fill >> 8);
    } else {
      std::fill(px->begin(), px->end(), uint8_t(fill));
      if (format == PixelFormat::kRGBA8) (*px)[3] = 0;
    }
    return okStatus();
  }, out, mosaic, read);
}

Status openHeightMosaic(const std::string& list_path, PixelFormat native, double gap_height,
                        std::unique_ptr<ImageSource>* out, MosaicInfo* mosaic,
                        const ImageReadOptions& read) {
  return openMosaicImpl(list_path, native, [gap_height](PixelFormat format, std::vector<uint8_t>* px) {
    const bool integer = format == PixelFormat::kI16 || format == PixelFormat::kR16;
    const double lo = format == PixelFormat::kI16 ? -32768.0 : 0.0;
    const double hi = format == PixelFormat::kI16 ? 32767.0 : 65535.0;
    if (integer && !(gap_height >= lo && gap_height <= hi && gap_height == std::floor(gap_height))) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "the no-data value " + std::to_string(gap_height) + " for the gaps is no " +
                               pixelFormatName(format) + " sample");
    }
    if (format == PixelFormat::kI16) {
      const int16_t v = int16_t(gap_height);
      std::memcpy(px->data(), &v, 2);
    } else if (format == PixelFormat::kR16) {
      const uint16_t v = uint16_t(gap_height);
      std::memcpy(px->data(), &v, 2);
    } else if (format == PixelFormat::kF32) {
      const float v = float(gap_height);
      std::memcpy(px->data(), &v, 4);
    } else {
      return Status::error(ErrorCode::kInvalidArgument, "heights are I16, R16 or F32");
    }
    return okStatus();
  }, out, mosaic, read);
}

}  // namespace clipstream
