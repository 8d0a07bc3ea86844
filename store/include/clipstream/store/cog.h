// Cloud-Optimized GeoTIFFs read directly as tile pyramids, without tiling
// them into a store first (docs/deployment.md, "Streaming a COG"). A COG
// (any tiled TIFF) on the local disk or behind an HTTP(S) URL is presented
// as a pyramid of 128 x 128 tiles with a store's geometry, so the streamer
// and the scenes use it like a store:
// - its internal tiles, of any power-of-two size from 16 to 4096, are cut
//   into 128 x 128 tiles (or put together from smaller ones) on the caller's
//   thread, each decoded internal tile kept a while for its neighbours;
// - its overviews are the pyramid's levels where their sizes are the
//   pyramid's (ceil(w / 2^l)); the levels it lacks (the last ones, below the
//   coarsest overview, or any between) are built from the level below with
//   the tiler's box filter, on demand, and kept;
// - its georeference is the store's (GeoTIFF tags, geotiff.h);
// - over HTTP, its header and tile tables are read once at open, each
//   tile's bytes by one range request, kept in the disk cache
//   (RemoteOptions::disk_cache_dir) like a store's.
// 8-bit grey, grey + alpha, RGB (JPEG's YCbCr included) and RGBA, and
// 16-bit grey, are read; compressions are those libtiff is built with
// (deflate, LZW, zstd, JPEG, WebP, LERC, ... on Debian). Heights, palettes,
// separate planes and striped files are refused with the command that
// converts them.
//
// Thread-safe: all const methods from any number of threads at once; no
// lock is held across I/O or decoding.
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace clipstream {

// Tile side of the pyramid a COG is presented as (the stores' default).
inline constexpr uint32_t kCogPyramidTilePx = 128;

// What a COG holds beside what StoreInfo says, for clipstream-info and logs.
struct CogLayout {
  uint32_t internal_tile_px = 0;  // the file's own tile side
  std::string compression;        // "deflate", "lzw", "zstd", "jpeg", "webp", ...
  uint32_t directories = 0;       // image directories in the file (masks included)
  // Per pyramid level: true where the file holds it (full image or an
  // overview), false where it is built from the level below.
  std::vector<bool> stored_levels;
  uint64_t header_bytes = 0;      // bytes read at open: header, directories, tile tables
};

class CogReader {
 public:
  // Opens a TIFF at `path` (a file or an http(s):// URL, read with
  // `remote`'s settings): reads its header, every directory and its tile
  // tables, and checks that it can be presented as a pyramid. kBadMagic
  // when it is no TIFF; kUnsupported naming what is not read (and the
  // command that converts it); kBadHeader for a damaged file.
  static Status open(const std::string& path, const RemoteOptions& remote, std::unique_ptr<CogReader>* out);
  ~CogReader();
  CogReader(const CogReader&) = delete;
  CogReader& operator=(const CogReader&) = delete;

  // Geometry (kCogPyramidTilePx tiles; R8, R16, RGB8 or RGBA8),
  // georeference and file size; encoding and elevation are defaults.
  const StoreInfo& info() const;
  const PyramidGeometry& geometry() const { return info().geometry; }
  const CogLayout& layout() const;

  // Tile `key` in the geometry's pixel format into `pixels` (exactly
  // geometry().tileBytes()), edge tiles padded clamp-to-edge like a
  // store's. *bytes_read: file bytes this call read (0 when the internal
  // tiles it needed were kept). kOutOfRange outside the pyramid;
  // kCorruptTile when a tile does not decode; kIo / kUnavailable from the
  // medium.
  Status readTile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* bytes_read) const;

  // Reader threads worth running: RemoteOptions::connections for a URL,
  // 0 (no preference) for a local file.
  unsigned suggestedReadThreads() const;
  // Requests, bytes and disk cache figures of a URL (zero for a file).
  RemoteStats remoteStats() const;
  // File bytes read so far (open included).
  uint64_t bytesRead() const;

 private:
  CogReader();
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

// What the tile store or the COG at `path` says about itself (the scenes
// read the georeference of their colour layer this way): a store's
// StoreInfo, or a COG's (CogReader::info()).
Status readRasterInfo(const std::string& path, const RemoteOptions& remote, StoreInfo* out);

}  // namespace clipstream
