// ByteSource over an http:// or https:// URL: HTTP range requests through
// libcurl, a pool of kept-alive connections (one request in flight on
// each), retries with back-off for transient failures, and a version check
// on every response so that a store replaced on the server is reported and
// never mixed with the one that was opened.
//
// Versions: the first request records the file's size, ETag and
// Last-Modified. Every later request carries If-Range with the strong ETag
// (or else the Last-Modified date), so a server holding another version
// answers 200 with the whole file instead of 206 with the range; the
// transfer is cut at once and the source turns "changed" for good. The
// Content-Range total and any ETag echoed in a 206 are compared as well,
// for servers that ignore If-Range.
#include "byte_source.h"

#include <curl/curl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <string_view>
#include <thread>
#include <vector>

namespace clipstream {
namespace {

// The first request asks for this many bytes: the store header and, for
// small stores, much of the rest, in one round trip.
constexpr size_t kOpenBytes = size_t(64) << 10;
// prefetch() ignores hints larger than this (they are read piecewise).
constexpr uint64_t kMaxPrefetchBytes = uint64_t(16) << 20;
// Error bodies (an HTML "404 Not Found" page) are discarded up to this size;
// a larger one is cut off.
constexpr size_t kMaxErrorBodyBytes = size_t(64) << 10;

void initCurlOnce() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

bool startsWithNoCase(std::string_view text, std::string_view prefix) {
  if (text.size() < prefix.size()) return false;
  for (size_t i = 0; i < prefix.size(); ++i) {
    const char a = text[i] >= 'A' && text[i] <= 'Z' ? char(text[i] - 'A' + 'a') : text[i];
    if (a != prefix[i]) return false;
  }
  return true;
}

std::string_view trim(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == '\r' || text.back() == '\n' || text.back() == ' ' ||
                           text.back() == '\t'))
    text.remove_suffix(1);
  return text;
}

const char* reasonPhrase(long code) {
  switch (code) {
    case 200: return "OK";
    case 206: return "Partial Content";
    case 400: return "Bad Request";
    case 401: return "Unauthorized";
    case 403: return "Forbidden";
    case 404: return "Not Found";
    case 408: return "Request Timeout";
    case 410: return "Gone";
    case 416: return "Range Not Satisfiable";
    case 429: return "Too Many Requests";
    case 500: return "Internal Server Error";
    case 502: return "Bad Gateway";
    case 503: return "Service Unavailable";
    case 504: return "Gateway Timeout";
    default: return "";
  }
}

std::string httpStatusText(long code) {
  std::string text = "HTTP " + std::to_string(code);
  const char* reason = reasonPhrase(code);
  if (*reason) text += std::string(" ") + reason;
  return text;
}

// The URL as shown in messages (displayStorePath()).
std::string displayUrl(const std::string& url) {
  std::string shown = url;
  const size_t query = shown.find_first_of("?#");
  if (query != std::string::npos) shown = shown.substr(0, query) + "?...";
  const size_t scheme = shown.find("://");
  if (scheme != std::string::npos) {
    const size_t host_start = scheme + 3;
    const size_t host_end = shown.find('/', host_start);
    const size_t at = shown.rfind('@', host_end == std::string::npos ? shown.size() : host_end);
    if (at != std::string::npos && at >= host_start) shown.erase(host_start, at + 1 - host_start);
  }
  return printableText(shown, 500);
}

// One request's state, shared with libcurl's callbacks.
struct Transfer {
  CURL* curl = nullptr;
  uint8_t* data = nullptr;
  size_t capacity = 0;
  size_t got = 0;
  size_t discarded = 0;
  bool overflow = false;      // the server sent more than the range asked for
  bool cut_whole_body = false;  // a 200 answer (the whole file) was cut off
  std::string etag, last_modified, content_range;
};

size_t onHeader(char* buffer, size_t size, size_t count, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::string_view line(buffer, size * count);
  if (line.starts_with("HTTP/")) {
    // A new response (after a redirect or a 100 Continue): forget the last.
    t->etag.clear();
    t->last_modified.clear();
    t->content_range.clear();
  } else if (startsWithNoCase(line, "etag:")) {
    t->etag = trim(line.substr(5));
  } else if (startsWithNoCase(line, "last-modified:")) {
    t->last_modified = trim(line.substr(14));
  } else if (startsWithNoCase(line, "content-range:")) {
    t->content_range = trim(line.substr(14));
  }
  return size * count;
}

size_t onBody(char* ptr, size_t size, size_t count, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const size_t bytes = size * count;
  long code = 0;
  curl_easy_getinfo(t->curl, CURLINFO_RESPONSE_CODE, &code);
  if (code == 200) {
    t->cut_whole_body = true;  // the whole file: not what was asked; stop now
    return 0;
  }
  if (code != 206) {
    t->discarded += bytes;
    return t->discarded > kMaxErrorBodyBytes ? 0 : bytes;
  }
  if (bytes > t->capacity - t->got) {
    t->overflow = true;
    return 0;
  }
  std::memcpy(t->data + t->got, ptr, bytes);
  t->got += bytes;
  return bytes;
}

// "bytes FIRST-LAST/TOTAL" (TOTAL may be "*"; then *total = UINT64_MAX).
// "bytes */TOTAL" (a 416 answer) gives first = last = UINT64_MAX.
bool parseContentRange(std::string_view text, uint64_t* first, uint64_t* last, uint64_t* total) {
  auto number = [](std::string_view s, uint64_t* out) {
    if (s.empty() || s.size() > 19) return false;
    uint64_t v = 0;
    for (char c : s) {
      if (c < '0' || c > '9') return false;
      v = v * 10 + uint64_t(c - '0');
    }
    *out = v;
    return true;
  };
  if (!startsWithNoCase(text, "bytes ")) return false;
  text.remove_prefix(6);
  const size_t slash = text.find('/');
  if (slash == std::string_view::npos) return false;
  const std::string_view range = text.substr(0, slash), size = text.substr(slash + 1);
  if (size == "*") {
    *total = UINT64_MAX;
  } else if (!number(size, total)) {
    return false;
  }
  if (range == "*") {
    *first = *last = UINT64_MAX;
    return true;
  }
  const size_t dash = range.find('-');
  if (dash == std::string_view::npos) return false;
  return number(range.substr(0, dash), first) && number(range.substr(dash + 1), last) &&
         *first <= *last;
}

bool isTransient(CURLcode rc) {
  switch (rc) {
    case CURLE_COULDNT_CONNECT:
    case CURLE_COULDNT_RESOLVE_HOST:
    case CURLE_COULDNT_RESOLVE_PROXY:
    case CURLE_OPERATION_TIMEDOUT:
    case CURLE_RECV_ERROR:
    case CURLE_SEND_ERROR:
    case CURLE_GOT_NOTHING:
    case CURLE_PARTIAL_FILE:
    case CURLE_HTTP2:
    case CURLE_HTTP2_STREAM:
      return true;
    default:
      return false;
  }
}

// curl's words for a failed transfer, with timeouts named as such.
std::string failureText(CURLcode rc, const char* error_text) {
  std::string detail = error_text[0] != '\0' ? error_text : curl_easy_strerror(rc);
  if (rc == CURLE_OPERATION_TIMEDOUT) detail = "timed out (connect or stall): " + detail;
  return detail;
}

bool isTransient(long http_code) {
  return http_code == 408 || http_code == 429 || (http_code >= 500 && http_code <= 599);
}

class HttpSource final : public ByteSource {
 public:
  HttpSource(std::string url, const RemoteOptions& options)
      : m_url(std::move(url)), m_shown(displayUrl(m_url)), m_options(options) {}

  ~HttpSource() override {
    for (CURL* curl : m_idle) curl_easy_cleanup(curl);
    if (m_if_range) curl_slist_free_all(m_if_range);
  }

  Status open();

  uint64_t size() const override { return m_size; }
  Status read(void* data, size_t bytes, uint64_t offset) const override;
  void prefetch(uint64_t offset, uint64_t bytes) override;
  unsigned suggestedReadThreads() const override { return m_options.connections; }
  RemoteStats remoteStats() const override {
    RemoteStats stats;
    stats.requests = m_requests.load(std::memory_order_relaxed);
    stats.retries = m_retries.load(std::memory_order_relaxed);
    stats.bytes = m_bytes.load(std::memory_order_relaxed);
    stats.failures = m_failures.load(std::memory_order_relaxed);
    return stats;
  }

 private:
  enum class Outcome { kOk, kTransient, kFailed };
  struct Window {
    uint64_t offset = 0;
    std::vector<uint8_t> bytes;
  };

  CURL* acquire() const;
  void release(CURL* curl) const;
  // One request for [offset, offset + bytes) into data; *got receives the
  // bytes delivered (the open request may get fewer than asked).
  Outcome attempt(CURL* curl, uint8_t* data, size_t bytes, uint64_t offset, bool opening,
                  size_t* got, Status* status) const;
  // attempt() with retries for transient outcomes.
  Status fetch(uint8_t* data, size_t bytes, uint64_t offset, bool opening, size_t* got) const;
  Status changed(const std::string& why) const;
  Status fail(ErrorCode code, const std::string& what) const {
    return Status::error(code, m_shown + ": " + what);
  }

  const std::string m_url;
  const std::string m_shown;
  const RemoteOptions m_options;
  // Set by open(), then immutable.
  uint64_t m_size = 0;
  std::string m_etag, m_last_modified;
  curl_slist* m_if_range = nullptr;
  // What the open request found; written by attempt() during open() only.
  mutable uint64_t m_size_at_open = 0;
  mutable std::string m_etag_at_open, m_last_modified_at_open;
  // Filled during open only (prefetch()), read-only afterwards.
  std::vector<Window> m_windows;

  // The connection pool; guarded by m_pool_mutex.
  mutable std::mutex m_pool_mutex;
  mutable std::condition_variable m_pool_cv;
  mutable std::vector<CURL*> m_idle;
  mutable unsigned m_created = 0;

  // Sticky: once the server holds another version every read fails.
  mutable std::once_flag m_changed_once;
  mutable std::atomic<bool> m_changed{false};
  mutable std::string m_changed_message;  // written once before m_changed turns true

  mutable std::atomic<uint64_t> m_requests{0}, m_retries{0}, m_bytes{0}, m_failures{0};
};

CURL* HttpSource::acquire() const {
  {
    std::unique_lock<std::mutex> lock(m_pool_mutex);
    m_pool_cv.wait(lock, [&] { return !m_idle.empty() || m_created < m_options.connections; });
    if (!m_idle.empty()) {
      CURL* curl = m_idle.back();
      m_idle.pop_back();
      return curl;
    }
    ++m_created;
  }
  CURL* curl = curl_easy_init();
  if (curl == nullptr) {
    std::lock_guard<std::mutex> lock(m_pool_mutex);
    --m_created;
    m_pool_cv.notify_one();
    return nullptr;
  }
  curl_easy_setopt(curl, CURLOPT_URL, m_url.c_str());
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);  // threads: no SIGALRM for timeouts
  curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(curl, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(curl, CURLOPT_FOLLOWLOCATION, 1L);  // object stores may redirect
  curl_easy_setopt(curl, CURLOPT_MAXREDIRS, 5L);
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, long(m_options.connect_timeout_ms));
  // A stall: under one byte per second for the stall time (whole seconds).
  curl_easy_setopt(curl, CURLOPT_LOW_SPEED_LIMIT, 1L);
  curl_easy_setopt(curl, CURLOPT_LOW_SPEED_TIME,
                   long(std::max<uint32_t>(1, (m_options.stall_timeout_ms + 999) / 1000)));
  curl_easy_setopt(curl, CURLOPT_TCP_KEEPALIVE, 1L);
  if (!m_options.ca_file.empty()) curl_easy_setopt(curl, CURLOPT_CAINFO, m_options.ca_file.c_str());
  curl_easy_setopt(curl, CURLOPT_USERAGENT, "clipstream");
  curl_easy_setopt(curl, CURLOPT_HEADERFUNCTION, onHeader);
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, onBody);
  return curl;
}

void HttpSource::release(CURL* curl) const {
  std::lock_guard<std::mutex> lock(m_pool_mutex);
  m_idle.push_back(curl);
  m_pool_cv.notify_one();
}

Status HttpSource::changed(const std::string& why) const {
  std::call_once(m_changed_once, [&] {
    m_changed_message = m_shown + ": the store changed on the server since it was opened (" + why +
                        "); tiles of the new version are not mixed with the old: reopen it";
    m_changed.store(true, std::memory_order_release);
  });
  return Status::error(ErrorCode::kIo, m_changed_message);
}

HttpSource::Outcome HttpSource::attempt(CURL* curl, uint8_t* data, size_t bytes, uint64_t offset,
                                        bool opening, size_t* got, Status* status) const {
  Transfer t;
  t.curl = curl;
  t.data = data;
  t.capacity = bytes;
  const std::string range = std::to_string(offset) + "-" + std::to_string(offset + bytes - 1);
  char error_text[CURL_ERROR_SIZE] = {};
  curl_easy_setopt(curl, CURLOPT_RANGE, range.c_str());
  curl_easy_setopt(curl, CURLOPT_HTTPHEADER, opening ? nullptr : m_if_range);
  curl_easy_setopt(curl, CURLOPT_HEADERDATA, &t);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &t);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, error_text);
  m_requests.fetch_add(1, std::memory_order_relaxed);
  const CURLcode rc = curl_easy_perform(curl);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, nullptr);
  m_bytes.fetch_add(t.got, std::memory_order_relaxed);
  long code = 0;
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &code);
  *got = t.got;
  const std::string what = "bytes " + range;

  if (opening && code == 200 && rc == CURLE_OK && t.got == 0 && !t.cut_whole_body) {
    // An empty file: nginx answers a range of it with an empty 200. The
    // reader reports a 0-byte file as too short to be a store.
    m_size_at_open = 0;
    m_etag_at_open = t.etag;
    m_last_modified_at_open = t.last_modified;
    *status = Status::ok();
    return Outcome::kOk;
  }
  if (code == 200 || t.cut_whole_body) {
    if (opening) {
      *status = fail(ErrorCode::kUnsupported,
                     "the server answered a range request with the whole file (HTTP 200); "
                     "stores are read by byte ranges, so the server must support them");
      return Outcome::kFailed;
    }
    *status = changed("a range request with If-Range got HTTP 200" +
                      (t.etag.empty() ? std::string() : ", ETag now " + t.etag));
    return Outcome::kFailed;
  }
  if (t.overflow) {
    *status = fail(ErrorCode::kIo, "the server sent more than the " + std::to_string(bytes) +
                                       " bytes asked for (" + what + ")");
    return Outcome::kFailed;
  }
  if (rc != CURLE_OK && code != 206 && (code == 0 || code < 300 || rc != CURLE_WRITE_ERROR)) {
    // No usable HTTP answer: the connection failed.
    const std::string detail = failureText(rc, error_text);
    *status = fail(isTransient(rc) ? ErrorCode::kUnavailable : ErrorCode::kIo,
                   printableText(detail, 300) + " (" + what + ")");
    return isTransient(rc) ? Outcome::kTransient : Outcome::kFailed;
  }
  if (code == 416) {
    if (!opening) {
      *status = changed("HTTP 416 Range Not Satisfiable for " + what);
      return Outcome::kFailed;
    }
    uint64_t first = 0, last = 0, total = 0;
    if (parseContentRange(t.content_range, &first, &last, &total) && total == 0) {
      *got = 0;  // an empty file: the reader reports it as too short
      *status = Status::ok();
      return Outcome::kOk;
    }
  }
  if (code != 206) {
    const ErrorCode ec = (code == 404 || code == 410) ? ErrorCode::kNotFound
                         : isTransient(code)         ? ErrorCode::kUnavailable
                                                     : ErrorCode::kIo;
    *status = fail(ec, httpStatusText(code) + " (" + what + ")");
    return isTransient(code) ? Outcome::kTransient : Outcome::kFailed;
  }
  // 206: the range asked for, of the version opened.
  if (rc != CURLE_OK) {
    const std::string detail = failureText(rc, error_text);
    *status = fail(isTransient(rc) ? ErrorCode::kUnavailable : ErrorCode::kIo,
                   printableText(detail, 300) + " (" + what + ")");
    return isTransient(rc) ? Outcome::kTransient : Outcome::kFailed;
  }
  uint64_t first = 0, last = 0, total = 0;
  if (!parseContentRange(t.content_range, &first, &last, &total) || first != offset ||
      total == UINT64_MAX) {
    *status = fail(ErrorCode::kIo, "HTTP 206 with a Content-Range \"" +
                                       printableText(t.content_range, 100) + "\" that does not "
                                       "match the request (" + what + ")");
    return Outcome::kFailed;
  }
  if (!opening) {
    if (total != m_size) {
      *status = changed("its size was " + std::to_string(m_size) + " bytes, now " +
                        std::to_string(total));
      return Outcome::kFailed;
    }
    if (!m_etag.empty() && !t.etag.empty() && t.etag != m_etag) {
      *status = changed("ETag " + m_etag + " is now " + printableText(t.etag, 100));
      return Outcome::kFailed;
    }
    if (m_etag.empty() && !m_last_modified.empty() && !t.last_modified.empty() &&
        t.last_modified != m_last_modified) {
      *status = changed("Last-Modified " + m_last_modified + " is now " +
                        printableText(t.last_modified, 100));
      return Outcome::kFailed;
    }
  }
  const uint64_t expected = opening ? std::min<uint64_t>(bytes, total - offset) : bytes;
  if (last - first + 1 != expected || t.got != expected) {
    *status = fail(ErrorCode::kTruncated, "received " + std::to_string(t.got) + " of " +
                                              std::to_string(expected) + " bytes (" + what +
                                              ", Content-Range " +
                                              printableText(t.content_range, 100) + ")");
    return Outcome::kTransient;  // a connection cut mid-body; the next try may complete it
  }
  if (opening) {
    m_size_at_open = total;
    m_etag_at_open = t.etag;
    m_last_modified_at_open = t.last_modified;
  }
  *status = Status::ok();
  return Outcome::kOk;
}

Status HttpSource::fetch(uint8_t* data, size_t bytes, uint64_t offset, bool opening,
                         size_t* got) const {
  if (m_changed.load(std::memory_order_acquire)) {
    m_failures.fetch_add(1, std::memory_order_relaxed);
    return Status::error(ErrorCode::kIo, m_changed_message);
  }
  CURL* curl = acquire();
  if (curl == nullptr) return fail(ErrorCode::kOutOfMemory, "cannot create an HTTP handle");
  Status status;
  for (uint32_t attempt_index = 0;; ++attempt_index) {
    const Outcome outcome = attempt(curl, data, bytes, offset, opening, got, &status);
    if (outcome != Outcome::kTransient || attempt_index >= m_options.retries) break;
    m_retries.fetch_add(1, std::memory_order_relaxed);
    const uint64_t wait_ms = uint64_t(m_options.retry_base_ms) << std::min(attempt_index, 16u);
    std::this_thread::sleep_for(std::chrono::milliseconds(wait_ms));
  }
  release(curl);
  if (!status) {
    m_failures.fetch_add(1, std::memory_order_relaxed);
    if (status.code == ErrorCode::kTruncated && !opening) status.code = ErrorCode::kUnavailable;
  }
  return status;
}

Status HttpSource::open() {
  initCurlOnce();
  std::vector<uint8_t> first(kOpenBytes);
  size_t got = 0;
  Status status = fetch(first.data(), first.size(), 0, true, &got);
  if (!status) return status;
  m_size = m_size_at_open;
  m_etag = m_etag_at_open;
  m_last_modified = m_last_modified_at_open;
  first.resize(got);
  if (got > 0) m_windows.push_back({0, std::move(first)});
  // If-Range needs a strong validator: the ETag unless weak, else the date.
  std::string validator;
  if (!m_etag.empty() && !m_etag.starts_with("W/")) {
    validator = m_etag;
  } else if (!m_last_modified.empty()) {
    validator = m_last_modified;
  }
  if (!validator.empty()) m_if_range = curl_slist_append(nullptr, ("If-Range: " + validator).c_str());
  return Status::ok();
}

void HttpSource::prefetch(uint64_t offset, uint64_t bytes) {
  if (bytes == 0 || bytes > kMaxPrefetchBytes || offset > m_size || bytes > m_size - offset) return;
  for (const Window& w : m_windows) {
    if (offset >= w.offset && offset + bytes <= w.offset + w.bytes.size()) return;
  }
  Window window;
  window.offset = offset;
  window.bytes.resize(static_cast<size_t>(bytes));
  size_t got = 0;
  if (fetch(window.bytes.data(), window.bytes.size(), offset, false, &got)) {
    m_windows.push_back(std::move(window));
  }
}

Status HttpSource::read(void* data, size_t bytes, uint64_t offset) const {
  if (bytes == 0) return Status::ok();
  if (offset > m_size || bytes > m_size - offset) {
    return fail(ErrorCode::kTruncated, "the file is " + std::to_string(m_size) + " bytes, needed " +
                                           std::to_string(bytes) + " bytes from byte " +
                                           std::to_string(offset));
  }
  for (const Window& w : m_windows) {
    if (offset >= w.offset && offset + bytes <= w.offset + w.bytes.size()) {
      std::memcpy(data, w.bytes.data() + (offset - w.offset), bytes);
      return Status::ok();
    }
  }
  size_t got = 0;
  return fetch(static_cast<uint8_t*>(data), bytes, offset, false, &got);
}

}  // namespace

bool isStoreUrl(const std::string& path) {
  return startsWithNoCase(path, "http://") || startsWithNoCase(path, "https://");
}

std::string displayStorePath(const std::string& path) {
  return isStoreUrl(path) ? displayUrl(path) : path;
}

Status openHttpSource(const std::string& url, const RemoteOptions& options,
                      std::unique_ptr<ByteSource>* out) {
  if (options.connections == 0 || options.connections > kMaxRemoteConnections) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "connections must be from 1 to " + std::to_string(kMaxRemoteConnections));
  }
  auto source = std::make_unique<HttpSource>(url, options);
  Status status = source->open();
  if (!status) return status;
  *out = std::move(source);
  return Status::ok();
}

}  // namespace clipstream
