// CPU-side clipmap rules: the toroidal slot rule and the usable map.
#include <clipstream/renderer/clipmap.h>

#include <gtest/gtest.h>

#include <set>

namespace clipstream {
namespace {

TEST(ToroidalSlot, MapsAnyWindowOfClipTilesOneToOne) {
  const uint32_t clip = 7;
  for (int64_t start : {int64_t(-20), int64_t(0), int64_t(5), int64_t(1) << 40}) {
    std::set<uint32_t> slots;
    for (int64_t t = start; t < start + clip; ++t) {
      const uint32_t s = toroidalSlot(t, clip);
      EXPECT_LT(s, clip);
      slots.insert(s);
    }
    EXPECT_EQ(slots.size(), clip) << "window starting at " << start;
  }
  EXPECT_EQ(toroidalSlot(-1, clip), 6u);
  EXPECT_EQ(toroidalSlot(14, clip), 0u);
}

TEST(ToroidalSlot, MovingTheWindowRewritesOnlyTheEnteringSlots) {
  const uint32_t clip = 5;
  // Window [10, 15) moves to [12, 17): tiles 15 and 16 enter and must land in
  // exactly the slots tiles 10 and 11 leave.
  std::set<uint32_t> left{toroidalSlot(10, clip), toroidalSlot(11, clip)};
  std::set<uint32_t> entered{toroidalSlot(15, clip), toroidalSlot(16, clip)};
  EXPECT_EQ(left, entered);
}

PyramidGeometry geometry1024() {
  PyramidGeometry g;
  EXPECT_TRUE(makePyramidGeometry(1024, 1024, 64, PixelFormat::kRGBA8, &g));
  return g;  // 16, 8, 4, 2, 1 tiles a side
}

LevelResidency full(uint32_t level, TileRect window) {
  LevelResidency r;
  r.level = level;
  r.window = window;
  r.resident.assign(size_t(window.width() * window.height()), 1);
  return r;
}

uint8_t usableAt(const UsableMap& m, uint32_t level, int64_t x, int64_t y) {
  return m.usable[level][toroidalSlot(y, m.clip_tiles) * m.clip_tiles + toroidalSlot(x, m.clip_tiles)];
}

TEST(UsableMap, NeedsEveryNeighbourResidentAndInTheWindow) {
  const PyramidGeometry g = geometry1024();
  const uint32_t clip = 6, pyramid = 2;  // level 2 (4x4 tiles) fits
  std::vector<LevelResidency> res{full(0, {4, 4, 10, 10}), full(1, {0, 0, 6, 6})};
  res[0].resident[(6 - 4) * 6 + (6 - 4)] = 0;  // tile (6, 6) of level 0 missing
  const UsableMap m = computeUsableMap(g, clip, pyramid, res);
  EXPECT_EQ(usableAt(m, 0, 8, 5), 1);  // interior, neighbours all resident
  EXPECT_EQ(usableAt(m, 0, 4, 5), 0);  // window edge: neighbour (3, 5) outside the window
  EXPECT_EQ(usableAt(m, 0, 7, 7), 0);  // neighbour of the missing tile
  EXPECT_EQ(usableAt(m, 0, 6, 6), 0);  // the missing tile itself
  EXPECT_EQ(usableAt(m, 1, 0, 0), 1);  // image corner: outside neighbours only read padding
}

// A missing neighbour that no tap of the frame reads (LevelResidency::
// unread, the streamer's sampled plan) does not keep a tile from being
// drawn; one the frame may read still does, and so does the window's edge.
TEST(UsableMap, IgnoresMissingNeighboursTheFrameDoesNotRead) {
  const PyramidGeometry g = geometry1024();
  const uint32_t clip = 6, pyramid = 2;
  std::vector<LevelResidency> res{full(0, {4, 4, 10, 10}), full(1, {0, 0, 6, 6})};
  res[0].resident[(6 - 4) * 6 + (6 - 4)] = 0;  // tile (6, 6) of level 0 missing ...
  res[0].unread.assign(res[0].resident.size(), 0);
  res[0].unread[(6 - 4) * 6 + (6 - 4)] = 1;    // ... and never read this frame
  const UsableMap m = computeUsableMap(g, clip, pyramid, res);
  EXPECT_EQ(usableAt(m, 0, 7, 7), 1);  // its neighbour is drawn
  EXPECT_EQ(usableAt(m, 0, 6, 6), 0);  // the missing tile itself never is
  EXPECT_EQ(usableAt(m, 0, 4, 5), 0);  // the window edge still counts
  res[0].unread[(6 - 4) * 6 + (6 - 4)] = 0;
  EXPECT_EQ(usableAt(computeUsableMap(g, clip, pyramid, res), 0, 7, 7), 0) << "read: it blocks";
}

TEST(UsableMap, NeedsTheParentTileUsable) {
  const PyramidGeometry g = geometry1024();
  const uint32_t clip = 6, pyramid = 2;
  std::vector<LevelResidency> res{full(0, {4, 4, 10, 10}), full(1, {0, 0, 6, 6})};
  res[1].resident[3 * 6 + 3] = 0;  // level-1 tile (3, 3): parent of level-0 tiles 6..7
  const UsableMap m = computeUsableMap(g, clip, pyramid, res);
  EXPECT_EQ(usableAt(m, 0, 6, 6), 0);
  EXPECT_EQ(usableAt(m, 0, 8, 8), 0);  // its parent (4, 4) neighbours the missing tile
  EXPECT_EQ(usableAt(m, 1, 1, 1), 1);
}

TEST(UsableMap, NamesTheFinestUsableAncestorForFallback) {
  const PyramidGeometry g = geometry1024();
  const uint32_t clip = 6, pyramid = 2;
  std::vector<LevelResidency> res{full(0, {4, 4, 10, 10}), full(1, {0, 0, 6, 6})};
  res[0].resident[(6 - 4) * 6 + (6 - 4)] = 0;  // level-0 tile (6, 6) missing
  const UsableMap m = computeUsableMap(g, clip, pyramid, res);
  auto finest = [&](uint32_t level, int64_t x, int64_t y) {
    return m.finest[level][toroidalSlot(y, clip) * clip + toroidalSlot(x, clip)];
  };
  EXPECT_EQ(finest(0, 8, 8), 0);  // usable itself
  EXPECT_EQ(finest(0, 6, 6), 1);  // its parent (3, 3) on level 1 is usable
  EXPECT_EQ(finest(0, 4, 4), 1);  // window edge: parent (2, 2)
  res[1].resident.assign(res[1].resident.size(), 0);
  const UsableMap none = computeUsableMap(g, clip, pyramid, res);
  EXPECT_EQ(none.finest[0][toroidalSlot(6, clip) * clip + toroidalSlot(6, clip)], pyramid);
}

TEST(UsableMap, CodeTellsTilesSharingASlotApart) {
  const uint32_t slots = 6;
  for (int64_t t = 0; t < 40; ++t) {
    EXPECT_NE(usableCode(t, 3, slots), usableCode(t + slots, 3, slots));
    EXPECT_NE(usableCode(3, t, slots), usableCode(3, t - int64_t(slots), slots));
    EXPECT_NE(usableCode(t, 3, slots), 0);
  }
}

TEST(UsableMap, CodesOfTheSixteenPeriodsDifferAndNoneIsZero) {
  const uint32_t slots = 22;
  std::set<uint8_t> codes;
  for (int64_t py = 0; py < 4; ++py)
    for (int64_t px = 0; px < 4; ++px) {
      const uint8_t code = usableCode(px * slots + 5, py * slots + 7, slots);
      EXPECT_NE(code, 0);
      EXPECT_LE(code, kUsableCodeMax);
      codes.insert(code);
    }
  EXPECT_EQ(codes.size(), 16u);
}

TEST(UsableMap, RejectsAResidencyArrayOfTheWrongSize) {
  const PyramidGeometry g = geometry1024();
  LevelResidency bad = full(0, {0, 0, 4, 4});
  bad.resident.resize(3);
  const UsableMap m = computeUsableMap(g, 6, 2, {bad});
  for (uint8_t u : m.usable[0]) EXPECT_EQ(u, 0);
}

}  // namespace
}  // namespace clipstream
