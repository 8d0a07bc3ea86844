// The run fingerprint and the band of a sharded tiler run (shard_run.h).
#include "shard_run.h"

#include "gdal_module.h"

#include <clipstream/tiler/shard.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

namespace clipstream {
namespace {

// FNV-1a, 64 bit: the run fingerprint must be the same on every machine and
// build that runs a shard, which std::hash does not promise.
struct Fnv1a {
  uint64_t h = 0xcbf29ce484222325ull;
  void bytes(const void* data, size_t n) {
    const auto* p = static_cast<const uint8_t*>(data);
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
  }
  void u64(uint64_t v) { bytes(&v, sizeof(v)); }
  void text(const std::string& t) {
    u64(t.size());
    bytes(t.data(), t.size());
  }
};

// Up to 64 KiB from the start and the end of a file, and its size: enough
// to tell inputs apart without reading them whole in every shard. The path
// is left out on purpose: shards may see the input under different mounts.
Status hashFileSample(const std::string& path, Fnv1a* h) {
  constexpr size_t kSampleBytes = size_t(64) << 10;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return Status::error(ErrorCode::kIo, path + ": cannot open to fingerprint it");
  std::vector<uint8_t> buf(kSampleBytes);
  std::fseek(f, 0, SEEK_END);
  const long size = std::ftell(f);
  h->u64(uint64_t(size < 0 ? 0 : size));
  for (long at : {0L, std::max(0L, size - long(kSampleBytes))}) {
    std::fseek(f, at, SEEK_SET);
    const size_t n = std::fread(buf.data(), 1, buf.size(), f);
    h->bytes(buf.data(), n);
  }
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return Status::error(ErrorCode::kIo, path + ": read failed while fingerprinting it");
  return okStatus();
}

}  // namespace

Status runFingerprint(const TilerOptions& o, const SourceInfo& src, const GeoReference& geo,
                      const std::vector<std::string>& sheets, uint64_t* out) {
  Fnv1a h;
  h.text("clipstream shard run 1");
  if (o.input_path.empty()) {
    h.text("synthetic");
  } else if (std::error_code ec; !std::filesystem::exists(o.input_path, ec) && isGdalName(o.input_path)) {
    // A URL or another name only GDAL opens: the name is what the shards share.
    h.text("named");
    h.text(o.input_path);
  } else {
    Status s = hashFileSample(o.input_path, &h);
    if (!s) return s;
  }
  h.u64(o.mosaic ? 1 : 0);
  h.u64(o.fill);
  for (const std::string& sheet : sheets) {
    Status s = hashFileSample(sheet, &h);
    if (!s) return s;
  }
  h.u64(src.width_px);
  h.u64(src.height_px);
  h.text(src.input_type);
  h.u64(src.input_channels);
  h.u64(uint64_t(src.format));
  h.u64(o.tile_px);
  h.u64(uint64_t(o.zstd_level));
  h.u64(o.predictor ? 1 : 0);
  h.u64(uint64_t(o.filter));
  h.u64(o.linear_light ? 1 : 0);
  // What changes the pixels beyond the input: reprojection and no-data.
  h.text(o.target_crs);
  h.text(o.resampling);
  h.bytes(&o.target_resolution, sizeof o.target_resolution);
  h.u64(o.nodata ? 1 : 0);
  if (o.nodata) h.bytes(&*o.nodata, sizeof *o.nodata);
  h.u64(geo.present ? 1 : 0);
  h.bytes(geo.transform, sizeof(geo.transform));
  h.text(geo.crs);
  h.u64(o.shard_count);
  *out = h.h;
  return okStatus();
}

BandSource::BandSource(std::unique_ptr<ImageSource> inner, uint64_t y0_px, uint64_t height_px)
    : m_inner(std::move(inner)), m_y0(y0_px), m_info(m_inner->info()) {
  m_info.height_px = height_px;
}

const SourceInfo& BandSource::info() const {
  m_info.clamped_samples = m_inner->info().clamped_samples;
  return m_info;
}

Status BandSource::readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                            size_t dst_stride) {
  return m_inner->readRows(m_y0 + y0, rows, x0, width, dst, dst_stride);
}

Status cutShard(const TilerOptions& o, const GeoReference& geo,
                const std::vector<std::string>& sheets, bool elevation,
                std::unique_ptr<ImageSource>* source, ShardInfo* shard) {
  if (elevation) {
    return Status::error(ErrorCode::kUnsupported,
                         o.input_path + " becomes an elevation store, and elevation stores are "
                                        "not sharded (use --layer colour for a picture of it)");
  }
  const SourceInfo& whole = (*source)->info();
  ShardPlan plan;
  Status s = planShard(whole.width_px, whole.height_px, o.tile_px, o.shard_index, o.shard_count, &plan);
  if (!s) return s;
  shard->present = true;
  shard->index = o.shard_index;
  shard->count = o.shard_count;
  shard->full_width_px = whole.width_px;
  shard->full_height_px = whole.height_px;
  shard->y0_px = plan.y0_px;
  shard->owned_levels = plan.owned_levels;
  s = runFingerprint(o, whole, geo, sheets, &shard->fingerprint);
  if (!s) return s;
  *source = std::make_unique<BandSource>(std::move(*source), plan.y0_px, plan.height_px);
  return okStatus();
}

}  // namespace clipstream
