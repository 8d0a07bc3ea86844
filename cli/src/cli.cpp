#include <clipstream/cli/cli.h>

#include <clipstream/util/output_file.h>
#include <clipstream/store/types.h>

#include <signal.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>

namespace clipstream::cli {

namespace {

std::atomic<int>* g_cancel = nullptr;

// A cooperative stop must come within this time; a program busy where it
// does not poll (an image library guessing the format of a huge file) is
// stopped by the alarm instead.
constexpr unsigned kCooperativeGraceSeconds = 5;

extern "C" void onSignal(int signo) {
  if (g_cancel) {
    int expected = 0;
    if (g_cancel->compare_exchange_strong(expected, signo)) {  // first: cooperative
      ::alarm(kCooperativeGraceSeconds);
      return;
    }
  }
  removeOutputTemporaries();
  ::signal(signo, SIG_DFL);
  ::raise(signo);
}

extern "C" void onGraceExpired(int) {
  removeOutputTemporaries();
  ::_exit(kExitSignalBase + (g_cancel ? g_cancel->load() : SIGALRM));
}

// Numbers in messages: integers as integers, the rest in %g.
std::string numberText(double v) {
  char text[64];
  if (std::fabs(v) < 1e15 && v == std::floor(v)) {
    std::snprintf(text, sizeof text, "%.0f", v);
  } else {
    std::snprintf(text, sizeof text, "%g", v);
  }
  return text;
}

// Digits, sign, point and exponent only: no spaces, no hex, no "inf".
bool plainNumber(const std::string& text) {
  return text.find_first_not_of("0123456789+-.eE") == std::string::npos;
}

std::string quotedValue(const std::string& text) { return "'" + printableText(text, 40) + "'"; }

// CLI11's help, except that a positional taking one or two words ("INPUT
// OUTPUT", expected(1, 2)) reads as its name in the usage line, not
// "INPUT OUTPUT(1x)"; its description says which word may be left out.
class Formatter : public CLI::Formatter {
 public:
  std::string make_option_usage(const CLI::Option* opt) const override {
    const int most = opt->get_expected_max();
    if (most > 1 && most < CLI::detail::expected_max_vector_size) {
      const std::string name = make_option_name(opt, true);
      return opt->get_required() ? name : "[" + name + "]";
    }
    return CLI::Formatter::make_option_usage(opt);
  }
};

}  // namespace

std::string versionText(const CLI::App& app) {
  return app.get_name() + " " + CLIPSTREAM_VERSION;
}

std::optional<int> parse(CLI::App& app, int argc, char** argv) {
  // Every program: --version, and each option's default in --help (the
  // value its variable holds before parsing; flags and empty values show
  // none).
  if (app.get_option_no_throw("--version") == nullptr) app.set_version_flag("--version", versionText(app));
  app.formatter(std::make_shared<Formatter>());
  for (CLI::Option* option : app.get_options()) {
    if (option->get_type_size() == 0 || !option->nonpositional()) continue;  // flags, positionals
    option->capture_default_str();
    if (option->get_default_str() == "[]") option->default_str("");  // an empty list says nothing
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForVersion& version) {
    std::cout << version.what() << "\n";
    return kExitOk;
  } catch (const CLI::CallForHelp&) {
    std::cout << app.help();
    return kExitOk;
  } catch (const CLI::CallForAllHelp&) {
    std::cout << app.help("", CLI::AppFormatMode::All);
    return kExitOk;
  } catch (const CLI::ParseError& e) {
    printError(app, std::string(e.what()) + " (" + app.get_name() + " --help lists the options)");
    return kExitUsage;
  }
  return std::nullopt;
}

int usageError(const CLI::App& app, const std::string& message) {
  printError(app, message);
  return kExitUsage;
}

void printError(const CLI::App& app, const std::string& message) {
  std::cerr << app.get_name() << ": " << printableText(message, kMaxMessageBytes) << "\n";
}

CLI::Validator inRange(double lo, double hi) {
  const std::string bounds = numberText(lo) + " to " + numberText(hi);
  return CLI::Validator(
      [lo, hi, bounds](std::string& text) -> std::string {
        errno = 0;
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (text.empty() || !plainNumber(text) || end != text.c_str() + text.size() ||
            (errno == ERANGE && std::fabs(v) >= 1.0) || !std::isfinite(v) ||
            v < lo || v > hi) {
          return quotedValue(text) + " must be a number from " + bounds;
        }
        // What was checked is what CLI11 converts next: the value in plain
        // decimal (its own parser reads hex and other forms differently).
        char exact[64];
        std::snprintf(exact, sizeof exact, "%.17g", v);
        text = exact;
        return {};
      },
      "NUMBER in " + bounds, "RANGE");
}

CLI::Validator wholeInRange(int64_t lo, int64_t hi) {
  const std::string bounds = std::to_string(lo) + " to " + std::to_string(hi);
  return CLI::Validator(
      [lo, hi, bounds](std::string& text) -> std::string {
        errno = 0;
        char* end = nullptr;
        const long long v = std::strtoll(text.c_str(), &end, 10);
        if (text.empty() || !plainNumber(text) || end != text.c_str() + text.size() || errno == ERANGE || v < lo || v > hi) {
          return quotedValue(text) + " must be a whole number from " + bounds;
        }
        // Decimal, as checked: CLI11's own conversion would read "010" as
        // octal 8 and "0x10" as 16.
        text = std::to_string(v);
        return {};
      },
      "INT in " + bounds, "RANGE");
}

std::optional<PayloadOrder> parsePayloadOrder(const std::string& text) {
  std::string lower = text;
  for (char& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
  for (PayloadOrder order : {PayloadOrder::kWritten, PayloadOrder::kCurve}) {
    if (lower == payloadOrderName(order)) return order;
  }
  return std::nullopt;
}

std::optional<PixelFormat> parsePixelFormat(const std::string& text) {
  std::string upper = text;
  for (char& c : upper) c = char(std::toupper(static_cast<unsigned char>(c)));
  for (PixelFormat format :
       {PixelFormat::kR8, PixelFormat::kR16, PixelFormat::kRGB8, PixelFormat::kRGBA8,
        PixelFormat::kI16, PixelFormat::kF32}) {
    if (upper == pixelFormatName(format)) return format;
  }
  return std::nullopt;
}

void installSignalHandlers(std::atomic<int>* cancel) {
  g_cancel = cancel;
  struct sigaction action = {};
  action.sa_handler = onSignal;
  sigemptyset(&action.sa_mask);
  for (int signo : {SIGINT, SIGTERM, SIGHUP}) {
    // A signal ignored at start stays ignored (nohup, background jobs of a
    // non-interactive shell): the caller asked for that.
    struct sigaction old = {};
    if (sigaction(signo, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    sigaction(signo, &action, nullptr);
  }
  if (cancel) {
    struct sigaction grace = {};
    grace.sa_handler = onGraceExpired;
    sigemptyset(&grace.sa_mask);
    sigaction(SIGALRM, &grace, nullptr);
  }
  ::signal(SIGPIPE, SIG_IGN);
  ::signal(SIGXFSZ, SIG_IGN);
}

int finish(const CLI::App& app, int code) {
  errno = 0;
  std::cout.flush();
  const bool cxx_failed = !std::cout;
  int err = errno;
  const bool c_failed = std::fflush(stdout) != 0 || std::ferror(stdout);
  if (err == 0) err = errno;
  if (cxx_failed || c_failed) {
    std::cerr << app.get_name() << ": cannot write standard output"
              << (err ? std::string(": ") + std::strerror(err) : std::string()) << "\n";
    return kExitFailure;
  }
  return code;
}

void addRemoteOptions(CLI::App& app, RemoteOptions* remote) {
  app.add_option("--http-connections", remote->connections,
                 "Requests in flight to a store given as a URL (HTTP/1.1: one kept-alive "
                 "connection each; HTTP/2: streams of one connection)")
      ->transform(wholeInRange(1, kMaxRemoteConnections));
  app.add_option("--disk-cache", remote->disk_cache_dir,
                 "Keep what is read from a store URL in this folder (made if missing), "
                 "checked and reused by later runs (default: off)");
  app.add_option_function<uint64_t>(
         "--disk-cache-mb",
         [remote](uint64_t mb) { remote->disk_cache_bytes = mb << 20; },
         "Cap of the --disk-cache folder in MiB (default " +
             std::to_string(RemoteOptions{}.disk_cache_bytes >> 20) + "); least recently used "
             "entries go first")
      ->transform(wholeInRange(1, int64_t(1) << 30));
}

}  // namespace clipstream::cli
