// Elevation stores: height units and the conversion of stored samples to
// heights. The sample formats themselves are codec.cpp's.
#include <clipstream/store/tile_store.h>

#include <cstring>

namespace clipstream {

bool isValidHeightUnits(uint32_t raw) { return raw >= 1 && raw <= 3; }

const char* heightUnitsName(HeightUnits units) {
  switch (units) {
    case HeightUnits::kMetre: return "metre";
    case HeightUnits::kFoot: return "foot";
    case HeightUnits::kUsSurveyFoot: return "US survey foot";
  }
  return "unknown";
}

double metresPerUnit(HeightUnits units) {
  switch (units) {
    case HeightUnits::kMetre: return 1.0;
    case HeightUnits::kFoot: return 0.3048;
    case HeightUnits::kUsSurveyFoot: return 1200.0 / 3937.0;
  }
  return 1.0;
}

double heightOfSample(PixelFormat format, const ElevationInfo& elevation, const uint8_t* pixel) {
  switch (format) {
    case PixelFormat::kR16: {
      uint16_t v;
      std::memcpy(&v, pixel, 2);
      return elevation.offset + elevation.scale * double(v);
    }
    case PixelFormat::kI16: {
      int16_t v;
      std::memcpy(&v, pixel, 2);
      return elevation.offset + elevation.scale * double(v);
    }
    case PixelFormat::kF32: {
      float v;
      std::memcpy(&v, pixel, 4);
      return double(v);
    }
    default: return 0.0;
  }
}

Status decodeTileHeights(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                         const ElevationInfo& elevation, const RawTile& raw,
                         std::span<float> heights) {
  const size_t count = size_t(geometry.tile_px) * geometry.tile_px;
  if (!isHeightFormat(geometry.format)) {
    return Status::error(ErrorCode::kUnsupported, std::string("pixel format ") +
                                                      pixelFormatName(geometry.format) +
                                                      " does not hold heights");
  }
  if (heights.size() != count) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "decode: height output holds " + std::to_string(heights.size()) +
                             " samples, expected " + std::to_string(count));
  }
  const size_t bpp = bytesPerPixel(geometry.format);
  if (geometry.format == PixelFormat::kF32) {
    // Same size as the output: decode in place.
    return decodeTile(geometry, encoding, raw,
                      std::span<uint8_t>(reinterpret_cast<uint8_t*>(heights.data()), count * 4));
  }
  thread_local std::vector<uint8_t> scratch;
  scratch.resize(geometry.tileBytes());
  Status status = decodeTile(geometry, encoding, raw, scratch);
  if (!status) return status;
  for (size_t i = 0; i < count; ++i) {
    heights[i] = float(heightOfSample(geometry.format, elevation, scratch.data() + i * bpp));
  }
  return okStatus();
}

}  // namespace clipstream
