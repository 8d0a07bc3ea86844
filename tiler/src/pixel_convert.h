// Conversion of decoded input samples to the store's pixel formats (and the
// orientation warning), shared
// by the tiler's own readers (native_source.cpp) and its OpenImageIO module
// (oiio_source.cpp), so both give the same bytes for the same samples
// (docs/decisions.md D24). Header-only and free of store
// symbols: the module links OpenImageIO alone.
//
// Thread rule: pure functions; any thread.
#pragma once

#include <clipstream/store/types.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

namespace clipstream::pixel_convert {

// A decoder's error text for one message line: libtiff and libjpeg report a
// damaged file once per strip or scanline, which would flood the terminal
// under our one error. Keeps the first line, control bytes shown as '?'.
inline std::string decoderMessage(const std::string& text, const char* fallback) {
  if (text.empty()) return fallback;
  const size_t end = text.find('\n');
  // (The OpenImageIO module is loaded on its own: no clipstream::printableText here.)
  std::string first = text.substr(0, std::min<size_t>(end, 300));
  for (char& c : first)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  size_t more = 0;
  for (size_t at = end; at != std::string::npos && at + 1 < text.size(); at = text.find('\n', at + 1)) ++more;
  if (more > 0) first += " (and " + std::to_string(more) + " more messages like it)";
  return first;
}

inline uint32_t formatChannels(PixelFormat f) {
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
inline void convertHeightRow(const T* src, uint32_t nch, uint64_t width, PixelFormat format,
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
inline void convertRow(const T* src, uint32_t nch, uint64_t width, PixelFormat format, uint8_t* dst,
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

// One row of `width` native pixels of `kind` with `nch` channels converted
// into `format`; `fast_copy` when the layouts already agree (8-bit samples,
// same channel count).
inline void convertNativeRow(SampleKind kind, const uint8_t* src, uint32_t nch, uint64_t width,
                             PixelFormat format, bool fast_copy, uint8_t* out, uint64_t* clamped) {
  if (fast_copy) {
    std::memcpy(out, src, width * nch);
    return;
  }
  if (format == PixelFormat::kI16 || format == PixelFormat::kF32) {
    switch (kind) {
      case SampleKind::kU8: convertHeightRow(src, nch, width, format, out); break;
      case SampleKind::kU16:
        convertHeightRow(reinterpret_cast<const uint16_t*>(src), nch, width, format, out);
        break;
      case SampleKind::kI16:
        convertHeightRow(reinterpret_cast<const int16_t*>(src), nch, width, format, out);
        break;
      case SampleKind::kF32:
        convertHeightRow(reinterpret_cast<const float*>(src), nch, width, format, out);
        break;
    }
    return;
  }
  switch (kind) {
    case SampleKind::kU8: convertRow(src, nch, width, format, out, clamped); break;
    case SampleKind::kU16:
      convertRow(reinterpret_cast<const uint16_t*>(src), nch, width, format, out, clamped);
      break;
    case SampleKind::kI16:
      convertRow(reinterpret_cast<const int16_t*>(src), nch, width, format, out, clamped);
      break;
    case SampleKind::kF32:
      convertRow(reinterpret_cast<const float*>(src), nch, width, format, out, clamped);
      break;
  }
}

// Bytes of one native sample.
inline size_t sampleBytes(SampleKind kind) {
  switch (kind) {
    case SampleKind::kU8: return 1;
    case SampleKind::kU16:
    case SampleKind::kI16: return 2;
    case SampleKind::kF32: return 4;
  }
  return 1;
}

// The store format a file of `nch` channels of `kind` becomes unless one is
// forced (image_source.h, openImageFile).
inline PixelFormat defaultFormat(uint32_t nch, SampleKind kind) {
  if (nch == 1) {
    return (kind == SampleKind::kU16 || kind == SampleKind::kI16) ? PixelFormat::kR16
                                                                  : PixelFormat::kR8;
  }
  return nch == 3 ? PixelFormat::kRGB8 : PixelFormat::kRGBA8;  // 2 (grey + alpha) and 4
}

inline const char* sampleKindName(SampleKind kind) {
  switch (kind) {
    case SampleKind::kU8: return "uint8";
    case SampleKind::kU16: return "uint16";
    case SampleKind::kI16: return "int16";
    case SampleKind::kF32: return "float";
  }
  return "?";
}

// The warning every reader gives for an orientation tag other than 1.
inline std::string orientationWarning(const std::string& path, int orientation) {
  // The store keeps pixels as the file stores them; a viewer that honours
  // the tag would show the image turned or mirrored.
  return path + ": orientation tag " + std::to_string(orientation) +
         " ignored: tiled as stored (not turned or mirrored as a viewer would show it)";
}

}  // namespace clipstream::pixel_convert
