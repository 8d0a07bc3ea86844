// PNG through libpng (native_source.h), a row at a time from the top: 8-
// and 16-bit grey, grey+alpha, RGB and RGBA, not interlaced. Palettes,
// transparency chunks, fewer than 8 bits and Adam7 interlacing (which needs
// the whole image at once) are OpenImageIO's.
#include "native_source.h"
#include "pixel_convert.h"
#include "sequential_source.h"

#include <png.h>

#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <vector>

namespace clipstream {
namespace {

using namespace pixel_convert;
namespace fs = std::filesystem;

struct PngError {
  char message[256] = {};
};

[[noreturn]] void onPngError(png_structp png, png_const_charp text) {
  auto* e = static_cast<PngError*>(png_get_error_ptr(png));
  std::snprintf(e->message, sizeof e->message, "%s", text != nullptr ? text : "decoder failed");
  png_longjmp(png, 1);
}

// Warnings (a known-bad colour profile, a damaged ancillary chunk) do not
// touch the pixels; libpng turns the ones that do into errors.
void onPngWarning(png_structp, png_const_charp) {}

// One libpng reader over the file, from its start. Every libpng call goes
// through guarded(), the only frame with setjmp.
class Decoder {
 public:
  ~Decoder() {
    if (m_png != nullptr) png_destroy_read_struct(&m_png, m_info != nullptr ? &m_info : nullptr, nullptr);
    if (m_file != nullptr) std::fclose(m_file);
  }

  Status open(const std::string& path) {
    m_path = path;
    Status opened = openInputFile(path, &m_file);
    if (!opened) return opened;
    m_png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &m_err, onPngError, onPngWarning);
    if (m_png != nullptr) m_info = png_create_info_struct(m_png);
    if (m_png == nullptr || m_info == nullptr) {
      return Status::error(ErrorCode::kOutOfMemory, path + ": cannot open image: out of memory");
    }
    if (!guarded([&] {
          png_init_io(m_png, m_file);
          png_read_info(m_png, m_info);
        })) {
      return failure("cannot open image");
    }
    return okStatus();
  }

  png_structp png() { return m_png; }
  png_infop info() { return m_info; }

  // Sets the output layout: 16-bit samples in the machine's byte order.
  Status start() {
    if (!guarded([&] {
          if (png_get_bit_depth(m_png, m_info) == 16) png_set_swap(m_png);
          png_read_update_info(m_png, m_info);
        })) {
      return failure("cannot decode image");
    }
    return okStatus();
  }

  uint64_t nextRow() const { return m_next_row; }

  Status readRow(uint8_t* row) {
    if (!guarded([&] { png_read_row(m_png, row, nullptr); })) {
      return failure("cannot read row " + std::to_string(m_next_row));
    }
    ++m_next_row;
    return okStatus();
  }

 private:
  template <typename F>
  bool guarded(F&& f) {
    if (setjmp(png_jmpbuf(m_png)) != 0) return false;
    f();
    return true;
  }

  Status failure(const std::string& what) {
    return Status::error(ErrorCode::kIo,
                         m_path + ": " + what + ": " + decoderMessage(m_err.message, "decoder failed"));
  }

  std::string m_path;
  std::FILE* m_file = nullptr;
  png_structp m_png = nullptr;
  png_infop m_info = nullptr;
  PngError m_err;
  uint64_t m_next_row = 0;
};

}  // namespace

Status openPngImage(const std::string& path, std::optional<PixelFormat> forced,
                    const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                    bool* covered) {
  (void)read;
  *covered = true;
  auto decoder = std::make_unique<Decoder>();
  Status s = decoder->open(path);
  if (!s) return s;
  png_structp png = decoder->png();
  png_infop pinfo = decoder->info();
  const uint32_t w = png_get_image_width(png, pinfo), h = png_get_image_height(png, pinfo);
  const int depth = png_get_bit_depth(png, pinfo);
  const int type = png_get_color_type(png, pinfo);
  uint32_t nch = 0;
  switch (type) {
    case PNG_COLOR_TYPE_GRAY: nch = 1; break;
    case PNG_COLOR_TYPE_GRAY_ALPHA: nch = 2; break;
    case PNG_COLOR_TYPE_RGB: nch = 3; break;
    case PNG_COLOR_TYPE_RGB_ALPHA: nch = 4; break;
    default: break;  // palette
  }
  if (nch == 0 || (depth != 8 && depth != 16) ||
      png_get_interlace_type(png, pinfo) != PNG_INTERLACE_NONE ||
      png_get_valid(png, pinfo, PNG_INFO_tRNS) != 0) {
    *covered = false;
    return okStatus();
  }
  const SampleKind kind = depth == 16 ? SampleKind::kU16 : SampleKind::kU8;
  SourceInfo info;
  info.width_px = w;
  info.height_px = h;
  info.input_channels = nch;
  info.input_type = sampleKindName(kind);
  info.decoder = "libpng";
  info.tiled = false;
  info.sequential_only = true;
  std::error_code ec;
  info.file_bytes = fs::file_size(path, ec);
  info.format = forced ? *forced : defaultFormat(nch, kind);
  png_uint_32 exif_bytes = 0;
  png_bytep exif = nullptr;
  if (png_get_eXIf_1(png, pinfo, &exif_bytes, &exif) != 0 && exif != nullptr) {
    const uint16_t orientation = exifOrientation(exif, exif_bytes);
    if (orientation != 1) info.warnings.push_back(orientationWarning(path, orientation));
  }
  s = decoder->start();
  if (!s) return s;
  auto restart = [path](std::unique_ptr<Decoder>* again) {
    *again = std::make_unique<Decoder>();
    Status st = (*again)->open(path);
    if (st) st = (*again)->start();
    return st;
  };
  *out = std::make_unique<SequentialSource<Decoder>>(path, std::move(info), kind, std::move(decoder),
                                                     restart);
  return okStatus();
}

}  // namespace clipstream
