// OutputFile: temporary name, checked writes, atomic publish that replaces
// nothing it did not own, and a signal-safe registry of live temporaries.
#include <clipstream/util/output_file.h>

#include <clipstream/util/file_io.h>

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/file.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>
#include <random>

namespace clipstream {

namespace {

// ---- Registry of live temporaries, read by signal handlers ----------------
// Each slot is claimed with a compare-exchange (0 -> 1), filled, then marked
// ready (2). A handler unlinks only ready slots; release marks the slot busy
// before freeing it, so a handler never reads a path being rewritten.
constexpr size_t kRegistrySlots = 256;
constexpr size_t kRegistryPathBytes = 4096;
// States apart from the paths: the paths (1 MiB) stay untouched zero pages
// until used, so the registry costs no resident memory.
std::atomic<int> g_slot_state[kRegistrySlots];  // 0 free, 1 being written or released, 2 ready
char g_slot_path[kRegistrySlots][kRegistryPathBytes];

int registerTemporary(const std::string& path) {
  if (path.size() >= kRegistryPathBytes) return -1;
  for (size_t i = 0; i < kRegistrySlots; ++i) {
    int expected = 0;
    if (!g_slot_state[i].compare_exchange_strong(expected, 1)) continue;
    std::memcpy(g_slot_path[i], path.c_str(), path.size() + 1);
    g_slot_state[i].store(2);
    return int(i);
  }
  return -1;
}

void releaseTemporary(int slot) {
  if (slot < 0) return;
  g_slot_state[slot].store(1);
  g_slot_path[slot][0] = '\0';
  g_slot_state[slot].store(0);
}

Status errnoStatus(int err, const std::string& what) {
  const ErrorCode code = err == ENOSPC || err == EDQUOT || err == EFBIG ? ErrorCode::kNoSpace
                         : err == ENOENT                                ? ErrorCode::kNotFound
                                                                        : ErrorCode::kIo;
  return Status::error(code, what + ": " + fileio::errnoText(err));
}

const char* kindOf(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISLNK(mode)) return "a symbolic link";
  return "not a regular file";
}

bool sameIdentity(const struct stat& a, const struct stat& b) {
  return a.st_dev == b.st_dev && a.st_ino == b.st_ino && a.st_size == b.st_size &&
         a.st_mtim.tv_sec == b.st_mtim.tv_sec && a.st_mtim.tv_nsec == b.st_mtim.tv_nsec;
}

void splitPath(const std::string& path, std::string* directory, std::string* name) {
  const std::filesystem::path p(path);
  *directory = p.parent_path().string();
  if (directory->empty()) *directory = ".";
  *name = p.filename().string();
}

// Checks what is at `path` now. *exists tells whether a regular file is there
// (and *existing its identity).
Status inspectPath(const std::string& path, const OutputOptions& options, bool* exists,
                   struct stat* existing) {
  *exists = false;
  std::string directory, name;
  splitPath(path, &directory, &name);
  if (name.empty() || name == "." || name == "..") {
    return Status::error(ErrorCode::kInvalidArgument, "output path " + path + " names no file");
  }
  struct stat dir_stat {};
  if (::stat(directory.c_str(), &dir_stat) != 0) {
    const int err = errno;
    if (err == ENOENT) {
      return Status::error(ErrorCode::kNotFound,
                           path + ": output directory " + directory + " does not exist");
    }
    return Status::error(ErrorCode::kIo,
                         path + ": output directory " + directory + ": " + fileio::errnoText(err));
  }
  if (!S_ISDIR(dir_stat.st_mode)) {
    return Status::error(ErrorCode::kNotFound,
                         path + ": output directory " + directory + " is not a directory");
  }
  // Checked now rather than after the work (a read-only filesystem, a
  // directory without write permission).
  if (::access(directory.c_str(), W_OK | X_OK) != 0) {
    const int err = errno;
    return Status::error(ErrorCode::kIo, path + ": output directory " + directory +
                                             " is not writable: " + fileio::errnoText(err));
  }
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    const int err = errno;
    if (err == ENOENT) return okStatus();
    return errnoStatus(err, "output " + path);
  }
  if (!S_ISREG(st.st_mode)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + " is " + kindOf(st.st_mode) +
                             ", not a regular file; only regular files are written or replaced");
  }
  if (options.existing == ExistingOutput::kRefuse) {
    return Status::error(ErrorCode::kAlreadyExists, path + " already exists");
  }
  *exists = true;
  *existing = st;
  return okStatus();
}

bool processAlive(long pid) {
  if (pid <= 0) return true;  // unknown: assume alive
  return ::kill(pid_t(pid), 0) == 0 || errno == EPERM;
}

}  // namespace

// ---- Sweeping temporaries of killed runs -----------------------------------

namespace {

// Removes ".NAME.tmp-PID-RANDOM[.SUFFIX]" groups in `directory` whose main
// temporary is not locked by a live writer and whose PID is gone.
void sweepDeadTemporaries(const std::string& directory, const std::string& name,
                          std::vector<std::string>* swept) {
  const std::string prefix = "." + name + ".tmp-";
  DIR* dir = ::opendir(directory.c_str());
  if (!dir) return;
  std::map<std::string, std::vector<std::string>> groups;  // main name -> every member
  while (const dirent* entry = ::readdir(dir)) {
    const std::string entry_name = entry->d_name;
    if (entry_name.compare(0, prefix.size(), prefix) != 0) continue;
    const size_t dot = entry_name.find('.', prefix.size());
    groups[entry_name.substr(0, dot)].push_back(entry_name);
  }
  ::closedir(dir);
  for (const auto& [main_name, members] : groups) {
    // Only names this class makes: "PID-XXXXXXXX" (8 hex digits) after the
    // prefix, and scratch suffixes "idx" or "L<digits>".
    const std::string tail = main_name.substr(prefix.size());
    const size_t dash = tail.find('-');
    const bool digits = dash != std::string::npos && dash > 0 &&
                        tail.find_first_not_of("0123456789") == dash;
    if (!digits || tail.size() != dash + 9 ||
        tail.find_first_not_of("0123456789abcdef", dash + 1) != std::string::npos)
      continue;
    const long pid = std::strtol(tail.c_str(), nullptr, 10);
    if (processAlive(pid)) continue;
    const std::string main_path = directory + "/" + main_name;
    const int fd = ::open(main_path.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
    if (fd >= 0) {
      struct stat st {};
      if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) ||
          ::flock(fd, LOCK_EX | LOCK_NB) != 0) {
        ::close(fd);
        continue;  // a live writer (another host, another PID namespace)
      }
    }
    uint64_t bytes = 0;
    size_t removed = 0;
    for (const std::string& member : members) {
      if (member != main_name) {
        const std::string suffix = member.substr(main_name.size() + 1);
        const bool scratch = suffix == "idx" || (suffix.size() > 1 && suffix[0] == 'L' &&
                                                 suffix.find_first_not_of("0123456789", 1) == std::string::npos);
        if (!scratch) continue;
      }
      const std::string member_path = directory + "/" + member;
      struct stat st {};
      if (::lstat(member_path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
      if (::unlink(member_path.c_str()) == 0) {
        bytes += uint64_t(st.st_size);
        ++removed;
      }
    }
    if (fd >= 0) ::close(fd);
    if (removed == 0) continue;
    char text[64];
    std::snprintf(text, sizeof text, " (%zu file%s, %.1f MB)", removed, removed == 1 ? "" : "s",
                  double(bytes) / 1e6);
    swept->push_back(directory + "/" + main_name + text);
  }
}

}  // namespace

// ---- OutputFile -------------------------------------------------------------

Status OutputFile::create(const std::string& path, const OutputOptions& options,
                          std::unique_ptr<OutputFile>* out) {
  out->reset();
  std::unique_ptr<OutputFile> file(new OutputFile());
  file->m_path = path;
  file->m_options = options;
  std::string name;
  splitPath(path, &file->m_directory, &name);
  if (Status s = inspectPath(path, options, &file->m_had_existing, &file->m_existing); !s) return s;
  if (options.sweep) sweepDeadTemporaries(file->m_directory, name, &file->m_swept);

  std::random_device random;
  char suffix[64];
  std::snprintf(suffix, sizeof suffix, ".tmp-%ld-%08x", long(::getpid()), unsigned(random()));
  file->m_temp_path = file->m_directory + "/." + name + suffix;
  // Registered before it exists, so a signal in between still removes it.
  file->m_registry_slot = registerTemporary(file->m_temp_path);
  file->m_fd = ::open(file->m_temp_path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (file->m_fd < 0) {
    const int err = errno;
    releaseTemporary(file->m_registry_slot);
    file->m_registry_slot = -1;
    file->m_temp_path.clear();
    return errnoStatus(err, "cannot create a temporary file beside " + path);
  }
  // Held for the temporary's life: tells a later sweep this writer is alive.
  ::flock(file->m_fd, LOCK_EX | LOCK_NB);
  *out = std::move(file);
  return okStatus();
}

OutputFile::~OutputFile() { discard(); }

void OutputFile::discard() {
  if (m_fd >= 0) ::close(m_fd);
  m_fd = -1;
  for (Scratch& scratch : m_scratch) {
    ::unlink(scratch.path.c_str());
    releaseTemporary(scratch.registry_slot);
  }
  m_scratch.clear();
  if (!m_committed && !m_temp_path.empty()) ::unlink(m_temp_path.c_str());
  releaseTemporary(m_registry_slot);
  m_registry_slot = -1;
}

Status OutputFile::append(const void* data, size_t bytes) {
  if (m_fd < 0) return Status::error(ErrorCode::kInvalidArgument, m_path + ": already committed");
  Status s = fileio::pwriteAll(m_fd, data, bytes, m_append_offset, m_path);
  if (!s) return s;
  m_append_offset += bytes;
  return okStatus();
}

Status OutputFile::createScratch(const std::string& suffix, int* fd, std::string* path) {
  Scratch scratch;
  scratch.path = m_temp_path + "." + suffix;
  scratch.registry_slot = registerTemporary(scratch.path);
  *fd = ::open(scratch.path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (*fd < 0) {
    const int err = errno;
    releaseTemporary(scratch.registry_slot);
    return errnoStatus(err, "cannot create " + scratch.path);
  }
  *path = scratch.path;
  m_scratch.push_back(std::move(scratch));
  return okStatus();
}

Status OutputFile::commit() {
  if (m_fd < 0) return Status::error(ErrorCode::kInvalidArgument, m_path + ": committed twice");
  Status status;
  if (m_options.fsync && ::fsync(m_fd) != 0) status = errnoStatus(errno, "fsync " + m_temp_path);
  const int fd = m_fd;
  m_fd = -1;
  if (::close(fd) != 0 && status) status = errnoStatus(errno, "closing " + m_temp_path);
  if (!status) {
    discard();
    return status;
  }

  const std::string& from = m_temp_path;
  const std::string& to = m_path;
  const Status appeared = Status::error(
      ErrorCode::kAlreadyExists,
      to + " appeared or changed while it was being written (another program?); it was left as "
           "it is and this output was discarded");
  bool published = false;
  if (m_had_existing) {
    // Swap the new file in, then check that what came out is the file seen at
    // create(); if not, swap back: nothing that was not ours is replaced.
    if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_EXCHANGE) == 0) {
      struct stat old {};
      if (::lstat(from.c_str(), &old) == 0 && S_ISREG(old.st_mode) &&
          sameIdentity(old, m_existing)) {
        ::unlink(from.c_str());  // the replaced file, now under the temporary name
        published = true;
      } else {
        ::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_EXCHANGE);
        discard();
        return appeared;
      }
    } else if (errno == EINVAL || errno == ENOSYS) {
      // No RENAME_EXCHANGE on this filesystem: check, then rename.
      struct stat now {};
      if (::lstat(to.c_str(), &now) == 0) {
        if (!S_ISREG(now.st_mode) || !sameIdentity(now, m_existing)) {
          discard();
          return appeared;
        }
        if (::rename(from.c_str(), to.c_str()) != 0) {
          const Status s = errnoStatus(errno, "renaming " + from + " to " + to);
          discard();
          return s;
        }
        published = true;
      }
    } else if (errno != ENOENT) {
      const Status s = errnoStatus(errno, "renaming " + from + " to " + to);
      discard();
      return s;
    }
    // ENOENT: the old file went away meanwhile; publish as a new file.
  }
  if (!published) {
    if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) != 0) {
      const int err = errno;
      if (err == EEXIST) {
        discard();
        return appeared;
      }
      if (err != EINVAL && err != ENOSYS) {
        const Status s = errnoStatus(err, "renaming " + from + " to " + to);
        discard();
        return s;
      }
      // No RENAME_NOREPLACE: a hard link fails on an existing name too.
      if (::link(from.c_str(), to.c_str()) != 0) {
        const int link_err = errno;
        discard();
        return link_err == EEXIST ? appeared : errnoStatus(link_err, "linking " + from + " to " + to);
      }
      ::unlink(from.c_str());
    }
  }
  m_committed = true;
  if (m_options.fsync) {
    // Make the rename itself durable.
    const int dir_fd = ::open(m_directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dir_fd >= 0) {
      ::fsync(dir_fd);
      ::close(dir_fd);
    }
  }
  discard();
  return okStatus();
}

Status writeOutputFile(const std::string& path, std::string_view contents,
                       const OutputOptions& options) {
  std::unique_ptr<OutputFile> file;
  if (Status s = OutputFile::create(path, options, &file); !s) return s;
  if (Status s = file->append(contents); !s) return s;
  return file->commit();
}

Status checkOutputPath(const std::string& path, const OutputOptions& options) {
  bool exists = false;
  struct stat existing {};
  return inspectPath(path, options, &exists, &existing);
}

void sweepOutputTemporaries(const std::string& path, std::vector<std::string>* swept) {
  std::string directory, name;
  splitPath(path, &directory, &name);
  if (!name.empty()) sweepDeadTemporaries(directory, name, swept);
}

bool sameFile(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  return ::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0 && sa.st_dev == sb.st_dev &&
         sa.st_ino == sb.st_ino;
}

void removeOutputTemporaries() {
  for (size_t i = 0; i < kRegistrySlots; ++i) {
    if (g_slot_state[i].load() == 2) ::unlink(g_slot_path[i]);
  }
}

}  // namespace clipstream
