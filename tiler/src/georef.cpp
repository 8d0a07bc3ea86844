// Georeferencing of tiler inputs: GeoTIFF tags (parsed by the store's
// parseGeoTiffTags()), world files and .prj files.
#include <clipstream/tiler/georef.h>

#include <clipstream/store/geotiff.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

}  // namespace

Status readWorldFile(const std::string& path, GeoReference* out) {
  *out = GeoReference{};
  std::ifstream in(path);
  if (!in) return Status::error(ErrorCode::kIo, path + ": cannot open world file");
  double v[6];
  for (double& x : v) {
    std::string token;
    if (!(in >> token)) {
      return Status::error(ErrorCode::kBadHeader, path + ": world file needs 6 numbers (A D B E C F)");
    }
    try {
      size_t used = 0;
      x = std::stod(token, &used);
      if (used != token.size()) throw std::invalid_argument(token);
    } catch (const std::exception&) {
      return Status::error(ErrorCode::kBadHeader, path + ": world file value '" + token + "' is not a number");
    }
  }
  const double a = v[0], d = v[1], b = v[2], e = v[3], c = v[4], f = v[5];
  if (a * e - b * d == 0.0) {
    return Status::error(ErrorCode::kBadHeader, path + ": world file transform is singular");
  }
  // C, F are the centre of pixel (0, 0); the corner is half a pixel back.
  out->present = true;
  out->transform[0] = c - 0.5 * a - 0.5 * b;
  out->transform[1] = a;
  out->transform[2] = b;
  out->transform[3] = f - 0.5 * d - 0.5 * e;
  out->transform[4] = d;
  out->transform[5] = e;
  return okStatus();
}

namespace {

// The file's GeoTIFF tags, read with an ifstream.
Status parseTiffTags(const std::string& path, GeoReference* out, ElevationTags* elevation) {
  *out = GeoReference{};
  *elevation = ElevationTags{};
  std::error_code ec;
  const uint64_t size = fs::file_size(path, ec);
  if (ec) return Status::error(ErrorCode::kIo, path + ": " + ec.message());
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::error(ErrorCode::kIo, path + ": cannot open");
  const TiffByteReader read = [&in](uint64_t offset, void* dst, size_t n) {
    in.clear();
    in.seekg(std::streamoff(offset));
    in.read(static_cast<char*>(dst), std::streamsize(n));
    return bool(in);
  };
  return parseGeoTiffTags(path, size, read, out, elevation);
}

}  // namespace

Status readGeoTiffTags(const std::string& path, GeoReference* out) {
  ElevationTags ignored;
  return parseTiffTags(path, out, &ignored);
}

Status readElevationTags(const std::string& path, ElevationTags* out) {
  GeoReference ignored;
  return parseTiffTags(path, &ignored, out);
}

Status findGeoReference(const std::string& path, GeoReference* out) {
  *out = GeoReference{};
  Status s = readGeoTiffTags(path, out);
  if (!s) return s;
  const fs::path p(path);
  if (!out->present) {
    std::string ext = p.extension().string();
    std::vector<std::string> candidates = {".wld"};
    if (ext.size() == 4) candidates.push_back(std::string(".") + ext[1] + ext[3] + "w");
    if (ext.size() >= 2) candidates.push_back(ext + "w");
    for (const std::string& c : candidates) {
      for (const std::string& cc : {c, [&] {
             std::string u = c;
             for (char& ch : u) ch = char(std::toupper(static_cast<unsigned char>(ch)));
             return u;
           }()}) {
        fs::path wp = p;
        wp.replace_extension(cc);
        std::error_code ec;
        if (fs::is_regular_file(wp, ec)) {
          s = readWorldFile(wp.string(), out);
          if (!s) return s;
          break;
        }
      }
      if (out->present) break;
    }
  }
  if (out->present && out->crs.empty()) {
    fs::path prj = p;
    prj.replace_extension(".prj");
    std::ifstream in(prj);
    if (in) {
      std::stringstream ss;
      ss << in.rdbuf();
      std::string wkt = ss.str();
      while (!wkt.empty() && std::isspace(static_cast<unsigned char>(wkt.back()))) wkt.pop_back();
      out->crs = wkt;
    }
  }
  return okStatus();
}

}  // namespace clipstream
