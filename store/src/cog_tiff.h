// Private: libtiff's side of the COG reader (cog_reader.cpp): the client
// I/O that lets libtiff parse a file from the reader's bytes, the tags of a
// directory, what makes a full image unstreamable, and codec names.
//
// Thread rule: a TIFF handle opened by openClient() is used by one thread
// at a time; the functions are otherwise pure.
#pragma once

#include <tiffio.h>

#include <cstdint>
#include <string>

namespace clipstream::cog {

// Internal tile sides the reader cuts into the pyramid: powers of two in
// this range (GDAL's COG writer takes 16 to 4096).
inline constexpr uint32_t kMinInternalTilePx = 16;
inline constexpr uint32_t kMaxInternalTilePx = 4096;

// The bytes libtiff reads through a Client.
class FileBytes {
 public:
  virtual ~FileBytes() = default;
  // Reads up to `n` bytes at `offset`; returns how many (0 past the end or on failure).
  virtual size_t readHead(uint64_t offset, void* dst, size_t n) = 0;
  virtual uint64_t fileSize() const = 0;
};


// Opens a libtiff handle over `file` ("rm": read, no memory mapping), its
// errors caught per handle (nothing reaches stderr); null with *error set
// on failure. TIFFClose() closes it.
TIFF* openClient(FileBytes* file, const std::string& name, std::string* error);
// The first error libtiff reported on a handle of openClient()'s, "" if none.
std::string lastError(TIFF* tif);
// Forgets it (before a call whose failure should be reported alone).
void clearError(TIFF* tif);

// The tags of one image directory the reader looks at.
struct ImageFields {
  uint32_t subfile = 0, width = 0, height = 0, tile_w = 0, tile_h = 0;
  uint16_t samples = 1, bits = 1, format = SAMPLEFORMAT_UINT, planar = PLANARCONFIG_CONTIG,
           photometric = PHOTOMETRIC_MINISBLACK, compression = COMPRESSION_NONE;
};
ImageFields readFields(TIFF* tif);

// Why a full image cannot be streamed, with the command that converts it;
// empty when it can.
std::string refusalOf(const ImageFields& f);

// "deflate", "lzw", "zstd", "jpeg", "webp", ... for a TIFF compression.
std::string codecName(uint16_t compression);

}  // namespace clipstream::cog
