// OutputFile: the one rule for every file the programs write. Each test
// breaks one promise on purpose: a device or FIFO at the path, a file that
// appears or changes while the output is written, a writer killed mid-way,
// a full disk, a signal.
#include <clipstream/util/output_file.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

namespace clipstream {
namespace {

using test::readText;

class OutputFileTest : public ::testing::Test {
 protected:
  std::string file(const std::string& name) const { return m_dir.file(name); }
  std::vector<std::string> entries() const { return m_dir.entries(); }

  test::TempDir m_dir{"output"};
};

TEST_F(OutputFileTest, PublishesOnlyAtCommitAndLeavesNoTemporary) {
  const std::string path = file("out.txt");
  std::unique_ptr<OutputFile> out;
  ASSERT_TRUE(OutputFile::create(path, {}, &out).ok());
  ASSERT_TRUE(out->append("hello ").ok());
  ASSERT_TRUE(out->append("world").ok());
  EXPECT_FALSE(std::filesystem::exists(path)) << "visible before commit";
  ASSERT_TRUE(out->commit().ok());
  EXPECT_EQ(readText(path), "hello world");
  EXPECT_EQ(entries(), std::vector<std::string>{"out.txt"});
}

TEST_F(OutputFileTest, DestroyingAnUncommittedOutputRemovesEverything) {
  const std::string path = file("out.txt");
  {
    std::unique_ptr<OutputFile> out;
    ASSERT_TRUE(OutputFile::create(path, {}, &out).ok());
    ASSERT_TRUE(out->append("partial").ok());
    int fd = -1;
    std::string scratch;
    ASSERT_TRUE(out->createScratch("idx", &fd, &scratch).ok());
    ::close(fd);
    EXPECT_EQ(entries().size(), 2u);
  }
  EXPECT_TRUE(entries().empty()) << entries().front();
}

// Bug: --force turned /dev/null (and FIFOs) into regular files.
TEST_F(OutputFileTest, NeverReplacesAFifoADeviceOrASymlink) {
  const std::string fifo = file("fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  const std::string target = file("target.txt");
  { std::ofstream(target) << "precious"; }
  const std::string link = file("link");
  std::filesystem::create_symlink(target, link);
  std::vector<std::string> paths = {fifo, link};
  // A character device like /dev/null, made here (needs root; skipped otherwise).
  const std::string device = file("null");
  if (::mknod(device.c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0) paths.push_back(device);
  for (const std::string& path : paths) {
    for (ExistingOutput existing : {ExistingOutput::kRefuse, ExistingOutput::kReplaceRegular}) {
      OutputOptions options;
      options.existing = existing;
      std::unique_ptr<OutputFile> out;
      const Status s = OutputFile::create(path, options, &out);
      EXPECT_EQ(s.code, ErrorCode::kInvalidArgument) << path << ": " << s.toString();
      EXPECT_NE(s.message.find("not a regular file"), std::string::npos) << s.message;
      EXPECT_FALSE(writeOutputFile(path, "x", options).ok()) << path;
    }
  }
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  ASSERT_EQ(::lstat(link.c_str(), &st), 0);
  EXPECT_TRUE(S_ISLNK(st.st_mode));
  EXPECT_EQ(readText(target), "precious");
  if (paths.size() == 3) {
    ASSERT_EQ(::lstat(device.c_str(), &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
  }
}

// Bug: the no-overwrite check ran only at the start, so a file created at
// the output path during the run was silently replaced.
TEST_F(OutputFileTest, AFileThatAppearsDuringTheWriteIsNotReplaced) {
  const std::string path = file("out.cst");
  std::unique_ptr<OutputFile> out;
  ASSERT_TRUE(OutputFile::create(path, {}, &out).ok());
  ASSERT_TRUE(out->append("store bytes").ok());
  { std::ofstream(path) << "precious"; }
  const Status s = out->commit();
  EXPECT_EQ(s.code, ErrorCode::kAlreadyExists) << s.toString();
  EXPECT_EQ(readText(path), "precious");
  EXPECT_EQ(entries(), std::vector<std::string>{"out.cst"});
}

TEST_F(OutputFileTest, ReplaceTakesOnlyTheFileSeenAtCreate) {
  OutputOptions replace;
  replace.existing = ExistingOutput::kReplaceRegular;
  const std::string path = file("out.cst");
  // Unchanged: replaced.
  { std::ofstream(path) << "old"; }
  ASSERT_TRUE(writeOutputFile(path, "new", replace).ok());
  EXPECT_EQ(readText(path), "new");
  // Rewritten in place while the output was being written: kept.
  std::unique_ptr<OutputFile> out;
  ASSERT_TRUE(OutputFile::create(path, replace, &out).ok());
  ASSERT_TRUE(out->append("mine").ok());
  { std::ofstream(path) << "someone else's, longer"; }
  EXPECT_EQ(out->commit().code, ErrorCode::kAlreadyExists);
  EXPECT_EQ(readText(path), "someone else's, longer");
  // Replaced by another file (another inode) meanwhile: kept.
  ASSERT_TRUE(OutputFile::create(path, replace, &out).ok());
  ASSERT_TRUE(out->append("mine").ok());
  { std::ofstream(file("other")) << "other"; }
  std::filesystem::rename(file("other"), path);
  EXPECT_EQ(out->commit().code, ErrorCode::kAlreadyExists);
  EXPECT_EQ(readText(path), "other");
  // Removed meanwhile: the output is published into the empty place.
  ASSERT_TRUE(OutputFile::create(path, replace, &out).ok());
  ASSERT_TRUE(out->append("mine").ok());
  std::filesystem::remove(path);
  EXPECT_TRUE(out->commit().ok());
  EXPECT_EQ(readText(path), "mine");
  EXPECT_EQ(entries(), std::vector<std::string>{"out.cst"});
}

TEST_F(OutputFileTest, RefuseReportsAnExistingFileUpFront) {
  const std::string path = file("out.cst");
  { std::ofstream(path) << "precious"; }
  EXPECT_EQ(checkOutputPath(path, {}).code, ErrorCode::kAlreadyExists);
  std::unique_ptr<OutputFile> out;
  EXPECT_EQ(OutputFile::create(path, {}, &out).code, ErrorCode::kAlreadyExists);
  EXPECT_EQ(checkOutputPath(file("missing/out.cst"), {}).code, ErrorCode::kNotFound);
  EXPECT_EQ(checkOutputPath(m_dir.path().string(), {}).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(readText(path), "precious");
}

// Bug: temporaries of a SIGKILLed writer (80-130 MB each) were never swept
// or reported. A live writer's temporaries must survive the sweep.
TEST_F(OutputFileTest, TemporariesOfAKilledWriterAreSweptAndReported) {
  const std::string path = file("out.cst");
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    std::unique_ptr<OutputFile> out;
    int fd = -1;
    std::string scratch;
    if (!OutputFile::create(path, {}, &out).ok() || !out->append(std::string(4096, 'x')).ok() ||
        !out->createScratch("L1", &fd, &scratch).ok())
      ::_exit(1);
    (void)!::write(ready[1], "r", 1);
    ::pause();  // killed here
    ::_exit(0);
  }
  ::close(ready[1]);
  char byte = 0;
  ASSERT_EQ(::read(ready[0], &byte, 1), 1);
  ::close(ready[0]);
  // While the writer lives, its temporaries are not touched.
  std::vector<std::string> swept;
  sweepOutputTemporaries(path, &swept);
  EXPECT_TRUE(swept.empty());
  EXPECT_EQ(entries().size(), 2u);
  ::kill(pid, SIGKILL);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_EQ(entries().size(), 2u) << "SIGKILL leaves the temporaries";
  // A live writer of the same output in this process is left alone too.
  std::unique_ptr<OutputFile> live;
  ASSERT_TRUE(OutputFile::create(path, {}, &live).ok());
  ASSERT_EQ(live->swept().size(), 1u);
  EXPECT_NE(live->swept()[0].find("(2 files, 0.0 MB)"), std::string::npos) << live->swept()[0];
  EXPECT_EQ(entries().size(), 1u) << "only the live writer's temporary is left";
  std::unique_ptr<OutputFile> second;
  ASSERT_TRUE(OutputFile::create(path, {}, &second).ok());
  EXPECT_TRUE(second->swept().empty());
  EXPECT_EQ(entries().size(), 2u);
}

// The sweep removes only names OutputFile makes, of writers that are gone,
// and regular files only.
TEST_F(OutputFileTest, TheSweepTouchesOnlyItsOwnNames) {
  const std::string path = file("out.cst");
  const std::vector<std::string> foreign = {
      ".out.cst.tmp-999999999-abcdef12.mydata", ".out.cst.tmp-zz", ".out.cst.tmp-999999999-abcdef1",
      ".out.cst.tmp-999999999-abcdef12x", ".out.cst.tmp-999999999-ABCDEF12", ".other.cst.tmp-999999999-abcdef12"};
  for (const std::string& name : foreign) std::ofstream(file(name)) << "keep";
  std::filesystem::create_symlink(file("target"), file(".out.cst.tmp-999999999-00000000"));
  std::ofstream(file(".out.cst.tmp-999999999-12345678")) << "stale";
  std::ofstream(file(".out.cst.tmp-999999999-12345678.L3")) << "stale";
  std::vector<std::string> swept;
  sweepOutputTemporaries(path, &swept);
  ASSERT_EQ(swept.size(), 1u);
  EXPECT_NE(swept[0].find(".out.cst.tmp-999999999-12345678 (2 files"), std::string::npos) << swept[0];
  std::vector<std::string> expected = foreign;
  expected.push_back(".out.cst.tmp-999999999-00000000");
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(entries(), expected);
}

// A signal handler calls removeOutputTemporaries() before the process dies.
TEST_F(OutputFileTest, TheSignalPathRemovesEveryLiveTemporary) {
  const std::string path = file("out.cst");
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    std::unique_ptr<OutputFile> a, b;
    int fd = -1;
    std::string scratch;
    if (!OutputFile::create(path, {}, &a).ok() || !OutputFile::create(file("b.txt"), {}, &b).ok() ||
        !a->createScratch("idx", &fd, &scratch).ok())
      ::_exit(1);
    removeOutputTemporaries();
    ::_exit(0);  // no destructors: as after a signal
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_TRUE(entries().empty()) << entries().front();
}

// A full disk (here a file-size limit, which fails writes the same way)
// fails the append or the commit and leaves nothing behind.
TEST_F(OutputFileTest, AFullDiskLeavesNothingBehind) {
  const std::string path = file("big.bin");
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::signal(SIGXFSZ, SIG_IGN);
    rlimit limit{4096, 4096};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    const Status s = writeOutputFile(path, std::string(100000, 'x'), {});
    ::_exit(s.ok() ? 0 : s.code == ErrorCode::kNoSpace ? 2 : 3);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
  EXPECT_TRUE(entries().empty()) << entries().front();
}

TEST_F(OutputFileTest, SameFileSeesThroughLinks) {
  const std::string a = file("a.tif");
  { std::ofstream(a) << "image"; }
  std::filesystem::create_symlink(a, file("sym.tif"));
  std::filesystem::create_hard_link(a, file("hard.tif"));
  { std::ofstream(file("other.tif")) << "image"; }
  EXPECT_TRUE(sameFile(a, file("sym.tif")));
  EXPECT_TRUE(sameFile(a, file("hard.tif")));
  EXPECT_FALSE(sameFile(a, file("other.tif")));
  EXPECT_FALSE(sameFile(a, file("absent.tif")));
}

}  // namespace
}  // namespace clipstream
