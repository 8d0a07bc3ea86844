// CPU-side clipmap rules: the toroidal slot rule and the usable map.
#include <clipstream/renderer/clipmap.h>
#include <clipstream/renderer/page_table.h>

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

TEST(PageTable, GivesFreePagesThenTheLeastRecentlyUsedUnpinnedOne) {
  PageTable t(4);
  const TileKey a{0, 1, 1}, b{0, 2, 1}, c{0, 3, 1}, d{1, 0, 0}, e{0, 9, 9};
  EXPECT_EQ(t.allocate(d, 1, true), 0u);  // pinned
  EXPECT_EQ(t.allocate(a, 1, false), 1u);
  EXPECT_EQ(t.allocate(b, 2, false), 2u);
  EXPECT_EQ(t.allocate(c, 3, false), 3u);
  EXPECT_EQ(t.used(), 4u);
  EXPECT_EQ(t.pinned(), 1u);
  t.use(1, 4);  // a is used again: b is now the oldest
  TileKey evicted{};
  bool had = false;
  EXPECT_EQ(t.allocate(e, 5, false, &evicted, &had), 2u);
  EXPECT_TRUE(had);
  EXPECT_EQ(evicted, b);
  EXPECT_EQ(t.find(b), PageTable::kNoPage);
  EXPECT_EQ(t.find(e), 2u);
  EXPECT_EQ(t.key(2), e);
  EXPECT_EQ(t.borders(2), 0u) << "a new page has no border filled";
  EXPECT_EQ(t.mip1From(2), PageTable::kMip1Empty);
}

TEST(PageTable, AFrameNeverTakesAPageItUsesAndAPinnedPageIsNeverTaken) {
  PageTable t(3);
  t.allocate(TileKey{2, 0, 0}, 7, true);
  t.allocate(TileKey{0, 0, 0}, 7, false);
  t.allocate(TileKey{0, 1, 0}, 7, false);
  // Every page pinned or used in frame 7: over-subscribed.
  EXPECT_EQ(t.allocate(TileKey{0, 2, 0}, 7, false), PageTable::kNoPage);
  EXPECT_EQ(t.find(TileKey{0, 2, 0}), PageTable::kNoPage);
  // In frame 8 the two unpinned pages are free to take, the pinned one not.
  const uint32_t p = t.allocate(TileKey{0, 2, 0}, 8, false);
  EXPECT_TRUE(p == 1u || p == 2u) << p;
  const uint32_t q = t.allocate(TileKey{0, 3, 0}, 8, false);
  EXPECT_TRUE((q == 1u || q == 2u) && q != p) << q;
  EXPECT_EQ(t.allocate(TileKey{0, 4, 0}, 8, false), PageTable::kNoPage);
  EXPECT_EQ(t.find(TileKey{2, 0, 0}), 0u);
  t.clearUnpinned();
  EXPECT_EQ(t.used(), 1u);
  EXPECT_EQ(t.find(TileKey{2, 0, 0}), 0u);
}

TEST(PageTable, BordersAndMip1Bookkeeping) {
  std::set<uint32_t> bits;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx)
      if (dx != 0 || dy != 0) bits.insert(borderBit(dx, dy));
  EXPECT_EQ(bits.size(), 8u);
  EXPECT_EQ(*bits.rbegin(), 7u);
  PageTable t(2);
  const uint32_t p = t.allocate(TileKey{0, 5, 5}, 1, false);
  t.addBorders(p, uint8_t(1u << borderBit(1, 0)));
  t.addBorders(p, uint8_t(1u << borderBit(-1, -1)));
  EXPECT_EQ(t.borders(p), uint8_t((1u << borderBit(1, 0)) | (1u << borderBit(-1, -1))));
  t.setMip1From(p, 0x0f);
  EXPECT_EQ(t.mip1From(p), 0x0f);
  // A page reused for another tile starts over.
  const uint32_t q = t.allocate(TileKey{0, 6, 5}, 2, false);
  const uint32_t r = t.allocate(TileKey{0, 7, 5}, 3, false);
  EXPECT_EQ(r, p);
  EXPECT_NE(q, p);
  EXPECT_EQ(t.borders(r), 0u);
  EXPECT_EQ(t.mip1From(r), PageTable::kMip1Empty);
}

TEST(PageTable, ReservedPagesAreGivenOnlyAtTheirPlaceAndStayPinned) {
  PageTable t(12, 4);
  t.reserve(4, 8);
  // Free pages never come from the reserved range, whatever the class.
  std::set<uint32_t> given;
  for (uint32_t i = 0; i < 8; ++i) given.insert(t.allocate(TileKey{0, i & 1, (i >> 1 & 1) + 2 * (i >> 2)}, 1, false));
  for (uint32_t p : given) EXPECT_TRUE(p < 4 || p >= 8) << p;
  EXPECT_EQ(given.size(), 8u);
  // Nor does eviction take one, though the reserved pages hold nothing.
  for (uint32_t i = 0; i < 8; ++i) {
    const uint32_t p = t.allocate(TileKey{2, i & 1, 10 + i}, 2 + i, false);
    EXPECT_TRUE(p < 4 || p >= 8) << p;
  }
  EXPECT_EQ(t.used(), 8u);
  EXPECT_EQ(t.find(TileKey{0, 0, 0}), PageTable::kNoPage);  // evicted, by its own page
  // A reserved page takes only a tile of its class, once.
  EXPECT_EQ(t.allocateAt(5, TileKey{3, 0, 0}, 2), PageTable::kNoPage);  // class 0, page class 1
  EXPECT_EQ(t.allocateAt(5, TileKey{3, 1, 0}, 2), 5u);
  EXPECT_EQ(t.allocateAt(5, TileKey{3, 3, 0}, 2), PageTable::kNoPage);  // holds a tile
  EXPECT_EQ(t.allocateAt(2, TileKey{3, 0, 1}, 2), PageTable::kNoPage);  // not reserved
  EXPECT_EQ(t.allocateAt(12, TileKey{3, 0, 0}, 2), PageTable::kNoPage);  // past the pool
  EXPECT_EQ(t.find(TileKey{3, 1, 0}), 5u);
  EXPECT_EQ(t.pinned(), 1u);
  // Eviction and clearUnpinned() leave the reserved pages alone, held or
  // not; the unreserved pages turn over.
  for (uint32_t i = 0; i < 8; ++i) {
    const uint32_t p = t.allocate(TileKey{1, i & 1, 40 + i}, 20 + i, false);
    EXPECT_TRUE(p < 4 || p >= 8) << p;
  }
  EXPECT_EQ(t.used(), 9u);
  t.clearUnpinned();
  EXPECT_EQ(t.find(TileKey{3, 1, 0}), 5u);
  EXPECT_EQ(t.used(), 1u);
  for (uint32_t i = 0; i < 8; ++i) {
    const uint32_t p = t.allocate(TileKey{1, i & 1, 60 + i}, 40 + i, false);
    EXPECT_TRUE(p < 4 || p >= 8) << p;
  }
}

}  // namespace
}  // namespace clipstream
