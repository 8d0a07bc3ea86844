// The boundary between the tiler and its OpenImageIO module. The module is
// loaded with dlopen on the first file open (image_source.cpp) and exports
// one C-linkage entry point with this signature.
#pragma once

#include <clipstream/tiler/image_source.h>

#include <memory>
#include <optional>
#include <string>

namespace clipstream {

inline constexpr const char* kOiioModuleFileName = "libclipstream_tiler_oiio.so";
inline constexpr const char* kOiioModuleSymbol = "clipstreamTilerOpenImageFile";

// Same contract as openImageFile(); results through pointers because the
// symbol has C linkage.
using OpenImageFileFn = void (*)(const std::string* path, const std::optional<PixelFormat>* forced,
                                 std::unique_ptr<ImageSource>* out, Status* status);

}  // namespace clipstream
