// Private: the tiler's side of a sharded run (`--shard K/N`, shard.h): the
// run fingerprint every shard of one run shares and the merge checks, and
// the band of the input a shard tiles as an image of its own
// (docs/tiler.md, "Sharded runs").
//
// Thread rule: runFingerprint() and cutShard() are free functions that may
// be called from any thread (they read files on the calling thread). A
// BandSource is an ImageSource: used by one thread at a time.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/tiler.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

// What a shard's tiles depend on, hashed (FNV-1a, 64 bit: the same on every
// machine and build): the input's size and its first and last 64 KiB (and
// every mosaic sheet's, `sheets`), the image size, pixel type and format,
// the georeference, and every option that changes a tile's bytes (tile size,
// zstd level, predictor, filter, linear light, mosaic, fill, shard count).
// The input's path, the shard index and options that only change how the
// run goes (threads, budget, payload order) are left out, so every shard of
// one run gets the same value. kIo naming the file when an input cannot be
// read.
Status runFingerprint(const TilerOptions& o, const SourceInfo& src, const GeoReference& geo,
                      const std::vector<std::string>& sheets, uint64_t* out);

// Rows [y0, y0 + height) of another source, as an image of their own: the
// band a shard tiles. Its pixels are the full image's, converted the same.
class BandSource final : public ImageSource {
 public:
  BandSource(std::unique_ptr<ImageSource> inner, uint64_t y0_px, uint64_t height_px);
  const SourceInfo& info() const override;
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override;

 private:
  std::unique_ptr<ImageSource> m_inner;
  uint64_t m_y0 = 0;
  mutable SourceInfo m_info;  // the inner one's, with the band's height
};

// Turns the whole input in *source into shard o.shard_index of
// o.shard_count: plans the band (planShard), fingerprints the run, fills
// *shard (the store's shard record) and replaces *source by the band.
// kUnsupported for an input that became an elevation store (`elevation`),
// planShard's kInvalidArgument, runFingerprint's kIo.
Status cutShard(const TilerOptions& o, const GeoReference& geo,
                const std::vector<std::string>& sheets, bool elevation,
                std::unique_ptr<ImageSource>* source, ShardInfo* shard);

}  // namespace clipstream
