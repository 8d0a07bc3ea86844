// The tables a benchmark prints, also written as tab-separated files that
// scripts/gen_benchmarks.sh renders into docs/benchmarks.md (--tsv FILE).
//
// Owned by the thread that prints. A file is written as FILE.tmp.PID and
// renamed to FILE by commit() once its table is whole, so a run that fails
// or is interrupted leaves the previous FILE as it was (written, fsynced,
// renamed: the rule of every writer here).
#pragma once

#include <unistd.h>

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <string>

namespace clipstream::bench {

// Removes "NAME VALUE" from argv (argc lowered) and returns VALUE, or "" when
// NAME is absent, so that the program's own parsing of its arguments sees
// what it always saw. NAME without a value is left for that parsing to reject.
inline std::string takeOption(int* argc, char** argv, const char* name) {
  for (int i = 1; i + 1 < *argc; ++i) {
    if (std::strcmp(argv[i], name) != 0) continue;
    std::string value = argv[i + 1];
    for (int j = i; j + 2 <= *argc; ++j) argv[j] = argv[j + 2];
    *argc -= 2;
    return value;
  }
  return "";
}

// One table: each row() goes to stdout and, when a path was given, to the
// file; fileOnly() to the file alone (for a program whose stdout shows the
// table in another form). Lines carry their own '\n'.
class TsvOut {
 public:
  explicit TsvOut(std::string path) : m_path(std::move(path)) {
    if (m_path.empty()) return;
    m_tmp = m_path + ".tmp." + std::to_string(::getpid());
    m_file = std::fopen(m_tmp.c_str(), "w");
    if (!m_file) std::fprintf(stderr, "cannot write %s: %s\n", m_tmp.c_str(), std::strerror(errno));
  }
  ~TsvOut() {
    if (!m_file) return;
    std::fclose(m_file);
    std::remove(m_tmp.c_str());  // not committed: the old file stays
  }
  TsvOut(const TsvOut&) = delete;
  TsvOut& operator=(const TsvOut&) = delete;

  // False when a path was given and its temporary could not be opened.
  bool ok() const { return m_path.empty() || m_file != nullptr; }

  __attribute__((format(printf, 2, 3))) void row(const char* format, ...) {
    va_list args;
    va_start(args, format);
    va_list copy;
    va_copy(copy, args);
    std::vprintf(format, args);
    if (m_file) std::vfprintf(m_file, format, copy);
    va_end(copy);
    va_end(args);
  }
  __attribute__((format(printf, 2, 3))) void fileOnly(const char* format, ...) {
    if (!m_file) return;
    va_list args;
    va_start(args, format);
    std::vfprintf(m_file, format, args);
    va_end(args);
  }

  // Closes the file and renames it into place; false, with a message, when
  // writing failed. Without a path: true.
  bool commit() {
    if (!m_file) return ok();
    const bool written = std::fflush(m_file) == 0 && !std::ferror(m_file) && ::fsync(::fileno(m_file)) == 0;
    const bool closed = std::fclose(m_file) == 0;
    m_file = nullptr;
    if (!written || !closed || std::rename(m_tmp.c_str(), m_path.c_str()) != 0) {
      std::fprintf(stderr, "cannot write %s: %s\n", m_path.c_str(), std::strerror(errno));
      std::remove(m_tmp.c_str());
      return false;
    }
    return true;
  }

 private:
  std::string m_path, m_tmp;
  std::FILE* m_file = nullptr;
};

}  // namespace clipstream::bench
