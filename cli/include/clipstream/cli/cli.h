// What the clipstream programs share on the command line: one exit-code
// table, one way to parse and report mistakes, range checks with plain
// messages, option values (pixel formats), signal handling that leaves no
// temporary behind, and a checked standard output (the progress bar is in
// progress.h). Linked only by executables, never by the libraries
// (an embedding host keeps its own signals and exit codes).
//
// Thread rule: parse(), finish() and installSignalHandlers() from the main
// thread; the validators run inside parse().
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>

namespace clipstream::cli {

// Exit codes of every program (docs/cli.md).
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;  // the work failed: input unreadable, output unwritable, ...
constexpr int kExitUsage = 2;    // a command-line mistake: nothing was read or written
constexpr int kExitCorrupt = 3;  // clipstream-info: corruption found
constexpr int kExitSignalBase = 128;  // 128 + N: stopped by signal N (INT 130, TERM 143, HUP 129)

// Parses the command line. Returns nullopt to go on, or the exit code to
// return now: 0 after --help or --version, kExitUsage after a mistake
// (printed on stderr as "PROGRAM: <problem>" with a pointer to --help).
// Adds --version (versionText()) and shows every option's default in
// --help: the value its variable holds when parse() is called.
std::optional<int> parse(CLI::App& app, int argc, char** argv);

// "PROGRAM VERSION", e.g. "clipstream-fly 0.1.0": the project's version.
std::string versionText(const CLI::App& app);

// "PROGRAM: <message>" on stderr, one line: control bytes (from file names,
// file contents, option values) shown as '?', cut at kMaxMessageBytes.
// Every message a program prints goes through it.
constexpr size_t kMaxMessageBytes = 1000;
void printError(const CLI::App& app, const std::string& message);

// printError(), then returns kExitUsage. For mistakes found after parse()
// (e.g. a malformed size).
int usageError(const CLI::App& app, const std::string& message);

// Validators: the value must be a finite number in [lo, hi] (inRange) or a
// decimal whole number in [lo, hi] (wholeInRange). Messages name the bounds
// plainly ("must be a number from 0 to 10000"); NaN, infinities and numbers
// too long to hold are rejected. The value is rewritten in plain decimal
// before CLI11 converts it, so "010" is ten, never octal eight: attach them
// with Option::transform() (check() would discard the rewrite).
CLI::Validator inRange(double lo, double hi);
CLI::Validator wholeInRange(int64_t lo, int64_t hi);

// Parses a pixel format option value: "R8", "R16", "RGB8", "RGBA8", "I16",
// "F32", in any case. nullopt for anything else (the caller names the option).
std::optional<PixelFormat> parsePixelFormat(const std::string& text);
// "curve" or "written" (payloadOrderName()), in any case; nullopt otherwise.
std::optional<PayloadOrder> parsePayloadOrder(const std::string& text);

// The options of every program that opens stores, for stores given as
// URLs: --http-connections N, --disk-cache DIR and --disk-cache-mb N
// (docs/cli.md). Parsing fills *remote, which must outlive parse().
void addRemoteOptions(CLI::App& app, RemoteOptions* remote);

// SIGINT, SIGTERM and SIGHUP (unless ignored at start, as under nohup).
// With `cancel`, the first signal stores its number there (the program polls
// it, stops, cleans up and returns kExitSignalBase + N) and arms a 5 s alarm:
// a program that does not poll in time (busy inside a library) then removes
// its temporaries and exits kExitSignalBase + N from the alarm. A second
// signal, or any signal without `cancel`, removes every live output
// temporary (removeOutputTemporaries()) and ends the process by that signal. SIGPIPE is ignored (a closed pipe is a write
// error, reported by finish()); SIGXFSZ too (a file-size limit is a write
// error, reported and cleaned up).
void installSignalHandlers(std::atomic<int>* cancel = nullptr);

// Flushes standard output (C and C++ streams). If anything written to it
// failed (a full disk, /dev/full, a closed pipe) prints
// "PROGRAM: cannot write standard output: <reason>" and returns
// kExitFailure; else returns `code`.
int finish(const CLI::App& app, int code);

}  // namespace clipstream::cli
