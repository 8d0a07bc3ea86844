// The OpenImageIO side of the tiler's image sources, built as a separate
// module (see oiio_module.h for why): every file the tiler's own readers
// (native_source.cpp) do not cover. Conversion to the store's pixel formats
// is pixel_convert.h's, shared with those readers. This file must not use
// symbols from clipstream_store: the module links OpenImageIO only.
#include "oiio_module.h"
#include "pixel_convert.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <vector>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

using namespace pixel_convert;

// Scratch reads are split so one OIIO call never needs more than this many
// bytes of native pixels, whatever the image width.
constexpr size_t kMaxScratchBytes = size_t(8) << 20;

class OiioSource final : public ImageSource {
 public:
  OiioSource(std::string path, std::unique_ptr<OIIO::ImageInput> input, SourceInfo info,
             SampleKind kind, OIIO::TypeDesc read_type)
      : m_path(std::move(path)),
        m_input(std::move(input)),
        m_info(std::move(info)),
        m_kind(kind),
        m_read_type(read_type) {}

  const SourceInfo& info() const override { return m_info; }

  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    if (y0 + rows > m_info.height_px || x0 + width > m_info.width_px) {
      return Status::error(ErrorCode::kOutOfRange, m_path + ": row request outside the image");
    }
    const size_t native_pixel = size_t(m_read_type.size()) * m_info.input_channels;
    if (m_info.tiled) return readTiledRows(y0, rows, x0, width, dst, dst_stride, native_pixel);
    const size_t native_row = native_pixel * m_info.width_px;
    const uint32_t chunk_rows =
        uint32_t(std::clamp<size_t>(kMaxScratchBytes / std::max<size_t>(native_row, 1), 1, rows));
    const bool fast_copy = m_kind == SampleKind::kU8 &&
                           formatChannels(m_info.format) == m_info.input_channels;
    if (fast_copy && x0 == 0 && width == m_info.width_px && dst_stride == native_row) {
      // Same layout as the store: decode straight into the caller's rows.
      const int yb = int(y0);
      if (!m_input->read_scanlines(0, 0, yb, yb + int(rows), 0, 0, int(m_info.input_channels),
                                   m_read_type, dst)) {
        return readError(yb, yb + int(rows));
      }
      if (m_input->has_error()) return damaged();
      return okStatus();
    }
    for (uint32_t done = 0; done < rows;) {
      const uint32_t n = std::min(chunk_rows, rows - done);
      m_scratch.resize(native_row * n);
      const int yb = int(y0 + done);
      if (!m_input->read_scanlines(0, 0, yb, yb + int(n), 0, 0, int(m_info.input_channels),
                                   m_read_type, m_scratch.data())) {
        return readError(yb, yb + int(n));
      }
      if (m_input->has_error()) return damaged();
      for (uint32_t r = 0; r < n; ++r) {
        convertInto(m_scratch.data() + r * native_row + x0 * native_pixel, width, fast_copy,
                    dst + size_t(done + r) * dst_stride);
      }
      done += n;
    }
    return okStatus();
  }

 private:
  // Converts one row of `width` native pixels into the store's format.
  void convertInto(const uint8_t* src, uint64_t width, bool fast_copy, uint8_t* out) {
    convertNativeRow(m_kind, src, m_info.input_channels, width, m_info.format, fast_copy, out,
                     &m_info.clamped_samples);
  }

  Status readError(int yb, int ye) {
    const std::string why = decoderMessage(m_input->geterror(), "decoder failed");
    return Status::error(ErrorCode::kIo, m_path + ": cannot read rows " + std::to_string(yb) + "-" +
                                             std::to_string(ye - 1) + ": " + why);
  }

  // OIIO reports some decoder problems (e.g. a JPEG cut short) as warnings
  // that still leave an error message behind; treat them as failures rather
  // than tile the decoder's grey padding.
  Status damaged() {
    return Status::error(ErrorCode::kTruncated,
                         m_path + ": damaged image data: " + decoderMessage(m_input->geterror(), "decoder failed"));
  }

  // Tiled files are read one band of tile rows at a time, only the tile
  // columns covering [x0, x0 + width); the band is kept because strips are
  // usually shorter than the file's tiles.
  Status readTiledRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                       size_t dst_stride, size_t native_pixel) {
    const OIIO::ImageSpec& spec = m_input->spec();
    const uint64_t tw = uint64_t(spec.tile_width), th = uint64_t(spec.tile_height);
    const uint64_t ax0 = x0 / tw * tw;
    const uint64_t ax1 = std::min<uint64_t>((x0 + width + tw - 1) / tw * tw, m_info.width_px);
    const bool fast_copy = m_kind == SampleKind::kU8 &&
                           formatChannels(m_info.format) == m_info.input_channels;
    for (uint64_t y = y0; y < y0 + rows; ++y) {
      const uint64_t band_y0 = y / th * th;
      if (band_y0 != m_band_y0 || ax0 != m_band_x0 || ax1 != m_band_x1) {
        const uint64_t band_y1 = std::min(band_y0 + th, m_info.height_px);
        m_scratch.resize(size_t(band_y1 - band_y0) * (ax1 - ax0) * native_pixel);
        m_band_y0 = UINT64_MAX;
        if (!m_input->read_tiles(0, 0, int(ax0), int(ax1), int(band_y0), int(band_y1), 0, 1, 0,
                                 int(m_info.input_channels), m_read_type, m_scratch.data())) {
          const std::string why = decoderMessage(m_input->geterror(), "decoder failed");
          return Status::error(ErrorCode::kIo, m_path + ": cannot read tiles at rows " +
                                                   std::to_string(band_y0) + "-" +
                                                   std::to_string(band_y1 - 1) + ": " + why);
        }
        m_band_y0 = band_y0, m_band_x0 = ax0, m_band_x1 = ax1;
      }
      const uint8_t* src = m_scratch.data() +
                           ((y - band_y0) * (ax1 - ax0) + (x0 - ax0)) * native_pixel;
      convertInto(src, width, fast_copy, dst + size_t(y - y0) * dst_stride);
    }
    return okStatus();
  }

  uint64_t m_band_y0 = UINT64_MAX, m_band_x0 = 0, m_band_x1 = 0;
  std::string m_path;
  std::unique_ptr<OIIO::ImageInput> m_input;
  SourceInfo m_info;
  SampleKind m_kind;
  OIIO::TypeDesc m_read_type;
  std::vector<uint8_t> m_scratch;
};


Status openOiio(const std::string& path, std::optional<PixelFormat> forced,
                std::unique_ptr<ImageSource>* out) {
  out->reset();  // the file exists and is regular (openImageFile checked)
  std::error_code ec;
  // OIIO's global thread pool would compete with the tiler's encoders for
  // cores (the pipeline already overlaps decoding with everything else), so
  // the module asks for none, once, process-wide.
  static const bool kSingleThreaded = OIIO::attribute("threads", 1);
  (void)kSingleThreaded;
  // Keep alpha as stored: OIIO would otherwise premultiply colour by alpha
  // for PNG and unassociated-alpha TIFF.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto input = OIIO::ImageInput::open(path, &config);
  if (!input) {
    const std::string why = decoderMessage(OIIO::geterror(), "not an image OpenImageIO can read");
    return Status::error(ErrorCode::kIo, path + ": cannot open image: " + why);
  }
  // One decode thread per input: the tiler's own pipeline already keeps
  // every core busy, and OIIO's pool would only compete with the encoders.
  input->threads(1);
  const OIIO::ImageSpec& spec = input->spec();
  SourceInfo info;
  if (spec.width <= 0 || spec.height <= 0 || spec.depth > 1) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + ": image size " + std::to_string(spec.width) + "x" +
                             std::to_string(spec.height) + " is empty or not 2D");
  }
  info.width_px = uint64_t(spec.width);
  info.height_px = uint64_t(spec.height);
  info.input_channels = uint32_t(spec.nchannels);
  info.tiled = spec.tile_width > 0;
  info.file_bytes = fs::file_size(path, ec);
  const int orientation = spec.get_int_attribute("Orientation", 1);
  if (orientation != 1) info.warnings.push_back(orientationWarning(path, orientation));
  if (spec.nchannels < 1 || spec.nchannels > 4) {
    return Status::error(ErrorCode::kUnsupported,
                         path + ": " + std::to_string(spec.nchannels) +
                             " channels; only 1 (grey), 2 (grey+alpha), 3 (RGB), 4 (RGBA) are supported");
  }
  // Per-channel formats (e.g. 8-bit colour with a float channel) read as the
  // widest type via OIIO's conversion.
  OIIO::TypeDesc type = spec.format;
  SampleKind kind;
  OIIO::TypeDesc read_type;
  if (type == OIIO::TypeDesc::UINT8) {
    kind = SampleKind::kU8, read_type = OIIO::TypeDesc::UINT8;
  } else if (type == OIIO::TypeDesc::UINT16) {
    kind = SampleKind::kU16, read_type = OIIO::TypeDesc::UINT16;
  } else if (type == OIIO::TypeDesc::INT16) {
    kind = SampleKind::kI16, read_type = OIIO::TypeDesc::INT16;
  } else if (type == OIIO::TypeDesc::FLOAT || type == OIIO::TypeDesc::HALF ||
             type == OIIO::TypeDesc::DOUBLE) {
    kind = SampleKind::kF32, read_type = OIIO::TypeDesc::FLOAT;
  } else {
    return Status::error(ErrorCode::kUnsupported,
                         path + ": pixel type " + std::string(type.c_str()) +
                             " is not supported (uint8, uint16, int16, half, float, double are)");
  }
  info.input_type = type.c_str();
  info.decoder = "openimageio";
  info.format = forced ? *forced : defaultFormat(uint32_t(spec.nchannels), kind);
  // JPEG and PNG decode strictly top to bottom.
  const std::string fmt_name = input->format_name();
  info.sequential_only = !info.tiled && fmt_name != "tiff";
  *out = std::make_unique<OiioSource>(path, std::move(input), info, kind, read_type);
  return okStatus();
}

}  // namespace
}  // namespace clipstream

extern "C" __attribute__((visibility("default"))) void clipstreamTilerOpenImageFile(
    const std::string* path, const std::optional<clipstream::PixelFormat>* forced,
    std::unique_ptr<clipstream::ImageSource>* out, clipstream::Status* status) {
  *status = clipstream::openOiio(*path, *forced, out);
}
