// Progress bar drawing. Output goes to stderr only so that a program's
// stdout (tables, JSON) stays machine-readable.
#include <clipstream/cli/progress.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace clipstream::cli {

namespace {
// Redrawing faster than this only costs terminal bandwidth.
constexpr auto kMinRedrawInterval = std::chrono::milliseconds(100);
constexpr int kBarWidth = 30;

std::string formatDuration(double seconds) {
  if (!(seconds >= 0.0) || seconds > 1e7) return "--:--";
  const uint64_t total = static_cast<uint64_t>(seconds + 0.5);
  char text[32];
  if (total >= 3600) {
    std::snprintf(text, sizeof(text), "%llu:%02llu:%02llu",
                  static_cast<unsigned long long>(total / 3600),
                  static_cast<unsigned long long>((total / 60) % 60),
                  static_cast<unsigned long long>(total % 60));
  } else {
    std::snprintf(text, sizeof(text), "%02llu:%02llu",
                  static_cast<unsigned long long>(total / 60),
                  static_cast<unsigned long long>(total % 60));
  }
  return text;
}

std::string formatRate(double per_second) {
  char text[32];
  if (per_second >= 1e6) {
    std::snprintf(text, sizeof(text), "%.1fM", per_second / 1e6);
  } else if (per_second >= 1e4) {
    std::snprintf(text, sizeof(text), "%.1fk", per_second / 1e3);
  } else {
    std::snprintf(text, sizeof(text), "%.0f", per_second);
  }
  return text;
}
}  // namespace

bool stderrIsTty() { return ::isatty(STDERR_FILENO) == 1; }

bool progressEnabledByDefault() {
  if (const char* env = std::getenv("CLIPSTREAM_PROGRESS")) {
    if (std::strcmp(env, "0") == 0) return false;
    if (std::strcmp(env, "1") == 0) return true;
  }
  return stderrIsTty();
}

ProgressBar::ProgressBar(std::string label, uint64_t total, bool enabled, std::string unit)
    : m_label(std::move(label)),
      m_unit(std::move(unit)),
      m_total(total),
      m_enabled(enabled),
      m_start(std::chrono::steady_clock::now()),
      m_last_draw(m_start - kMinRedrawInterval) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(uint64_t done) {
  uint64_t previous = m_done.load(std::memory_order_relaxed);
  while (done > previous &&
         !m_done.compare_exchange_weak(previous, done, std::memory_order_relaxed)) {
  }
  if (m_enabled) draw(false);
}

void ProgressBar::add(uint64_t delta) {
  m_done.fetch_add(delta, std::memory_order_relaxed);
  if (m_enabled) draw(false);
}

void ProgressBar::finish() {
  if (m_finished.exchange(true)) return;
  if (m_enabled) draw(true);
}

void ProgressBar::draw(bool final_draw) {
  // A worker that finds another thread drawing just moves on: progress is
  // advisory and must never make work wait.
  std::unique_lock<std::mutex> lock(m_draw_mutex, std::defer_lock);
  if (final_draw) {
    lock.lock();
  } else if (!lock.try_lock()) {
    return;
  }
  const auto now = std::chrono::steady_clock::now();
  if (!final_draw) {
    if (m_finished.load()) return;
    if (now - m_last_draw < kMinRedrawInterval) return;
  }
  m_last_draw = now;

  const uint64_t done = m_done.load(std::memory_order_relaxed);
  const double elapsed_s = std::chrono::duration<double>(now - m_start).count();
  const double rate = elapsed_s > 0.0 ? double(done) / elapsed_s : 0.0;
  std::string line = "\r" + m_label + " ";
  if (m_total > 0) {
    const double fraction = std::min(1.0, double(done) / double(m_total));
    const int filled = static_cast<int>(fraction * kBarWidth);
    char percent[16];
    std::snprintf(percent, sizeof(percent), "%3d%% ", static_cast<int>(fraction * 100.0));
    line += percent;
    line += '[';
    line.append(static_cast<size_t>(filled), '#');
    line.append(static_cast<size_t>(kBarWidth - filled), '.');
    line += "] ";
    line += std::to_string(done) + "/" + std::to_string(m_total) + " ";
  } else {
    line += std::to_string(done) + " ";
  }
  line += formatRate(rate) + " " + m_unit + "/s";
  if (final_draw) {
    line += " in " + formatDuration(elapsed_s) + "\n";
  } else if (m_total > 0) {
    const double eta_s = rate > 0.0 ? double(m_total - std::min(done, m_total)) / rate : -1.0;
    line += " ETA " + formatDuration(eta_s) + "   ";
  }
  std::fputs(line.c_str(), stderr);
  std::fflush(stderr);
}

}  // namespace clipstream::cli
