// Fault injection: a TileSource wrapper that adds latency to every fetch
// and fails a chosen fraction of tiles (deterministically by key) or all of
// them, for the tests and for clipstream-fly's --fault-* options (a slow
// server, corrupt tiles). Part of the streamer library but not installed:
// a host has no use for it. The wrapper follows TileSource's thread rule.
#pragma once

#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <memory>

namespace clipstream {

struct FaultSpec {
  double latency_ms = 0.0;
  double fail_fraction = 0.0;     // 0..1, chosen by hashing the key
  ErrorCode fail_code = ErrorCode::kCorruptTile;
  uint32_t seed = 7;
};
std::shared_ptr<TileSource> makeFaultySource(std::shared_ptr<TileSource> inner,
                                             const FaultSpec& spec);

// True when the faulty source fails `key` (a pure function of key and seed),
// so tests know exactly which tiles fail.
bool failsTile(const FaultSpec& spec, const TileKey& key);

}  // namespace clipstream
