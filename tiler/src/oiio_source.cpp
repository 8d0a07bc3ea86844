// The OpenImageIO side of the tiler's image sources, built as a separate
// module (see oiio_module.h for why). Conversion to the store's pixel
// formats lives here so the rest of the tiler only moves bytes of one known
// layout. This file must not use symbols from clipstream_store: the module
// links OpenImageIO only.
#include "oiio_module.h"

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

// A decoder's error text for one message line: libtiff and libjpeg report a
// damaged file once per strip or scanline, which would flood the terminal
// under our one error. Keeps the first line, control bytes shown as '?'.
std::string decoderMessage(const std::string& text, const char* fallback) {
  if (text.empty()) return fallback;
  const size_t end = text.find('\n');
  // (This module is loaded on its own: no clipstream::printableText here.)
  std::string first = text.substr(0, std::min<size_t>(end, 300));
  for (char& c : first)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  size_t more = 0;
  for (size_t at = end; at != std::string::npos && at + 1 < text.size(); at = text.find('\n', at + 1)) ++more;
  if (more > 0) first += " (and " + std::to_string(more) + " more messages like it)";
  return first;
}

uint32_t formatChannels(PixelFormat f) {
  switch (f) {
    case PixelFormat::kR8:
    case PixelFormat::kR16: return 1;
    case PixelFormat::kRGB8: return 3;
    case PixelFormat::kRGBA8: return 4;
    case PixelFormat::kI16:
    case PixelFormat::kF32: return 1;
  }
  return 0;
}

// Heights: channel 0 as its value, not as a colour (no normalisation).
// I16 is asked for int16 input only; F32 takes any sample type.
template <typename T>
void convertHeightRow(const T* src, uint32_t nch, uint64_t width, PixelFormat format,
                      uint8_t* dst) {
  for (uint64_t x = 0; x < width; ++x, src += nch) {
    if (format == PixelFormat::kI16) {
      const int16_t v = int16_t(std::clamp<double>(double(src[0]), -32768.0, 32767.0));
      std::memcpy(dst + 2 * x, &v, 2);
    } else {
      const float v = float(src[0]);
      std::memcpy(dst + 4 * x, &v, 4);
    }
  }
}

// Scratch reads are split so one OIIO call never needs more than this many
// bytes of native pixels, whatever the image width.
constexpr size_t kMaxScratchBytes = size_t(8) << 20;

enum class SampleKind { kU8, kU16, kI16, kF32 };

// One sample of the input converted to the target's bit depth (8 or 16).
template <typename T>
inline uint32_t convertSample(T v, bool to16, uint64_t* clamped);

template <>
inline uint32_t convertSample<uint8_t>(uint8_t v, bool to16, uint64_t*) {
  return to16 ? uint32_t(v) * 257u : v;
}
template <>
inline uint32_t convertSample<uint16_t>(uint16_t v, bool to16, uint64_t*) {
  // Rounded, exact for the 257 multiples that 8 -> 16 produces.
  return to16 ? v : (uint32_t(v) * 255u + 32767u) / 65535u;
}
template <>
inline uint32_t convertSample<int16_t>(int16_t v, bool to16, uint64_t* clamped) {
  // Signed elevations below zero (and no-data values) clamp to 0: R16 is unsigned.
  int32_t s = v;
  if (s < 0) {
    ++*clamped;
    s = 0;
  }
  const uint32_t u = uint32_t(s);
  return to16 ? u : (u * 255u + 32767u) / 65535u;
}
template <>
inline uint32_t convertSample<float>(float v, bool to16, uint64_t* clamped) {
  // Float colour is taken as display-referred [0, 1]; outside values clamp.
  if (!(v >= 0.0f)) {  // also catches NaN
    if (v != 0.0f) ++*clamped;
    v = 0.0f;
  } else if (v > 1.0f) {
    ++*clamped;
    v = 1.0f;
  }
  return uint32_t(v * (to16 ? 65535.0f : 255.0f) + 0.5f);
}

// Rec. 709 luma with integer weights summing to 10000.
inline uint32_t luma(uint32_t r, uint32_t g, uint32_t b) {
  return (2126u * r + 7152u * g + 722u * b + 5000u) / 10000u;
}

template <typename T>
void convertRow(const T* src, uint32_t nch, uint64_t width, PixelFormat format, uint8_t* dst,
                uint64_t* clamped) {
  const bool to16 = format == PixelFormat::kR16;
  const uint32_t max_value = to16 ? 65535u : 255u;
  for (uint64_t x = 0; x < width; ++x) {
    uint32_t c[4] = {0, 0, 0, max_value};
    for (uint32_t ch = 0; ch < nch && ch < 4; ++ch) c[ch] = convertSample<T>(src[ch], to16, clamped);
    src += nch;
    switch (format) {
      case PixelFormat::kR8:
        dst[0] = uint8_t(nch >= 3 ? luma(c[0], c[1], c[2]) : c[0]);
        dst += 1;
        break;
      case PixelFormat::kR16: {
        const uint32_t v = nch >= 3 ? luma(c[0], c[1], c[2]) : c[0];
        dst[0] = uint8_t(v & 0xff);
        dst[1] = uint8_t(v >> 8);
        dst += 2;
        break;
      }
      case PixelFormat::kRGB8:
        if (nch <= 2) {
          dst[0] = dst[1] = dst[2] = uint8_t(c[0]);
        } else {
          dst[0] = uint8_t(c[0]);
          dst[1] = uint8_t(c[1]);
          dst[2] = uint8_t(c[2]);
        }
        dst += 3;
        break;
      case PixelFormat::kRGBA8:
        if (nch <= 2) {
          dst[0] = dst[1] = dst[2] = uint8_t(c[0]);
          dst[3] = uint8_t(nch == 2 ? c[1] : 255u);
        } else {
          dst[0] = uint8_t(c[0]);
          dst[1] = uint8_t(c[1]);
          dst[2] = uint8_t(c[2]);
          dst[3] = uint8_t(nch == 4 ? c[3] : 255u);
        }
        dst += 4;
        break;
      case PixelFormat::kI16:
      case PixelFormat::kF32: break;  // convertHeightRow's
    }
  }
}

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
      return Status::ok();
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
                    native_pixel, dst + size_t(done + r) * dst_stride);
      }
      done += n;
    }
    return Status::ok();
  }

 private:
  // Converts one row of `width` native pixels into the store's format.
  void convertInto(const uint8_t* src, uint64_t width, bool fast_copy, size_t native_pixel,
                   uint8_t* out) {
    if (fast_copy) {
      std::memcpy(out, src, width * native_pixel);
      return;
    }
    const uint32_t nch = m_info.input_channels;
    uint64_t* clamped = &m_info.clamped_samples;
    if (m_info.format == PixelFormat::kI16 || m_info.format == PixelFormat::kF32) {
      switch (m_kind) {
        case SampleKind::kU8: convertHeightRow(src, nch, width, m_info.format, out); break;
        case SampleKind::kU16:
          convertHeightRow(reinterpret_cast<const uint16_t*>(src), nch, width, m_info.format, out);
          break;
        case SampleKind::kI16:
          convertHeightRow(reinterpret_cast<const int16_t*>(src), nch, width, m_info.format, out);
          break;
        case SampleKind::kF32:
          convertHeightRow(reinterpret_cast<const float*>(src), nch, width, m_info.format, out);
          break;
      }
      return;
    }
    switch (m_kind) {
      case SampleKind::kU8:
        convertRow(src, nch, width, m_info.format, out, clamped);
        break;
      case SampleKind::kU16:
        convertRow(reinterpret_cast<const uint16_t*>(src), nch, width, m_info.format, out, clamped);
        break;
      case SampleKind::kI16:
        convertRow(reinterpret_cast<const int16_t*>(src), nch, width, m_info.format, out, clamped);
        break;
      case SampleKind::kF32:
        convertRow(reinterpret_cast<const float*>(src), nch, width, m_info.format, out, clamped);
        break;
    }
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
      convertInto(src, width, fast_copy, native_pixel, dst + size_t(y - y0) * dst_stride);
    }
    return Status::ok();
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
  out->reset();
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    if (ec) return Status::error(ErrorCode::kIo, path + ": " + ec.message());
    return Status::error(ErrorCode::kNotFound, path + ": no such file");
  }
  if (!fs::is_regular_file(path, ec)) {
    return Status::error(ErrorCode::kIo, path + ": not a regular file");
  }
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
  // The store keeps pixels as the file stores them; a viewer that honours
  // the orientation tag would show the image turned or mirrored.
  const int orientation = spec.get_int_attribute("Orientation", 1);
  if (orientation != 1) {
    info.warnings.push_back(path + ": orientation tag " + std::to_string(orientation) +
                            " ignored: tiled as stored (not turned or mirrored as a viewer would show it)");
  }
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
  if (forced) {
    info.format = *forced;
  } else if (spec.nchannels == 1) {
    info.format = (kind == SampleKind::kU16 || kind == SampleKind::kI16) ? PixelFormat::kR16
                                                                         : PixelFormat::kR8;
  } else if (spec.nchannels == 3) {
    info.format = PixelFormat::kRGB8;
  } else {
    info.format = PixelFormat::kRGBA8;  // 2 (grey + alpha) and 4
  }
  // JPEG and PNG decode strictly top to bottom.
  const std::string fmt_name = input->format_name();
  info.sequential_only = !info.tiled && fmt_name != "tiff";
  *out = std::make_unique<OiioSource>(path, std::move(input), info, kind, read_type);
  return Status::ok();
}

}  // namespace
}  // namespace clipstream

extern "C" __attribute__((visibility("default"))) void clipstreamTilerOpenImageFile(
    const std::string* path, const std::optional<clipstream::PixelFormat>* forced,
    std::unique_ptr<clipstream::ImageSource>* out, clipstream::Status* status) {
  *status = clipstream::openOiio(*path, *forced, out);
}
