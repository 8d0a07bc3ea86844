// Which of the tiler's own readers a file goes to (native_source.h), and
// the EXIF orientation block parser they share.
#include "native_source.h"

#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>

namespace clipstream {

Status openInputFile(const std::string& path, std::FILE** out) {
  *out = std::fopen(path.c_str(), "rb");
  if (*out == nullptr) return Status::error(ErrorCode::kIo, path + ": cannot open: " + std::strerror(errno));
  return okStatus();
}

uint16_t exifOrientation(const uint8_t* data, size_t size) {
  if (data == nullptr || size < 8) return 1;
  const bool be = data[0] == 'M' && data[1] == 'M';
  if (!be && !(data[0] == 'I' && data[1] == 'I')) return 1;
  auto get = [&](size_t at, int n) -> uint64_t {
    uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= uint64_t(data[at + (be ? n - 1 - i : i)]) << (8 * i);
    return v;
  };
  if (get(2, 2) != 42) return 1;
  const uint64_t ifd = get(4, 4);
  if (ifd > size || size - ifd < 2) return 1;
  const uint64_t count = get(ifd, 2);
  for (uint64_t i = 0; i < count; ++i) {
    const uint64_t at = ifd + 2 + 12 * i;
    if (at > size || size - at < 12) return 1;
    if (get(at, 2) == 0x0112 && get(at + 2, 2) == 3 /* SHORT */ && get(at + 4, 4) >= 1) {
      const uint16_t v = uint16_t(get(at + 8, 2));
      return v >= 1 && v <= 8 ? v : 1;
    }
  }
  return 1;
}

Status openNativeImage(const std::string& path, std::optional<PixelFormat> forced,
                       const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                       bool* covered) {
  out->reset();
  *covered = false;
  std::array<uint8_t, 8> head{};
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) return Status::error(ErrorCode::kIo, path + ": cannot open: " + std::strerror(errno));
    in.read(reinterpret_cast<char*>(head.data()), head.size());
    if (in.gcount() < 4) return okStatus();  // too short for any signature: OpenImageIO says why
  }
  const auto starts = [&](std::initializer_list<uint8_t> sig) {
    return std::equal(sig.begin(), sig.end(), head.begin());
  };
  // Classic TIFF (42) and BigTIFF (43), either byte order.
  if (starts({'I', 'I', 42, 0}) || starts({'M', 'M', 0, 42}) || starts({'I', 'I', 43, 0}) ||
      starts({'M', 'M', 0, 43})) {
    return openTiffImage(path, forced, read, out, covered);
  }
  if (starts({0xff, 0xd8, 0xff})) return openJpegImage(path, forced, read, out, covered);
  if (starts({0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'})) {
    return openPngImage(path, forced, read, out, covered);
  }
  return okStatus();
}

}  // namespace clipstream
