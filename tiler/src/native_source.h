// The tiler's own readers for the formats most inputs come in: TIFF and
// BigTIFF through libtiff (tiff_source.cpp), JPEG through libjpeg-turbo
// (jpeg_source.cpp), PNG through libpng (png_source.cpp). They are tried
// before the OpenImageIO module, which costs ~0.6 s and ~120 MB to load
// (docs/decisions.md D33); every file or variant they leave alone goes to
// OpenImageIO.
// Conversion to the store's formats is pixel_convert.h's, the module's too,
// so both paths give the same bytes (tested).
//
// Thread rule: the open functions may be called from any thread; each
// source they make is used by one thread at a time (image_source.h), and
// may run decode workers of its own (TIFF) that it stops before returning.
#pragma once

#include <clipstream/tiler/image_source.h>

#include <cstddef>
#include <cstdio>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace clipstream {

// Opens `path` with the reader for its format (by its first bytes) when one
// covers the file. Sets *covered false, returning ok and opening nothing,
// when the file is of none of these formats or uses something left to
// OpenImageIO: TIFF with a palette, min-is-white, separate planes, odd bit
// depths, half floats or raw YCbCr; CMYK JPEG; PNG with a palette,
// transparency chunk, fewer than 8 bits or interlacing. Errors otherwise
// (*covered true): as openImageFile's, with the decoder's message.
Status openNativeImage(const std::string& path, std::optional<PixelFormat> forced,
                       const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                       bool* covered);

// The per-format openers behind openNativeImage, same contract; the file is
// known to exist and to start with the format's signature.
Status openTiffImage(const std::string& path, std::optional<PixelFormat> forced,
                     const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                     bool* covered);
Status openJpegImage(const std::string& path, std::optional<PixelFormat> forced,
                     const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                     bool* covered);
Status openPngImage(const std::string& path, std::optional<PixelFormat> forced,
                    const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                    bool* covered);

// Opens `path` for reading with stdio (what libjpeg and libpng read from);
// kIo naming the file and the reason otherwise.
Status openInputFile(const std::string& path, std::FILE** out);

// The Orientation tag (0x0112) of the first IFD of a TIFF-structured EXIF
// block (without the "Exif\0\0" prefix), every offset checked; 1 (as
// stored) when absent or unreadable.
uint16_t exifOrientation(const uint8_t* data, size_t size);

}  // namespace clipstream
