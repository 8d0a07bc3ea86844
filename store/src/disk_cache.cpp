// DiskCache: entries are files "<store key>/<name>" under the folder, each a
// 24-byte header (magic, format, a hash of its own path, content size) and
// the content. Written under "<store key>/tmp.<pid>.<n>" and renamed.
#include "disk_cache.h"

#include <clipstream/util/file_io.h>

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <map>

namespace clipstream {
namespace {

constexpr uint32_t kEntryMagic = 0x43445343;  // "CSDC" little-endian
constexpr uint32_t kEntryFormat = 1;
constexpr size_t kEntryHeaderBytes = 24;
// Temporaries older than this at open belong to a writer that died (a live
// one renames its entry within milliseconds).
constexpr time_t kStaleTemporaryS = 60;
constexpr const char* kTempPrefix = "tmp.";

uint64_t identity(const std::string& path) { return XXH3_64bits(path.data(), path.size()); }

void encodeHeader(const std::string& path, uint64_t bytes, uint8_t* out) {
  const uint64_t id = identity(path);
  std::memcpy(out, &kEntryMagic, 4);
  std::memcpy(out + 4, &kEntryFormat, 4);
  std::memcpy(out + 8, &id, 8);
  std::memcpy(out + 16, &bytes, 8);
}

bool isStoreKey(const char* name) {
  size_t n = 0;
  for (; name[n] != '\0'; ++n) {
    const char c = name[n];
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return n == 32;
}

// Reads `groups` runs of decimal digits separated by `separator` from *p.
bool digitGroups(const char* p, int groups, char separator) {
  for (int g = 0; g < groups; ++g) {
    if (g > 0 && *p++ != separator) return false;
    const char* start = p;
    while (*p >= '0' && *p <= '9') ++p;
    if (p == start || p - start > 20) return false;
  }
  return *p == '\0';
}

// The names this cache gives: "t<level>-<x>-<y>" (a tile payload),
// "p<level>-<x>-<y>" (an index page) and "tmp.<pid>.<n>" (being written).
bool isEntryName(const char* name) {
  return (name[0] == 't' || name[0] == 'p') && digitGroups(name + 1, 3, '-');
}
bool isTempName(const char* name) {
  return std::strncmp(name, kTempPrefix, std::strlen(kTempPrefix)) == 0 &&
         digitGroups(name + std::strlen(kTempPrefix), 2, '.');
}

// Whether the file at `full` is one this cache wrote: a regular file (not
// followed if a symlink; a FIFO is not opened for reading) that starts with
// this cache's header, of entry `path` unless `path` is null (a temporary,
// whose header names the entry it will become). A file shorter than a
// header, or whose header is zeros, counts as ours: a write a crash cut
// off, with nothing of anybody's in it.
bool isOurs(const std::string& full, const std::string* path) {
  const int fd = ::open(full.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
  if (fd < 0) return false;
  struct stat st {};
  uint8_t header[kEntryHeaderBytes] = {};
  bool ours = false;
  if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) {
    if (uint64_t(st.st_size) < kEntryHeaderBytes) {
      ours = true;
    } else if (fileio::preadAll(fd, header, sizeof header, 0, full).ok()) {
      uint32_t magic = 0, format = 0;
      uint64_t id = 0;
      std::memcpy(&magic, header, 4);
      std::memcpy(&format, header + 4, 4);
      std::memcpy(&id, header + 8, 8);
      const bool zeros = std::all_of(header, header + sizeof header, [](uint8_t b) { return b == 0; });
      ours = zeros || (magic == kEntryMagic && format == kEntryFormat &&
                       (path == nullptr || id == identity(*path)));
    }
  }
  ::close(fd);
  return ours;
}

// A store sub-folder this cache may use: a folder (not a symlink to one)
// of this user.
bool isOwnFolder(const std::string& full) {
  struct stat st {};
  return ::lstat(full.c_str(), &st) == 0 && S_ISDIR(st.st_mode) && st.st_uid == ::geteuid();
}

// The one DiskCache per folder of this process.
std::mutex g_registry_mutex;  // guards g_registry
std::map<std::string, std::weak_ptr<DiskCache>> g_registry;

}  // namespace

Status DiskCache::open(const std::string& dir, uint64_t cap_bytes, std::shared_ptr<DiskCache>* out) {
  if (dir.empty()) return Status::error(ErrorCode::kInvalidArgument, "empty disk cache folder");
  if (cap_bytes == 0) {
    return Status::error(ErrorCode::kInvalidArgument, "disk cache " + dir + ": a cap of 0 bytes");
  }
  if (::mkdir(dir.c_str(), 0777) != 0 && errno != EEXIST) {
    const int err = errno;
    return Status::error(err == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                         "cannot make the disk cache folder " + dir + ": " + fileio::errnoText(err));
  }
  char resolved[PATH_MAX];
  if (::realpath(dir.c_str(), resolved) == nullptr) {
    return Status::error(ErrorCode::kIo, "disk cache folder " + dir + ": " +
                                             fileio::errnoText(errno));
  }
  struct stat st {};
  if (::stat(resolved, &st) != 0 || !S_ISDIR(st.st_mode) ||
      ::access(resolved, R_OK | W_OK | X_OK) != 0) {
    return Status::error(ErrorCode::kIo, "disk cache folder " + dir +
                                             " is not a folder this program can write");
  }
  if (st.st_uid != ::geteuid()) {
    // Its other users could put files and links where this cache evicts.
    return Status::error(ErrorCode::kIo, "disk cache folder " + dir + " belongs to user " +
                                             std::to_string(st.st_uid) +
                                             ", not this one: give a folder of your own");
  }
  std::lock_guard<std::mutex> lock(g_registry_mutex);
  std::weak_ptr<DiskCache>& slot = g_registry[resolved];
  if (std::shared_ptr<DiskCache> cache = slot.lock()) {
    *out = std::move(cache);
    return okStatus();
  }
  auto cache = std::make_shared<DiskCache>(resolved, cap_bytes);
  if (Status s = cache->scan(); !s) return s;
  slot = cache;
  *out = std::move(cache);
  return okStatus();
}

std::string DiskCache::storeKey(const std::string& url, const std::string& version) {
  const std::string text = url + '\n' + version;
  const XXH128_hash_t hash = XXH3_128bits(text.data(), text.size());
  char out[33];
  std::snprintf(out, sizeof out, "%016llx%016llx", (unsigned long long)hash.high64,
                (unsigned long long)hash.low64);
  return out;
}

Status DiskCache::scan() {
  // Every entry of every store, oldest use first, then evict to the cap.
  struct Found {
    time_t mtime_s = 0;
    long mtime_ns = 0;
    std::string path;
    uint64_t bytes = 0;
  };
  std::vector<Found> found;
  DIR* top = ::opendir(m_dir.c_str());
  if (top == nullptr) {
    return Status::error(ErrorCode::kIo, "cannot read the disk cache folder " + m_dir + ": " +
                                             fileio::errnoText(errno));
  }
  const time_t now = ::time(nullptr);
  while (const dirent* store = ::readdir(top)) {
    if (!isStoreKey(store->d_name)) continue;  // not ours: left alone
    const std::string store_dir = m_dir + "/" + store->d_name;
    if (!isOwnFolder(store_dir)) {
      m_store_dirs[store->d_name] = false;  // a symlink or another user's: never used
      continue;
    }
    DIR* sub = ::opendir(store_dir.c_str());
    if (sub == nullptr) continue;
    m_store_dirs[store->d_name] = true;
    while (const dirent* file = ::readdir(sub)) {
      if (std::strcmp(file->d_name, ".") == 0 || std::strcmp(file->d_name, "..") == 0) continue;
      const std::string full = store_dir + "/" + file->d_name;
      const std::string path = std::string(store->d_name) + "/" + file->d_name;
      struct stat st {};
      const bool temp = isTempName(file->d_name);
      if (::lstat(full.c_str(), &st) != 0 || !S_ISREG(st.st_mode) ||
          !(temp || isEntryName(file->d_name)) || !isOurs(full, temp ? nullptr : &path)) {
        continue;  // not an entry: left alone, not counted
      }
      if (temp) {
        if (now - st.st_mtime > kStaleTemporaryS) ::unlink(full.c_str());
        continue;
      }
      found.push_back({st.st_mtim.tv_sec, st.st_mtim.tv_nsec, path, uint64_t(st.st_size)});
    }
    ::closedir(sub);
  }
  ::closedir(top);
  std::sort(found.begin(), found.end(), [](const Found& a, const Found& b) {
    return a.mtime_s != b.mtime_s ? a.mtime_s > b.mtime_s : a.mtime_ns > b.mtime_ns;
  });
  std::vector<std::string> doomed;
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    for (Found& f : found) {
      m_lru.push_back(f.path);  // newest first
      m_entries[f.path] = Entry{f.bytes, std::prev(m_lru.end())};
      m_bytes += f.bytes;
    }
    doomed = evict(0);
  }
  for (const std::string& path : doomed) removeEntry(path);
  return okStatus();
}

void DiskCache::forget(const std::string& path) {
  auto it = m_entries.find(path);
  if (it == m_entries.end()) return;
  m_bytes -= it->second.bytes;
  m_lru.erase(it->second.lru);
  m_entries.erase(it);
}

std::vector<std::string> DiskCache::evict(uint64_t extra) {
  std::vector<std::string> doomed;
  while (m_bytes + m_reserved + extra > m_cap_bytes && !m_lru.empty()) {
    const std::string path = m_lru.back();
    forget(path);
    doomed.push_back(path);
    ++m_evictions;
  }
  return doomed;
}

void DiskCache::removeEntry(const std::string& path) const {
  const std::string full = m_dir + "/" + path;
  if (isOurs(full, &path)) ::unlink(full.c_str());
}

bool DiskCache::usableStoreDir(const std::string& store_key) {
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    auto it = m_store_dirs.find(store_key);
    if (it != m_store_dirs.end()) return it->second;
  }
  const std::string store_dir = m_dir + "/" + store_key;
  if (::mkdir(store_dir.c_str(), 0777) != 0 && errno != EEXIST) return false;
  const bool usable = isOwnFolder(store_dir);
  std::lock_guard<std::mutex> lock(m_mutex);
  m_store_dirs[store_key] = usable;
  return usable;
}

DiskCache::Lookup DiskCache::get(const std::string& store_key, const std::string& name,
                                 size_t bytes, std::vector<uint8_t>* out) {
  const std::string path = entryPath(store_key, name);
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    if (m_entries.find(path) == m_entries.end()) return Lookup::kMiss;
  }
  const std::string full = m_dir + "/" + path;
  const int fd = ::open(full.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  bool ok = false;
  if (fd >= 0) {
    struct stat st {};
    uint8_t header[kEntryHeaderBytes];
    uint8_t expected[kEntryHeaderBytes];
    encodeHeader(path, bytes, expected);
    out->resize(bytes);
    ok = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) &&
         uint64_t(st.st_size) == kEntryHeaderBytes + bytes &&
         fileio::preadAll(fd, header, sizeof header, 0, full).ok() &&
         std::memcmp(header, expected, sizeof header) == 0 &&
         fileio::preadAll(fd, out->data(), bytes, kEntryHeaderBytes, full).ok();
    if (ok) ::futimens(fd, nullptr);  // recency for the next process's scan
    ::close(fd);
  }
  if (!ok && fd >= 0) {
    drop(store_key, name);  // torn or foreign: never served, fetched again
    return Lookup::kBad;
  }
  std::lock_guard<std::mutex> lock(m_mutex);
  if (!ok) {
    forget(path);  // gone (another process evicted it)
    return Lookup::kMiss;
  }
  auto it = m_entries.find(path);
  if (it != m_entries.end()) m_lru.splice(m_lru.begin(), m_lru, it->second.lru);
  return Lookup::kHit;
}

void DiskCache::put(const std::string& store_key, const std::string& name,
                    std::span<const uint8_t> bytes) {
  const uint64_t entry_bytes = kEntryHeaderBytes + bytes.size();
  if (entry_bytes > m_cap_bytes) return;  // would evict everything for one entry
  auto failed = [&](bool reserved) {
    std::lock_guard<std::mutex> lock(m_mutex);
    if (reserved) m_reserved -= entry_bytes;
    ++m_write_failures;
  };
  if (!usableStoreDir(store_key)) return failed(false);
  const std::string path = entryPath(store_key, name);
  const std::string full = m_dir + "/" + path;
  // Room first: the entry's bytes are reserved, evicting others, before its
  // temporary is written, so the folder never holds more than the cap.
  std::vector<std::string> doomed;
  bool known = false;
  bool reserved = false;
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    known = m_entries.count(path) != 0;
    forget(path);  // replaced by the rename below
    doomed = evict(entry_bytes);
    reserved = m_bytes + m_reserved + entry_bytes <= m_cap_bytes;
    if (reserved) m_reserved += entry_bytes;
  }
  for (const std::string& victim : doomed) removeEntry(victim);
  if (!reserved) return;  // the rest of the cap is being written by other threads
  // A file of this name that is not one of ours is never replaced.
  struct stat st {};
  if (!known && ::lstat(full.c_str(), &st) == 0 && !isOurs(full, &path)) return failed(true);
  static std::atomic<uint64_t> counter{0};
  const std::string temp = m_dir + "/" + store_key + "/" + kTempPrefix +
                           std::to_string(::getpid()) + "." + std::to_string(counter.fetch_add(1));
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0666);
  if (fd < 0) {
    // The sub-folder may have been removed by hand: check it on the next put.
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      m_store_dirs.erase(store_key);
    }
    return failed(true);
  }
  uint8_t header[kEntryHeaderBytes];
  encodeHeader(path, bytes.size(), header);
  const bool written = fileio::pwriteAll(fd, header, sizeof header, 0, temp).ok() &&
                       fileio::pwriteAll(fd, bytes.data(), bytes.size(), sizeof header, temp).ok();
  // No fsync: a torn entry fails the reader's checksum and is fetched again.
  const bool closed = ::close(fd) == 0;
  if (!written || !closed || ::rename(temp.c_str(), full.c_str()) != 0) {
    ::unlink(temp.c_str());
    return failed(true);
  }
  std::lock_guard<std::mutex> lock(m_mutex);
  m_reserved -= entry_bytes;
  forget(path);  // another thread's put of the same entry, replaced by this rename
  m_lru.push_front(path);
  m_entries[path] = Entry{entry_bytes, m_lru.begin()};
  m_bytes += entry_bytes;
}

void DiskCache::drop(const std::string& store_key, const std::string& name) {
  const std::string path = entryPath(store_key, name);
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    forget(path);
  }
  removeEntry(path);
}

DiskCache::Stats DiskCache::stats() const {
  std::lock_guard<std::mutex> lock(m_mutex);
  Stats s;
  s.entries = m_entries.size();
  s.bytes = m_bytes;
  s.evictions = m_evictions;
  s.write_failures = m_write_failures;
  return s;
}

}  // namespace clipstream
