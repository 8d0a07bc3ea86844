// Image sources: the procedural image, and which reader opens a file: the
// tiler's own (native_source.h) or the OpenImageIO module (oiio_source.cpp),
// loaded here on first use.
#include <clipstream/tiler/image_source.h>

#include "native_source.h"
#include "gdal_module.h"
#include "oiio_module.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <system_error>
#include <mutex>
#include <vector>

#ifndef CLIPSTREAM_TILER_OIIO_MODULE_PATH
#define CLIPSTREAM_TILER_OIIO_MODULE_PATH ""
#endif
#ifndef CLIPSTREAM_TILER_GDAL_MODULE_PATH
#define CLIPSTREAM_TILER_GDAL_MODULE_PATH ""
#endif
#ifndef CLIPSTREAM_TILER_MODULE_FROM_BINDIR
#define CLIPSTREAM_TILER_MODULE_FROM_BINDIR "../lib/clipstream"
#endif
#ifndef CLIPSTREAM_TILER_MODULE_INSTALLED
#define CLIPSTREAM_TILER_MODULE_INSTALLED ""
#endif
#ifndef CLIPSTREAM_TILER_MODULE_PACKAGED
#define CLIPSTREAM_TILER_MODULE_PACKAGED ""
#endif

namespace clipstream {
namespace {

namespace fs = std::filesystem;

// A module the tiler loads on first use: its file, its entry point, the
// environment variable that names it, and where the build put it.
struct ModuleSpec {
  const char* file_name;
  const char* symbol;
  const char* env;
  const char* build_path;
};

// Loads `spec`'s module (once per process; it stays loaded) and returns its
// entry point. Looked for: $env, beside the program, LIBDIR/clipstream
// relative to the program, the build folder, the configured and packaged
// module folders, then the loader's search path.
Status loadModule(const ModuleSpec& spec, void** out) {
  static std::mutex mutex;
  static std::vector<std::pair<std::string, void*>> loaded;
  std::lock_guard lock(mutex);
  for (const auto& [name, fn] : loaded) {
    if (name == spec.file_name) {
      *out = fn;
      return okStatus();
    }
  }
  std::vector<std::string> candidates;
  if (const char* env = std::getenv(spec.env); env != nullptr && *env) candidates.push_back(env);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    candidates.push_back((exe.parent_path() / spec.file_name).string());
    candidates.push_back((exe.parent_path() / CLIPSTREAM_TILER_MODULE_FROM_BINDIR / spec.file_name).string());
  }
  if (*spec.build_path) candidates.push_back(spec.build_path);
  for (const char* folder : {CLIPSTREAM_TILER_MODULE_INSTALLED, CLIPSTREAM_TILER_MODULE_PACKAGED})
    if (*folder) candidates.push_back((fs::path(folder) / spec.file_name).string());
  candidates.push_back(spec.file_name);  // the loader's search path
  std::string errors;
  for (const std::string& c : candidates) {
    if (c.find('/') != std::string::npos && !fs::exists(c, ec)) continue;
    void* handle = dlopen(c.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      errors += std::string(" ") + dlerror() + ";";
      continue;
    }
    void* fn = dlsym(handle, spec.symbol);
    if (fn == nullptr) {
      errors += " " + c + ": no " + spec.symbol + ";";
      continue;
    }
    loaded.emplace_back(spec.file_name, fn);
    *out = fn;
    return okStatus();
  }
  return Status::error(ErrorCode::kUnsupported, std::string("cannot load the image reader module ") +
                                                    spec.file_name + " (set " + spec.env + "):" + errors);
}

// OpenImageIO and its ~260 dependent libraries cost about 120 MB of
// resident memory as soon as they are loaded, which alone would break small
// --memory-mb budgets. They live in a module loaded on the first file open
// that needs them, so procedural inputs and the formats the tiler reads
// itself never pay for them.
Status openWithOiio(const std::string& path, std::optional<PixelFormat> forced,
                    std::unique_ptr<ImageSource>* out) {
  static const ModuleSpec kSpec{kOiioModuleFileName, kOiioModuleSymbol, "CLIPSTREAM_TILER_OIIO_MODULE",
                                CLIPSTREAM_TILER_OIIO_MODULE_PATH};
  void* fn = nullptr;
  Status s = loadModule(kSpec, &fn);
  if (!s) return s;
  reinterpret_cast<OpenImageFileFn>(fn)(&path, &forced, out, &s);
  return s;
}

// GDAL likewise (gdal_module.h).
Status openWithGdal(const std::string& path, std::optional<PixelFormat> forced,
                    const ImageReadOptions& read, std::unique_ptr<ImageSource>* out) {
  static const ModuleSpec kSpec{kGdalModuleFileName, kGdalModuleSymbol, "CLIPSTREAM_TILER_GDAL_MODULE",
                                CLIPSTREAM_TILER_GDAL_MODULE_PATH};
  void* fn = nullptr;
  Status s = loadModule(kSpec, &fn);
  if (!s) return s;
  reinterpret_cast<OpenGdalFn>(fn)(&path, &forced, &read, out, &s);
  return s;
}

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

// The first bytes of a file (fewer when it is shorter).
std::string fileHead(const std::string& path, size_t bytes) {
  std::string head(bytes, '\0');
  std::ifstream in(path, std::ios::binary);
  in.read(head.data(), std::streamsize(bytes));
  head.resize(size_t(std::max<std::streamsize>(in.gcount(), 0)));
  return head;
}

// Files whose place on the ground only GDAL reads among our readers: a
// VRT (which may also warp, crop or combine its sources) and JPEG 2000
// (OpenImageIO decodes its pixels but drops GeoJP2 and GMLJP2).
bool gdalFormat(const std::string& path) {
  const std::string head = fileHead(path, 64);
  size_t i = 0;
  while (i < head.size() && std::isspace(static_cast<unsigned char>(head[i]))) ++i;
  if (head.compare(i, 11, "<VRTDataset") == 0) return true;
  static const char kJp2[] = {0, 0, 0, 0x0c, 'j', 'P', ' ', ' '};
  static const char kJ2k[] = {char(0xff), 0x4f, char(0xff), 0x51};
  return head.compare(0, sizeof kJp2, kJp2, sizeof kJp2) == 0 ||
         head.compare(0, sizeof kJ2k, kJ2k, sizeof kJ2k) == 0;
}

inline uint32_t hash32(uint64_t x, uint64_t y) {
  // A small integer hash (xxhash-style avalanche): cheap and stable.
  uint64_t h = x * 0x9E3779B185EBCA87ull ^ (y + 0x165667B19E3779F9ull) * 0xC2B2AE3D27D4EB4Full;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 32;
  return uint32_t(h);
}

class SyntheticSource final : public ImageSource {
 public:
  explicit SyntheticSource(SourceInfo info) : m_info(std::move(info)) {}
  const SourceInfo& info() const override { return m_info; }

  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    if (y0 + rows > m_info.height_px || x0 + width > m_info.width_px) {
      return Status::error(ErrorCode::kOutOfRange, "synthetic: row request outside the image");
    }
    const uint32_t bpp = bytesPerPixel(m_info.format);
    for (uint32_t r = 0; r < rows; ++r) {
      uint8_t* out = dst + size_t(r) * dst_stride;
      for (uint64_t x = 0; x < width; ++x) syntheticPixel(x0 + x, y0 + r, m_info.format, out + x * bpp);
    }
    return okStatus();
  }

 private:
  SourceInfo m_info;
};

}  // namespace

void syntheticPixel(uint64_t x, uint64_t y, PixelFormat format, uint8_t* out) {
  const uint32_t h = hash32(x, y);
  const uint32_t noise = h & 15u;
  // Smooth fields at a few scales plus a little noise: enough texture that
  // compression works like it does on photographs, and coordinate bits
  // (x >> 3 in red, y >> 3 in green) so a misplaced block shows.
  const uint32_t r = uint32_t((x >> 3) + ((x >> 9) * 7) + noise) & 255u;
  const uint32_t g = uint32_t((y >> 3) + ((y >> 9) * 13) + (noise >> 1)) & 255u;
  const uint32_t b = uint32_t(((x ^ y) >> 6) * 29 + ((h >> 4) & 7u)) & 255u;
  switch (format) {
    case PixelFormat::kR8:
      out[0] = uint8_t((r + g) >> 1);
      break;
    case PixelFormat::kR16: {
      const uint32_t v = uint32_t((x + y) * 3 + ((h >> 8) & 63u)) & 0xffffu;
      out[0] = uint8_t(v & 0xff);
      out[1] = uint8_t(v >> 8);
      break;
    }
    case PixelFormat::kRGB8:
      out[0] = uint8_t(r);
      out[1] = uint8_t(g);
      out[2] = uint8_t(b);
      break;
    case PixelFormat::kRGBA8:
      out[0] = uint8_t(r);
      out[1] = uint8_t(g);
      out[2] = uint8_t(b);
      out[3] = uint8_t(255u - ((h >> 12) & 3u));
      break;
    case PixelFormat::kI16: {
      const int16_t v = int16_t(((x + y) & 0x3fffu) + (h & 7u));
      std::memcpy(out, &v, 2);
      break;
    }
    case PixelFormat::kF32: {
      const float v = float((x + y) & 0xffffu) + float(h & 7u) * 0.125f;
      std::memcpy(out, &v, 4);
      break;
    }
  }
}

Status makeSyntheticSource(uint64_t width_px, uint64_t height_px, PixelFormat format,
                           std::unique_ptr<ImageSource>* out) {
  if (width_px == 0 || height_px == 0) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "synthetic image size " + std::to_string(width_px) + "x" +
                             std::to_string(height_px) + " is empty");
  }
  SourceInfo info;
  info.width_px = width_px;
  info.height_px = height_px;
  info.input_channels = channelCount(format);
  info.input_type = "synthetic";
  info.decoder = "synthetic";
  info.tiled = true;
  info.format = format;
  *out = std::make_unique<SyntheticSource>(info);
  return okStatus();
}

bool isGdalName(const std::string& path) {
  if (isUrl(path) || startsWith(path, "/vsi")) return true;
  // A driver's connection string: NETCDF:"file.nc":variable, HDF5:..., GPKG:...
  size_t i = 0;
  while (i < path.size() && (std::isupper(static_cast<unsigned char>(path[i])) ||
                             std::isdigit(static_cast<unsigned char>(path[i])) || path[i] == '_')) {
    ++i;
  }
  return i >= 2 && i < path.size() && path[i] == ':' && std::isupper(static_cast<unsigned char>(path[0]));
}

Status openImageFile(const std::string& path, std::optional<PixelFormat> forced,
                     std::unique_ptr<ImageSource>* out, const ImageReadOptions& read) {
  out->reset();
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    if (isGdalName(path)) return openWithGdal(path, forced, read, out);
    if (ec) return Status::error(ErrorCode::kIo, path + ": " + ec.message());
    return Status::error(ErrorCode::kNotFound, path + ": no such file");
  }
  if (!fs::is_regular_file(path, ec)) {
    return Status::error(ErrorCode::kIo, path + ": not a regular file");
  }
  if (!read.target_crs.empty() && read.reader != ImageReader::kOpenImageIO) {
    return openWithGdal(path, forced, read, out);  // only GDAL reprojects
  }
  if (read.reader == ImageReader::kAuto) {
    bool covered = false;
    Status s = openNativeImage(path, forced, read, out, &covered);
    if (covered || !s) return s;
    if (gdalFormat(path)) return openWithGdal(path, forced, read, out);
  } else {
    // OpenImageIO's TIFF reader drops libtiff's warnings, so a file whose
    // layout libtiff had to ignore would tile as zeros: our readers' checks
    // at open (layout warnings, strips and tiles inside the file) refuse a
    // damaged file whichever reader then decodes it.
    bool covered = false;
    std::unique_ptr<ImageSource> probe;
    Status s = openNativeImage(path, forced, read, &probe, &covered);
    if (!s && s.code == ErrorCode::kTruncated) return s;
    if (read.reader == ImageReader::kGdal) return openWithGdal(path, forced, read, out);
  }
  Status s = openWithOiio(path, forced, out);
  if (s || read.reader != ImageReader::kAuto || s.code != ErrorCode::kIo) return s;
  // Neither our readers nor OpenImageIO: GDAL's geodata formats (HDF,
  // NetCDF, ERDAS Imagine, ASCII grids, ...).
  Status g = openWithGdal(path, forced, read, out);
  if (g || g.code != ErrorCode::kIo) return g;
  const std::string prefix = path + ": cannot open image: ";
  auto why = [&](const Status& st) {
    return startsWith(st.message, prefix.c_str()) ? st.message.substr(prefix.size()) : st.message;
  };
  return Status::error(ErrorCode::kIo, prefix + "OpenImageIO: " + why(s) + "; " + why(g));
}

}  // namespace clipstream
