// libtiff's side of the COG reader: client I/O, a directory's tags, what
// cannot be streamed (cog_tiff.h).
#include "cog_tiff.h"

#include <cstdarg>
#include <cstdio>

namespace clipstream::cog {
namespace {

// libtiff's view of a file: the reader's head and source, and a position.
struct Client {
  FileBytes* file = nullptr;
  uint64_t position = 0;
  std::string error;  // libtiff's first error message
};

tmsize_t clientRead(thandle_t handle, void* data, tmsize_t size) {
  Client* c = static_cast<Client*>(handle);
  if (size <= 0) return 0;
  const size_t n = c->file->readHead(c->position, data, size_t(size));
  c->position += n;
  return tmsize_t(n);
}
tmsize_t clientWrite(thandle_t, void*, tmsize_t) { return -1; }
toff_t clientSeek(thandle_t handle, toff_t offset, int whence) {
  Client* c = static_cast<Client*>(handle);
  if (whence == SEEK_SET) c->position = offset;
  else if (whence == SEEK_CUR) c->position += offset;
  else if (whence == SEEK_END) c->position = c->file->fileSize() + offset;
  return c->position;
}
int clientClose(thandle_t handle) {
  delete static_cast<Client*>(handle);
  return 0;
}
toff_t clientSize(thandle_t handle) { return static_cast<Client*>(handle)->file->fileSize(); }
int clientMap(thandle_t, void**, toff_t*) { return 0; }
void clientUnmap(thandle_t, void*, toff_t) {}

int onError(TIFF*, void* user, const char* module, const char* format, va_list ap) {
  Client* c = static_cast<Client*>(user);
  if (c->error.empty()) {
    char text[512];
    std::vsnprintf(text, sizeof text, format, ap);
    c->error = (module != nullptr && *module != '\0' ? std::string(module) + ": " : std::string()) + text;
  }
  return 1;  // handled: nothing reaches stderr
}
int onWarning(TIFF*, void*, const char*, const char*, va_list) { return 1; }

}  // namespace

TIFF* openClient(FileBytes* file, const std::string& name, std::string* error) {
  Client* client = new Client{file};
  TIFFOpenOptions* options = TIFFOpenOptionsAlloc();
  TIFFOpenOptionsSetErrorHandlerExtR(options, onError, client);
  TIFFOpenOptionsSetWarningHandlerExtR(options, onWarning, client);
  // "r": read; "m": no memory mapping (the client has none).
  TIFF* tif = TIFFClientOpenExt(name.c_str(), "rm", client, clientRead, clientWrite, clientSeek,
                                clientClose, clientSize, clientMap, clientUnmap, options);
  TIFFOpenOptionsFree(options);
  if (tif == nullptr) {
    // A failed open does not close the client.
    *error = client->error.empty() ? "not a TIFF libtiff reads" : client->error;
    delete client;
  }
  return tif;
}



std::string lastError(TIFF* tif) { return static_cast<Client*>(TIFFClientdata(tif))->error; }
void clearError(TIFF* tif) { static_cast<Client*>(TIFFClientdata(tif))->error.clear(); }

std::string codecName(uint16_t compression) {
  switch (compression) {
    case COMPRESSION_NONE: return "none";
    case COMPRESSION_LZW: return "lzw";
    case COMPRESSION_JPEG: return "jpeg";
    case COMPRESSION_ADOBE_DEFLATE:
    case COMPRESSION_DEFLATE: return "deflate";
    case COMPRESSION_PACKBITS: return "packbits";
    case COMPRESSION_ZSTD: return "zstd";
    case COMPRESSION_WEBP: return "webp";
    case COMPRESSION_LERC: return "lerc";
    case COMPRESSION_LZMA: return "lzma";
    default: {
      const TIFFCodec* codec = TIFFFindCODEC(compression);
      return codec != nullptr ? codec->name : "compression " + std::to_string(compression);
    }
  }
}


ImageFields readFields(TIFF* tif) {
  ImageFields f;
  TIFFGetField(tif, TIFFTAG_SUBFILETYPE, &f.subfile);
  TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &f.width);
  TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &f.height);
  TIFFGetField(tif, TIFFTAG_TILEWIDTH, &f.tile_w);
  TIFFGetField(tif, TIFFTAG_TILELENGTH, &f.tile_h);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &f.samples);
  TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &f.bits);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &f.format);
  TIFFGetFieldDefaulted(tif, TIFFTAG_PLANARCONFIG, &f.planar);
  TIFFGetFieldDefaulted(tif, TIFFTAG_COMPRESSION, &f.compression);
  TIFFGetField(tif, TIFFTAG_PHOTOMETRIC, &f.photometric);
  return f;
}

std::string refusalOf(const ImageFields& f) {
  const uint32_t tw = f.tile_w;
  if (tw != f.tile_h || tw < kMinInternalTilePx || tw > kMaxInternalTilePx || (tw & (tw - 1)) != 0)
    return "internal tiles of " + std::to_string(tw) + " x " + std::to_string(f.tile_h) +
           " px: only square power-of-two tiles of 16 to 4096 px are cut into the pyramid "
           "(gdal_translate -of COG -co BLOCKSIZE=512 IN OUT.tif)";
  if (f.format == SAMPLEFORMAT_INT || f.format == SAMPLEFORMAT_IEEEFP)
    return std::string("holds ") + (f.format == SAMPLEFORMAT_INT ? "signed integers" : "floating-point samples") +
           " (heights?), not colour: tile a DEM for the elevation layer (clipstream-tile DEM.tif dem.cstore)";
  if (f.planar != PLANARCONFIG_CONTIG)
    return "stores its bands in separate planes: rewrite it pixel-interleaved "
           "(gdal_translate -of COG -co INTERLEAVE=PIXEL IN OUT.tif)";
  if (f.photometric == PHOTOMETRIC_MINISWHITE)
    return "is grey with white as zero: rewrite it black-is-zero (gdal_translate -of COG -co PHOTOMETRIC=MINISBLACK IN "
           "OUT.tif)";
  if (f.photometric == PHOTOMETRIC_PALETTE)
    return "is paletted: expand it to RGB (gdal_translate -of COG -expand rgb IN OUT.tif)";
  if (f.photometric == PHOTOMETRIC_SEPARATED || f.photometric == PHOTOMETRIC_CIELAB ||
      f.photometric == PHOTOMETRIC_ICCLAB || f.photometric == PHOTOMETRIC_ITULAB)
    return "holds CMYK or Lab colour: convert it to RGB (gdal_translate -of COG -co PHOTOMETRIC=RGB IN OUT.tif)";
  if (f.photometric == PHOTOMETRIC_YCBCR && f.compression != COMPRESSION_JPEG)
    return "holds YCbCr samples without JPEG: convert it to RGB (gdal_translate -of COG IN OUT.tif)";
  const bool grey16 = f.bits == 16 && f.samples == 1;
  if (!(f.bits == 8 && f.samples >= 1 && f.samples <= 4) && !grey16)
    return std::to_string(f.samples) + " bands of " + std::to_string(f.bits) +
           " bits: COGs are read as 8-bit grey, grey + alpha, RGB or RGBA, or 16-bit grey; tile it instead "
           "(clipstream-tile IN OUT.cstore)";
  if (!TIFFIsCODECConfigured(f.compression))
    return "compressed with " + codecName(f.compression) + ", which this libtiff cannot decode";
  return {};
}

}  // namespace clipstream::cog
