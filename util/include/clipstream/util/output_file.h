// The one rule for every file a clipstream program writes (stores, summaries,
// CSV/JSON, PNG frames, traces): the bytes go to a hidden temporary name in
// the output's directory, are checked (every write, fsync, close), and only
// then is the temporary renamed onto the final name, atomically and without
// replacing anything the program did not own. On any failure, or on a signal
// handled with removeOutputTemporaries(), nothing half-written remains under
// a final name. docs/decisions.md (D122-D132) gives the reasons.
//
// Temporary names: ".NAME.tmp-PID-RANDOM" (scratch files beside it add
// ".SUFFIX"). The writer holds an flock on its temporary while it lives, so a
// later create() for the same NAME can tell temporaries left by a killed run
// (SIGKILL, power loss) from those of a run still going: it removes the dead
// ones and reports them (swept()).
#pragma once

#include <clipstream/util/status.h>

#include <sys/stat.h>

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace clipstream {

// What create() and commit() may do with a file already at the final path.
enum class ExistingOutput {
  kRefuse,          // anything there is kAlreadyExists, at create() and again at commit()
  kReplaceRegular,  // a regular file there at create() is replaced, if unchanged at commit()
};

struct OutputOptions {
  ExistingOutput existing = ExistingOutput::kRefuse;
  bool fsync = true;  // flush the file (and its directory) before and after the rename
  // Remove temporaries of killed writers of the same name first (a scan of
  // the directory). Off for many small outputs in one directory whose owner
  // sweeps it once (clipstream-fly's frames), where a scan per file would
  // cost O(files^2).
  bool sweep = true;
};

// One output file being written.
//
// Thread rule: create(), append(), createScratch() and commit() from one
// thread at a time. fd() may be used for pwrite() from several threads
// (the store writer does) as long as commit() waits for them.
class OutputFile {
 public:
  // Checks the final path and creates the temporary. Fails with:
  //   kInvalidArgument  the path names a directory, or something that is not a
  //                     regular file (FIFO, device, socket, symbolic link);
  //                     only regular files are ever replaced
  //   kAlreadyExists    a regular file is there and options.existing is kRefuse
  //   kNotFound         the directory does not exist
  //   kIo / kNoSpace    the temporary cannot be created
  // Before creating its temporary it removes temporaries of the same NAME
  // whose writer is gone (see swept()).
  static Status create(const std::string& path, const OutputOptions& options,
                       std::unique_ptr<OutputFile>* out);
  // Removes the temporary and every scratch file unless commit() succeeded.
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  const std::string& path() const { return m_path; }
  const std::string& tempPath() const { return m_temp_path; }
  // The temporary, open read-write; valid until commit().
  int fd() const { return m_fd; }

  // Appends at the end of what append() wrote so far. kNoSpace on a full disk
  // (or a file-size limit), else kIo, naming the file.
  Status append(const void* data, size_t bytes);
  Status append(std::string_view text) { return append(text.data(), text.size()); }

  // Creates a scratch file "<temporary>.<suffix>" (never published; removed
  // by commit() and by the destructor, and by a signal handler). The caller
  // owns *fd and closes it.
  Status createScratch(const std::string& suffix, int* fd, std::string* path);

  // fsync (if asked), close (checked), then publishes the temporary under the
  // final name: with kRefuse only if nothing has appeared there meanwhile;
  // with kReplaceRegular only if what is there is still the file seen at
  // create() (same inode, size and modification time) or nothing. Otherwise
  // kAlreadyExists naming the path, and the temporary is removed. Scratch
  // files are removed either way. Call once.
  Status commit();

  // One line per temporary of an earlier, killed run that create() removed:
  // "NAME (12.3 MB)".
  const std::vector<std::string>& swept() const { return m_swept; }

 private:
  OutputFile() = default;
  void discard();

  std::string m_path;
  std::string m_directory;
  std::string m_temp_path;
  OutputOptions m_options;
  int m_fd = -1;
  int m_registry_slot = -1;
  uint64_t m_append_offset = 0;
  bool m_had_existing = false;
  struct stat m_existing {};
  bool m_committed = false;
  struct Scratch {
    std::string path;
    int registry_slot = -1;
  };
  std::vector<Scratch> m_scratch;
  std::vector<std::string> m_swept;
};

// create() + append(contents) + commit().
Status writeOutputFile(const std::string& path, std::string_view contents,
                       const OutputOptions& options);

// Checks, without creating anything, that create() would accept `path`:
// the up-front check programs make before long work.
Status checkOutputPath(const std::string& path, const OutputOptions& options);

// Removes the temporaries that killed writers left for the output `path`
// (what create() does first), appending one line per removal to *swept.
void sweepOutputTemporaries(const std::string& path, std::vector<std::string>* swept);

// True when `a` and `b` name the same existing file (symbolic links
// followed, hard links included).
bool sameFile(const std::string& a, const std::string& b);

// Removes every temporary and scratch file of every live OutputFile in this
// process. Async-signal-safe (only unlink()): for signal handlers, which then
// end the process. Paths longer than 4 KiB, or more than 256 files at once,
// are not covered (the next create() of that output sweeps them).
void removeOutputTemporaries();

}  // namespace clipstream
