// Paged texture memory bookkeeping. See page_table.h.
#include <clipstream/renderer/page_table.h>

#include <algorithm>

namespace clipstream {

PageTable::PageTable(uint32_t pages, uint32_t classes)
    : m_pages(pages), m_classes(classes == 4 ? 4 : 1), m_free(m_classes) {
  // Taken from the back: the lowest page of each class first.
  for (uint32_t p = pages; p-- > 0;) m_free[p % m_classes].push_back(p);
}

uint32_t PageTable::find(const TileKey& key) const {
  const auto it = m_by_key.find(pack(key));
  return it == m_by_key.end() ? kNoPage : it->second;
}

uint32_t PageTable::allocate(const TileKey& key, uint64_t frame, bool pin, TileKey* evicted,
                             bool* had_evicted) {
  if (had_evicted != nullptr) *had_evicted = false;
  uint32_t page = kNoPage;
  const uint32_t cls = classOf(key);
  std::vector<uint32_t>& free = m_free[cls];
  if (!free.empty()) {
    page = free.back();
    free.pop_back();
  } else {
    // The least recently used page no frame at or after `frame` needs. A
    // scan: a pool has at most a few thousand pages and a frame allocates
    // a few dozen.
    uint64_t oldest = frame;
    // A page holding nothing here is a reserved one (the free ones are in
    // the free list, which is empty): only allocateAt() gives it.
    for (uint32_t p = cls; p < m_pages.size(); p += m_classes) {
      const Page& c = m_pages[p];
      if (c.holds && !c.pinned && c.last_used < oldest) {
        oldest = c.last_used;
        page = p;
      }
    }
    if (page == kNoPage) return kNoPage;
    Page& victim = m_pages[page];
    m_by_key.erase(pack(victim.key));
    if (evicted != nullptr) *evicted = victim.key;
    if (had_evicted != nullptr) *had_evicted = true;
  }
  return take(page, key, frame, pin);
}

uint32_t PageTable::take(uint32_t page, const TileKey& key, uint64_t frame, bool pin) {
  Page& p = m_pages[page];
  p = Page{};
  p.key = key;
  p.holds = true;
  p.pinned = pin;
  p.last_used = frame;
  if (pin) ++m_pinned;
  m_by_key[pack(key)] = page;
  return page;
}

void PageTable::reserve(uint32_t first, uint32_t end) {
  end = std::min<uint32_t>(end, pages());
  if (m_reserved.empty()) m_reserved.assign(m_pages.size(), false);
  for (uint32_t p = first; p < end; ++p) {
    if (m_reserved[p] || m_pages[p].holds) continue;
    m_reserved[p] = true;
    std::vector<uint32_t>& free = m_free[p % m_classes];
    free.erase(std::find(free.begin(), free.end(), p));
  }
}

uint32_t PageTable::allocateAt(uint32_t page, const TileKey& key, uint64_t frame) {
  if (page >= pages() || m_reserved.empty() || !m_reserved[page] || m_pages[page].holds ||
      page % m_classes != classOf(key) || find(key) != kNoPage)
    return kNoPage;
  return take(page, key, frame, true);
}

void PageTable::clearUnpinned() {
  for (uint32_t p = 0; p < m_pages.size(); ++p) {
    Page& c = m_pages[p];
    if (!c.holds || c.pinned) continue;
    m_by_key.erase(pack(c.key));
    c = Page{};
    m_free[p % m_classes].push_back(p);
  }
}

}  // namespace clipstream
