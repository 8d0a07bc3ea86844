// The paged texture memory's bookkeeping, without GL: which tile each page
// of the physical pool holds, which page a new tile may take, and which
// parts of each page (its border towards each neighbour, its mip 1) are
// filled. ClipmapRenderer (TextureMemory::kPaged) does the GL work it
// describes; docs/renderer.md, "Paged texture memory", tells the whole.
//
// Thread rule: owned by the GL thread, like ClipmapRenderer (it is plain
// data; nothing in it is shared).
#pragma once

#include <clipstream/store/types.h>

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace clipstream {

// The 8 neighbours of a tile, as bits: bit borderBit(dx, dy) for the
// neighbour at (x + dx, y + dy), dx and dy in {-1, 0, 1}, not both 0.
inline constexpr uint8_t kAllBorders = 0xff;
inline uint32_t borderBit(int dx, int dy) {
  const uint32_t i = uint32_t((dy + 1) * 3 + (dx + 1));  // 0..8, 4 is the tile itself
  return i < 4 ? i : i - 1;
}

class PageTable {
 public:
  static constexpr uint32_t kNoPage = ~uint32_t(0);
  // Mip 1 of a page that was never filled (PageTable::mip1From()).
  static constexpr uint16_t kMip1Empty = 0xffff;

  // Pages fall into `classes` classes (page p in class p % classes), and a
  // tile only ever takes a page of its class (classOf()): 1, or 4 by the
  // parity of the tile's x and y (ClipmapRenderer keeps four pages a layer,
  // a tile always in the same quarter of whichever layer it gets).
  explicit PageTable(uint32_t pages, uint32_t classes = 1);
  uint32_t classOf(const TileKey& key) const {
    return m_classes == 4 ? (key.x & 1u) + 2u * (key.y & 1u) : 0u;
  }

  uint32_t pages() const { return uint32_t(m_pages.size()); }
  uint32_t used() const { return uint32_t(m_by_key.size()); }
  uint32_t pinned() const { return m_pinned; }

  // The page holding `key`, or kNoPage.
  uint32_t find(const TileKey& key) const;

  // A page for `key` (which must not have one), of its class: a free page
  // if there is one, else the least recently used page that is not pinned
  // and was not used in `frame`; its tile loses the page (`*evicted`, when not null, is
  // set to that tile and `*had_evicted` to true). kNoPage when every page is
  // pinned or used in `frame`: the pool is over-subscribed. The new page
  // counts as used in `frame`, has no border and no mip 1 filled.
  uint32_t allocate(const TileKey& key, uint64_t frame, bool pin, TileKey* evicted = nullptr,
                    bool* had_evicted = nullptr);

  // Takes pages [first, end) out of the free pages: only allocateAt()
  // gives them (ClipmapRenderer keeps the black page and the pyramid
  // level's pages at fixed places, which the shader computes instead of
  // looking up).
  void reserve(uint32_t first, uint32_t end);
  // `page` (reserved, holding nothing, of `key`'s class) for `key`, pinned;
  // kNoPage when it is not such a page.
  uint32_t allocateAt(uint32_t page, const TileKey& key, uint64_t frame);

  // Marks `page` used in `frame`: allocate() will not take it this frame.
  void use(uint32_t page, uint64_t frame) { m_pages[page].last_used = frame; }
  uint64_t lastUsed(uint32_t page) const { return m_pages[page].last_used; }

  // Forgets every unpinned page's tile (a new source, a resize).
  void clearUnpinned();

  const TileKey& key(uint32_t page) const { return m_pages[page].key; }
  bool holds(uint32_t page) const { return m_pages[page].holds; }

  // Which of the page's 8 borders hold their neighbour's texels (or, at the
  // level's edge, the tile's own edge): bits of borderBit().
  uint8_t borders(uint32_t page) const { return m_pages[page].borders; }
  void addBorders(uint32_t page, uint8_t bits) { m_pages[page].borders |= bits; }
  // The parent page's borders() when this page's mip 1 was last copied from
  // it (kMip1Empty: never). Mip 1 is copied again when the parent has more.
  uint16_t mip1From(uint32_t page) const { return m_pages[page].mip1_from; }
  void setMip1From(uint32_t page, uint16_t parent_borders) { m_pages[page].mip1_from = parent_borders; }

  // Tiles keyed for the maps of this class and the renderer: level in the
  // top 6 bits, y in the next 29, x in the low 29.
  static uint64_t pack(const TileKey& key) {
    return (uint64_t(key.level) << 58) | (uint64_t(key.y) << 29) | uint64_t(key.x);
  }
  static TileKey unpack(uint64_t packed) {
    constexpr uint64_t kMask = (uint64_t(1) << 29) - 1;
    return TileKey{uint32_t(packed >> 58), uint32_t(packed & kMask), uint32_t((packed >> 29) & kMask)};
  }

 private:
  // Gives `page` (holding nothing, off the free lists) to `key`.
  uint32_t take(uint32_t page, const TileKey& key, uint64_t frame, bool pin);

  struct Page {
    TileKey key;
    bool holds = false;
    bool pinned = false;
    uint8_t borders = 0;
    uint16_t mip1_from = kMip1Empty;
    uint64_t last_used = 0;
  };
  std::vector<Page> m_pages;
  uint32_t m_classes = 1;
  std::vector<std::vector<uint32_t>> m_free;  // per class: pages holding nothing, taken from the back
  std::vector<bool> m_reserved;               // pages only allocateAt() gives
  std::unordered_map<uint64_t, uint32_t> m_by_key;
  uint32_t m_pinned = 0;
};

}  // namespace clipstream
