// The hash of the streamer's own maps keyed by LayerTile. Thread-safe (a
// pure function).
#pragma once

#include <clipstream/streamer/streamer.h>

#include <cstddef>
#include <cstdint>

namespace clipstream {

static_assert(sizeof(LayerTile) == 16, "LayerTile is hashed as four words: no padding allowed");

// Probed thousands of times per plan change: a multiply-xorshift of the four
// fields is several times cheaper than hashing 16 bytes with XXH3 and mixes
// as well for grid coordinates. The layer shares the level's word (levels
// stay below 64).
struct FastKeyHash {
  size_t operator()(const LayerTile& t) const noexcept {
    const TileKey& k = t.key;
    uint64_t h = (uint64_t(k.x) << 32 | k.y) * 0x9E3779B97F4A7C15ull;
    h ^= (uint64_t(k.level) | uint64_t(t.layer) << 32) * 0xC2B2AE3D27D4EB4Full;
    h ^= h >> 29;
    h *= 0xBF58476D1CE4E5B9ull;
    return size_t(h ^ (h >> 32));
  }
};

}  // namespace clipstream
