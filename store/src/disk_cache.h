// Private: the persistent disk cache of stores read over HTTP, below the
// streamer's RAM cache. One folder, one sub-folder per store version (the
// hash of its URL and version), one file per index page or tile payload.
//
// Crash safety: an entry is written to a temporary name and renamed into
// place, without fsync. A crash may leave an entry short or garbled; the
// reader checks every entry it gets against the checksum its index (read
// from the server at open) records, exactly as it checks the server's
// bytes, and drop()s a bad one, which is then fetched again. So a torn
// entry costs a request, never a wrong tile.
//
// Size: room for an entry is made before it is written, by evicting least
// recently used entries (by bytes), so within one process the folder's
// entries and temporaries never hold more than the cap. Recency survives a
// restart through the files' modification times (a hit touches its file).
//
// What it touches: only what it wrote. The folder must belong to this
// user (open() refuses another's); a store sub-folder is used only if it is
// a real folder of this user (not a symlink); a file in it counts as an
// entry, and may be evicted, dropped or replaced, only if its name is one
// this cache gives (t<level>-<x>-<y>, p<level>-<x>-<y>, tmp.<pid>.<n>) and
// its header is this cache's (or it is shorter than a header or its header
// is zeros: a write a crash cut off). Anything else in the folder is left
// alone, whatever its name.
//
// Thread-safe: all methods, from any thread; no lock held across file I/O.
// Several processes may share a folder: each keeps the cap by its own
// count, made at open from the folder's contents (so N processes may
// together hold up to N caps), and an entry another process removed reads
// as a miss.
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/types.h>

#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

namespace clipstream {

class DiskCache {
 public:
  // The cache of folder `dir` in this process: made (and the folder with
  // it, if missing) on first use with `cap_bytes`; later calls for the same
  // folder share it and its first cap. kIo / kNotFound naming the folder
  // when it cannot be made or read; kInvalidArgument for a cap of 0.
  static Status open(const std::string& dir, uint64_t cap_bytes, std::shared_ptr<DiskCache>* out);

  // The sub-folder name of one store version: a hash of the URL and its
  // version text (ByteSource::version()).
  static std::string storeKey(const std::string& url, const std::string& version);

  enum class Lookup {
    kMiss,  // no such entry
    kHit,   // *out holds the content; the caller checks it (drop() if wrong)
    kBad,   // an entry of the wrong size or header (a torn write): removed
  };
  // Reads entry `name` of store `store_key` into *out if it is there with
  // exactly `bytes` bytes of content.
  Lookup get(const std::string& store_key, const std::string& name, size_t bytes,
             std::vector<uint8_t>* out);
  // What one reader's lookups found (RemoteStats' disk cache figures).
  struct Counts {
    std::atomic<uint64_t> hits{0};     // there, and accepted by the reader's check
    std::atomic<uint64_t> misses{0};   // not there, or dropped: read from the server
    std::atomic<uint64_t> dropped{0};  // there but torn, or rejected: removed
    bool folder_refused = false;       // the store's sub-folder is not ours to use (set at open)
    // These figures into a reader's RemoteStats.
    void fill(RemoteStats* stats) const {
      stats->disk_cache_hits = hits.load(std::memory_order_relaxed);
      stats->disk_cache_misses = misses.load(std::memory_order_relaxed);
      stats->disk_cache_dropped = dropped.load(std::memory_order_relaxed);
      stats->disk_cache_folders_refused = folder_refused ? 1 : 0;
    }
  };
  // get() for a reader that checks what it gets, as it checks the
  // server's bytes: true when an entry of `bytes` is there and `valid`
  // accepts it; an entry it rejects is removed. Counts the hit, the miss or
  // the dropped entry in *counts.
  template <typename Valid>
  bool getChecked(const std::string& store_key, const std::string& name, size_t bytes, std::vector<uint8_t>* out,
                  const Valid& valid, Counts* counts) {
    switch (get(store_key, name, bytes, out)) {
      case Lookup::kHit:
        if (valid(*out)) {
          counts->hits.fetch_add(1, std::memory_order_relaxed);
          return true;
        }
        drop(store_key, name);
        [[fallthrough]];
      case Lookup::kBad:
        counts->dropped.fetch_add(1, std::memory_order_relaxed);
        break;
      case Lookup::kMiss:
        break;
    }
    counts->misses.fetch_add(1, std::memory_order_relaxed);
    return false;
  }

  // Stores an entry (replacing one of the same name), then evicts least
  // recently used entries until the folder is under its cap. Failures
  // (disk full, permissions) are counted and otherwise ignored: the cache
  // only ever saves requests.
  void put(const std::string& store_key, const std::string& name, std::span<const uint8_t> bytes);
  // Removes an entry found wrong by the caller.
  void drop(const std::string& store_key, const std::string& name);

  // Whether store sub-folder `store_key` may be used (made if missing).
  bool usableStoreDir(const std::string& store_key);

  struct Stats {
    uint64_t entries = 0;
    uint64_t bytes = 0;          // content and entry headers, as counted against the cap
    uint64_t evictions = 0;      // entries removed to keep the cap
    uint64_t write_failures = 0; // puts that could not be written
  };
  Stats stats() const;
  const std::string& dir() const { return m_dir; }
  uint64_t capBytes() const { return m_cap_bytes; }

  DiskCache(std::string dir, uint64_t cap_bytes) : m_dir(std::move(dir)), m_cap_bytes(cap_bytes) {}

 private:
  struct Entry {
    uint64_t bytes = 0;
    std::list<std::string>::iterator lru;  // position in m_lru
  };
  Status scan();
  // Removes the index entry of `path` (mutex held); its file is left alone.
  void forget(const std::string& path);
  // Evicts until `extra` more bytes fit under the cap (mutex held); returns
  // the entries to remove, which the caller passes to removeEntry().
  std::vector<std::string> evict(uint64_t extra);
  // Unlinks entry `path` if it is still one of ours (name and header).
  void removeEntry(const std::string& path) const;
  std::string entryPath(const std::string& store_key, const std::string& name) const {
    return store_key + "/" + name;
  }

  const std::string m_dir;
  const uint64_t m_cap_bytes;
  mutable std::mutex m_mutex;  // guards everything below
  std::list<std::string> m_lru;  // relative paths, most recently used first
  std::unordered_map<std::string, Entry> m_entries;
  // Sub-folders checked: true if ours (usable), false if not (a symlink,
  // a file, another user's folder).
  std::unordered_map<std::string, bool> m_store_dirs;
  uint64_t m_bytes = 0;     // entries in m_entries
  uint64_t m_reserved = 0;  // entries being written (room made for them)
  uint64_t m_evictions = 0;
  uint64_t m_write_failures = 0;
};

}  // namespace clipstream
