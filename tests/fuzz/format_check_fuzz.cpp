// libFuzzer driver for the tile store's format checks (store/src/
// format_check.h): runs every check the reader makes at open and on first
// use of an index page, in the reader's order, over the input held in
// memory; no file is written or read. Faster per input than store_fuzz,
// which drives the same checks through TileStoreReader and a file. Built
// only with -DCLIPSTREAM_FUZZ=ON (clang); scripts/test.sh runs it for a
// fixed time as a regression guard (docs/cli.md, "Fuzzing").
//
// Besides crashes and sanitizer reports it checks one promise of the
// checks: every region they accept (the level table, each page directory,
// the metadata block, each index page and each tile payload) lies inside
// the input. A region outside it aborts the run.
//
// Input: store_fuzz's (store_seeds.h: a control byte whose bit 0 re-seals,
// then the store bytes); its seeds are the same stores.
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./format_check_fuzz -runs=0   # write seed stores
//   ./format_check_fuzz -max_total_time=300 -timeout=10 corpus
#include "format.h"
#include "format_check.h"
#include "fuzz_util.h"
#include "store_seeds.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

namespace {

using namespace clipstream;

// The accepted region [offset, offset + bytes) of `file`; aborts when a
// check let it reach outside.
std::span<const uint8_t> accepted(std::span<const uint8_t> file, uint64_t offset, uint64_t bytes) {
  if (!fuzz::inFile(offset, bytes, file.size())) std::abort();
  return file.subspan(size_t(offset), size_t(bytes));
}

// Every index page of every level that the checks accept, and each tile
// payload its entries point to.
void checkPages(std::span<const uint8_t> file, const format::CheckedHeader& header,
                const format::IndexLayout& layout,
                const std::vector<std::vector<format::PageDirEntry>>& directories) {
  std::vector<format::TileEntry> entries;
  for (uint32_t l = 0; l < directories.size(); ++l) {
    const format::LevelEntry& level = layout.levels[l];
    for (size_t i = 0; i < directories[l].size(); ++i) {
      const format::PageDirEntry& dir = directories[l][i];
      if (dir.flags & format::kPageFlagConstant) continue;
      const uint32_t px = uint32_t(i % level.pages_x), py = uint32_t(i / level.pages_x);
      if (!format::checkIndexPage(accepted(file, dir.offset, dir.bytes), header, l, px, py,
                                  dir.checksum, level.payload_bytes, &entries)) {
        continue;
      }
      for (const format::TileEntry& entry : entries) {
        if (entry.stored_bytes == 0) continue;
        (void)accepted(file, level.payload_offset + entry.offset_or_value, entry.stored_bytes);
      }
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = fuzz::seedDir()) fuzz::writeSeeds(dir);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  std::vector<uint8_t> bytes(data + 1, data + size);
  if (data[0] & 1) fuzz::reseal(bytes);
  const std::span<const uint8_t> file(bytes);

  format::CheckedHeader header;
  const size_t prefix = std::min<size_t>(file.size(), format::kHeaderBytes);
  if (!format::checkHeader(file.first(prefix), file.size(), &header)) return 0;
  const format::Header& h = header.fields;
  format::IndexLayout layout;
  if (!format::checkLevelTable(accepted(file, h.level_table_offset, h.level_table_bytes), header,
                               &layout)) {
    return 0;
  }
  std::vector<std::vector<format::PageDirEntry>> directories(h.level_count);
  for (uint32_t l = 0; l < h.level_count; ++l) {
    uint64_t offset = 0;
    if (!format::checkDirectoryPlace(layout, l, &offset)) return 0;
    const std::span<const uint8_t> directory =
        accepted(file, offset, layout.levels[l].directory_bytes);
    if (!format::checkPageDirectory(directory, header, layout, l, &directories[l])) return 0;
  }
  StoreInfo info;
  if (!format::checkMetadata(accepted(file, h.metadata_offset, h.metadata_bytes), header, &info)) {
    return 0;
  }
  checkPages(file, header, layout, directories);
  return 0;
}
