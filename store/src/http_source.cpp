// ByteSource over an http:// or https:// URL: HTTP range requests through
// libcurl's multi interface, driven by one thread per source; HTTP/2
// streams multiplexed on one connection when an https:// server offers h2
// (ALPN), else up to RemoteOptions::connections kept-alive HTTP/1.1
// connections; retries with back-off for transient failures, and a version
// check on every response so that a store replaced on the server is
// reported and never mixed with the one that was opened.
//
// Threads: reader threads prepare their easy handles, hand them to the
// transfer loop (TransferLoop) and wait; the loop's thread runs every
// transfer, libcurl's callbacks included, and hands each handle back under
// the loop's mutex. A handle belongs to one side at a time.
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
#include <memory>
#include <mutex>
#include <span>
#include <string_view>
#include <system_error>
#include <thread>
#include <vector>

namespace clipstream {
namespace {

// The first request asks for this many bytes: the store header and, for
// small stores, much of the rest, in one round trip.
constexpr size_t kOpenBytes = size_t(64) << 10;
// prefetch() ignores hints larger than this (they are read piecewise).
constexpr uint64_t kMaxPrefetchBytes = uint64_t(16) << 20;
// The transfer loop wakes at least this often (curl's own timers: connect
// and stall timeouts, retransmissions) when no socket is ready.
constexpr int kLoopPollMs = 100;
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

// One request's state, shared with libcurl's callbacks (which run on the
// transfer loop's thread while the request is in flight).
struct Transfer {
  CURL* curl = nullptr;
  uint8_t* data = nullptr;
  size_t capacity = 0;
  uint64_t offset = 0;
  size_t got = 0;
  size_t discarded = 0;
  bool overflow = false;      // the server sent more than the range asked for
  bool cut_whole_body = false;  // a 200 answer (the whole file) was cut off
  std::string range;          // "FIRST-LAST", for CURLOPT_RANGE and messages
  std::string etag, last_modified, content_range;
  char error_text[CURL_ERROR_SIZE] = {};
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

// One curl multi handle and the thread that drives it. Reader threads hand
// it prepared easy handles (performAll()) and sleep until their transfers
// finished; the multi handle keeps the connections (HTTP/2: one, its
// requests multiplexed as streams; HTTP/1.1: up to the connection limit,
// further requests queued inside libcurl until one is free).
//
// Thread-safe: performAll() from any number of threads at once. The
// destructor runs when no performAll() is in progress.
class TransferLoop {
 public:
  TransferLoop() = default;
  ~TransferLoop() {
    if (m_thread.joinable()) {
      {
        std::lock_guard<std::mutex> lock(m_mutex);
        m_stopping = true;
      }
      curl_multi_wakeup(m_multi);
      m_thread.join();
    }
    if (m_multi != nullptr) curl_multi_cleanup(m_multi);
  }
  TransferLoop(const TransferLoop&) = delete;
  TransferLoop& operator=(const TransferLoop&) = delete;

  // Creates the multi handle (`connections` connections to the server at
  // most) and starts the thread. kOutOfMemory / kIo when either fails.
  Status start(unsigned connections) {
    m_multi = curl_multi_init();
    if (m_multi == nullptr) return Status::error(ErrorCode::kOutOfMemory, "curl_multi_init failed");
    curl_multi_setopt(m_multi, CURLMOPT_PIPELINING, long(CURLPIPE_MULTIPLEX));
    curl_multi_setopt(m_multi, CURLMOPT_MAX_HOST_CONNECTIONS, long(connections));
    curl_multi_setopt(m_multi, CURLMOPT_MAX_TOTAL_CONNECTIONS, long(connections));
    // Keep every connection alive between requests (the default cache
    // shrinks with the handles added).
    curl_multi_setopt(m_multi, CURLMOPT_MAXCONNECTS, long(connections));
    try {
      m_thread = std::thread([this] { run(); });
    } catch (const std::system_error& e) {
      return Status::error(ErrorCode::kIo, std::string("cannot start the HTTP thread: ") + e.what());
    }
    return okStatus();
  }

  // Runs every handle's transfer, all at once; returns when all finished,
  // with results[i] the outcome of handles[i]. The handles come back
  // removed from the multi handle, their callbacks done.
  void performAll(std::span<CURL* const> handles, std::span<CURLcode> results) {
    Group group;
    std::vector<Job> jobs(handles.size());
    std::unique_lock<std::mutex> lock(m_mutex);
    group.remaining = handles.size();
    for (size_t i = 0; i < handles.size(); ++i) {
      jobs[i] = Job{handles[i], &results[i], &group};
      m_incoming.push_back(&jobs[i]);
    }
    lock.unlock();
    curl_multi_wakeup(m_multi);
    lock.lock();
    group.done.wait(lock, [&] { return group.remaining == 0; });
  }

 private:
  struct Group {
    size_t remaining = 0;  // guarded by m_mutex
    std::condition_variable done;
  };
  struct Job {
    CURL* curl = nullptr;
    CURLcode* result = nullptr;
    Group* group = nullptr;
  };

  void finish(Job* job, CURLcode rc) {
    std::lock_guard<std::mutex> lock(m_mutex);
    *job->result = rc;
    // Notified under the lock: the waiter cannot return (and destroy the
    // group) before the lock is released.
    if (--job->group->remaining == 0) job->group->done.notify_all();
  }

  void run() {
    std::vector<Job*> adding;
    for (;;) {
      {
        std::lock_guard<std::mutex> lock(m_mutex);
        if (m_stopping) return;
        adding.swap(m_incoming);
      }
      for (Job* job : adding) {
        curl_easy_setopt(job->curl, CURLOPT_PRIVATE, static_cast<void*>(job));
        if (curl_multi_add_handle(m_multi, job->curl) != CURLM_OK) finish(job, CURLE_OUT_OF_MEMORY);
      }
      adding.clear();
      int running = 0;
      curl_multi_perform(m_multi, &running);
      int left = 0;
      while (CURLMsg* message = curl_multi_info_read(m_multi, &left)) {
        if (message->msg != CURLMSG_DONE) continue;
        CURL* curl = message->easy_handle;
        const CURLcode rc = message->data.result;
        void* job = nullptr;
        curl_easy_getinfo(curl, CURLINFO_PRIVATE, &job);
        curl_multi_remove_handle(m_multi, curl);  // `message` is invalid from here
        finish(static_cast<Job*>(job), rc);
      }
      curl_multi_poll(m_multi, nullptr, 0, kLoopPollMs, nullptr);
    }
  }

  CURLM* m_multi = nullptr;
  std::thread m_thread;
  std::mutex m_mutex;  // guards m_incoming, m_stopping and every Group's remaining
  std::vector<Job*> m_incoming;
  bool m_stopping = false;
};

class HttpSource final : public ByteSource {
 public:
  HttpSource(std::string url, const RemoteOptions& options)
      : m_url(std::move(url)), m_shown(displayUrl(m_url)), m_options(options) {}

  ~HttpSource() override {
    m_loop.reset();  // no transfer in flight; the loop goes before the handles
    for (CURL* curl : m_idle) curl_easy_cleanup(curl);
    if (m_if_range) curl_slist_free_all(m_if_range);
  }

  Status open();

  uint64_t size() const override { return m_size; }
  Status read(void* data, size_t bytes, uint64_t offset) const override;
  void readMany(std::span<const ByteRange> ranges, std::span<Status> statuses) const override;
  std::string version() const override { return m_version; }
  void prefetch(uint64_t offset, uint64_t bytes) override;
  unsigned suggestedReadThreads() const override { return m_options.connections; }
  RemoteStats remoteStats() const override {
    RemoteStats stats;
    stats.requests = m_requests.load(std::memory_order_relaxed);
    stats.retries = m_retries.load(std::memory_order_relaxed);
    stats.bytes = m_bytes.load(std::memory_order_relaxed);
    stats.failures = m_failures.load(std::memory_order_relaxed);
    stats.http2_requests = m_http2_requests.load(std::memory_order_relaxed);
    stats.connections = m_connections.load(std::memory_order_relaxed);
    return stats;
  }

 private:
  enum class Outcome { kOk, kTransient, kFailed };
  struct Window {
    uint64_t offset = 0;
    std::vector<uint8_t> bytes;
  };
  // One range of a fetch(): where it goes, what came back.
  struct Piece {
    uint8_t* data = nullptr;
    size_t bytes = 0;
    uint64_t offset = 0;
    size_t got = 0;  // bytes delivered (the open request may get fewer than asked)
    Status status;
  };

  CURL* acquire() const;
  void release(CURL* curl) const;
  // Sets up `curl` for one request of [offset, offset + bytes) into data.
  void prepare(CURL* curl, Transfer* t, uint8_t* data, size_t bytes, uint64_t offset,
               bool opening) const;
  // Judges a finished request; *got receives the bytes delivered.
  Outcome judge(const Transfer& t, CURLcode rc, bool opening, size_t* got, Status* status) const;
  // judge() of an HTTP 206 answer: the range asked for, all of it, of the
  // file version opened (its size, ETag, Last-Modified).
  Outcome judgePartial(const Transfer& t, CURLcode rc, bool opening, Status* status) const;
  // Every piece's request at once, each retried on its own while transient
  // (all retries of one round wait the same back-off).
  void fetch(std::span<Piece> pieces, bool opening) const;
  Status changed(const std::string& why) const;
  Status fail(ErrorCode code, const std::string& what) const {
    return Status::error(code, m_shown + ": " + what);
  }

  const std::string m_url;
  const std::string m_shown;
  const RemoteOptions m_options;
  std::unique_ptr<TransferLoop> m_loop;  // set by open()
  // Set by open(), then immutable.
  uint64_t m_size = 0;
  std::string m_etag, m_last_modified, m_version;
  curl_slist* m_if_range = nullptr;
  // What the open request found; written by judge() during open() only.
  mutable uint64_t m_size_at_open = 0;
  mutable std::string m_etag_at_open, m_last_modified_at_open;
  // Filled during open only (prefetch()), read-only afterwards.
  std::vector<Window> m_windows;

  // Easy handles not in use (each keeps its options; the connections live
  // in the multi handle); guarded by m_pool_mutex.
  mutable std::mutex m_pool_mutex;
  mutable std::vector<CURL*> m_idle;

  // Sticky: once the server holds another version every read fails.
  mutable std::once_flag m_changed_once;
  mutable std::atomic<bool> m_changed{false};
  mutable std::string m_changed_message;  // written once before m_changed turns true

  mutable std::atomic<uint64_t> m_requests{0}, m_retries{0}, m_bytes{0}, m_failures{0};
  mutable std::atomic<uint64_t> m_http2_requests{0}, m_connections{0};
};

CURL* HttpSource::acquire() const {
  {
    std::lock_guard<std::mutex> lock(m_pool_mutex);
    if (!m_idle.empty()) {
      CURL* curl = m_idle.back();
      m_idle.pop_back();
      return curl;
    }
  }
  CURL* curl = curl_easy_init();
  if (curl == nullptr) return nullptr;
  curl_easy_setopt(curl, CURLOPT_URL, m_url.c_str());
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);  // threads: no SIGALRM for timeouts
  curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(curl, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(curl, CURLOPT_FOLLOWLOCATION, 1L);  // object stores may redirect
  curl_easy_setopt(curl, CURLOPT_MAXREDIRS, 5L);
  // HTTP/2 where TLS negotiates it (ALPN), HTTP/1.1 otherwise; cleartext
  // stays HTTP/1.1 (docs/decisions.md D198, D199).
  curl_easy_setopt(curl, CURLOPT_HTTP_VERSION,
                   m_options.http2 ? long(CURL_HTTP_VERSION_2TLS) : long(CURL_HTTP_VERSION_1_1));
  // A new request waits for a connection being set up rather than opening
  // another, so that HTTP/2 requests share one connection.
  curl_easy_setopt(curl, CURLOPT_PIPEWAIT, 1L);
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
}

Status HttpSource::changed(const std::string& why) const {
  std::call_once(m_changed_once, [&] {
    m_changed_message = m_shown + ": the store changed on the server since it was opened (" + why +
                        "); tiles of the new version are not mixed with the old: reopen it";
    m_changed.store(true, std::memory_order_release);
  });
  return Status::error(ErrorCode::kIo, m_changed_message);
}

void HttpSource::prepare(CURL* curl, Transfer* t, uint8_t* data, size_t bytes, uint64_t offset,
                         bool opening) const {
  t->curl = curl;
  t->data = data;
  t->capacity = bytes;
  t->offset = offset;
  t->range = std::to_string(offset) + "-" + std::to_string(offset + bytes - 1);
  curl_easy_setopt(curl, CURLOPT_RANGE, t->range.c_str());
  curl_easy_setopt(curl, CURLOPT_HTTPHEADER, opening ? nullptr : m_if_range);
  curl_easy_setopt(curl, CURLOPT_HEADERDATA, t);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, t);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, t->error_text);
}

HttpSource::Outcome HttpSource::judge(const Transfer& t, CURLcode rc, bool opening, size_t* got,
                                      Status* status) const {
  CURL* curl = t.curl;
  const size_t bytes = t.capacity;
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, nullptr);
  m_bytes.fetch_add(t.got, std::memory_order_relaxed);
  long code = 0, version = 0, connects = 0;
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &code);
  curl_easy_getinfo(curl, CURLINFO_HTTP_VERSION, &version);
  curl_easy_getinfo(curl, CURLINFO_NUM_CONNECTS, &connects);
  if (version == CURL_HTTP_VERSION_2_0) m_http2_requests.fetch_add(1, std::memory_order_relaxed);
  m_connections.fetch_add(uint64_t(std::max(0L, connects)), std::memory_order_relaxed);
  *got = t.got;
  const std::string what = "bytes " + t.range;
  const char* error_text = t.error_text;

  if (opening && code == 200 && rc == CURLE_OK && t.got == 0 && !t.cut_whole_body) {
    // An empty file: nginx answers a range of it with an empty 200. The
    // reader reports a 0-byte file as too short to be a store.
    m_size_at_open = 0;
    m_etag_at_open = t.etag;
    m_last_modified_at_open = t.last_modified;
    *status = okStatus();
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
      *status = okStatus();
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
  return judgePartial(t, rc, opening, status);
}

HttpSource::Outcome HttpSource::judgePartial(const Transfer& t, CURLcode rc, bool opening,
                                             Status* status) const {
  const uint64_t offset = t.offset;
  const std::string what = "bytes " + t.range;
  // 206: the range asked for, of the version opened.
  if (rc != CURLE_OK) {
    const std::string detail = failureText(rc, t.error_text);
    *status = fail(isTransient(rc) ? ErrorCode::kUnavailable : ErrorCode::kIo,
                   printableText(detail, 300) + " (" + what + ")");
    return isTransient(rc) ? Outcome::kTransient : Outcome::kFailed;
  }
  uint64_t first = 0, last = 0, total = 0;
  const bool parsed = parseContentRange(t.content_range, &first, &last, &total);
  if (parsed && first == offset && total == UINT64_MAX) {
    // "bytes 0-65535/*": allowed by RFC 9110, but a store is read by offsets
    // from its end too, and a changed file is told by its size.
    *status = fail(ErrorCode::kUnsupported,
                   "HTTP 206 with a Content-Range \"" + printableText(t.content_range, 100) +
                       "\" that gives no total size (\"*\"); the server must report the file's "
                       "size (" + what + ")");
    return Outcome::kFailed;
  }
  if (!parsed || first != offset || total == UINT64_MAX) {
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
  const uint64_t expected = opening ? std::min<uint64_t>(t.capacity, total - offset) : t.capacity;
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
  *status = okStatus();
  return Outcome::kOk;
}

void HttpSource::fetch(std::span<Piece> pieces, bool opening) const {
  if (m_changed.load(std::memory_order_acquire)) {
    for (Piece& piece : pieces) piece.status = Status::error(ErrorCode::kIo, m_changed_message);
    m_failures.fetch_add(pieces.size(), std::memory_order_relaxed);
    return;
  }
  std::vector<Piece*> todo;
  for (Piece& piece : pieces) todo.push_back(&piece);
  std::vector<Transfer> transfers;
  std::vector<CURL*> handles;
  std::vector<CURLcode> results;
  std::vector<Piece*> again;
  for (uint32_t attempt_index = 0; !todo.empty(); ++attempt_index) {
    transfers.assign(todo.size(), Transfer{});
    handles.clear();
    for (size_t i = 0; i < todo.size(); ++i) {
      CURL* curl = acquire();
      if (curl == nullptr) {
        // Without a handle this piece fails now; the others still run.
        todo[i]->status = fail(ErrorCode::kOutOfMemory, "cannot create an HTTP handle");
        continue;
      }
      prepare(curl, &transfers[handles.size()], todo[i]->data, todo[i]->bytes, todo[i]->offset,
              opening);
      handles.push_back(curl);
      todo[handles.size() - 1] = todo[i];
    }
    todo.resize(handles.size());
    results.assign(handles.size(), CURLE_OK);
    m_requests.fetch_add(handles.size(), std::memory_order_relaxed);
    m_loop->performAll(handles, results);
    again.clear();
    for (size_t i = 0; i < handles.size(); ++i) {
      const Outcome outcome = judge(transfers[i], results[i], opening, &todo[i]->got,
                                    &todo[i]->status);
      release(handles[i]);
      if (outcome == Outcome::kTransient && attempt_index < m_options.retries) {
        again.push_back(todo[i]);
      }
    }
    todo.swap(again);
    if (todo.empty()) break;
    m_retries.fetch_add(todo.size(), std::memory_order_relaxed);
    const uint64_t wait_ms = uint64_t(m_options.retry_base_ms) << std::min(attempt_index, 16u);
    std::this_thread::sleep_for(std::chrono::milliseconds(wait_ms));
  }
  for (Piece& piece : pieces) {
    if (piece.status) continue;
    m_failures.fetch_add(1, std::memory_order_relaxed);
    if (piece.status.code == ErrorCode::kTruncated && !opening) {
      piece.status.code = ErrorCode::kUnavailable;
    }
  }
}

Status HttpSource::open() {
  initCurlOnce();
  m_loop = std::make_unique<TransferLoop>();
  if (Status started = m_loop->start(m_options.connections); !started) {
    return fail(started.code, started.message);
  }
  std::vector<uint8_t> first(kOpenBytes);
  Piece piece{first.data(), first.size(), 0};
  fetch(std::span<Piece>(&piece, 1), true);
  if (!piece.status) return piece.status;
  m_size = m_size_at_open;
  m_etag = m_etag_at_open;
  m_last_modified = m_last_modified_at_open;
  first.resize(piece.got);
  if (piece.got > 0) m_windows.push_back({0, std::move(first)});
  // If-Range needs a strong validator: the ETag unless weak, else the date.
  std::string validator;
  if (!m_etag.empty() && !m_etag.starts_with("W/")) {
    validator = m_etag;
  } else if (!m_last_modified.empty()) {
    validator = m_last_modified;
  }
  if (!validator.empty()) {
    m_if_range = curl_slist_append(nullptr, ("If-Range: " + validator).c_str());
    m_version = validator + " " + std::to_string(m_size);
  }
  return okStatus();
}

void HttpSource::prefetch(uint64_t offset, uint64_t bytes) {
  if (bytes == 0 || bytes > kMaxPrefetchBytes || offset > m_size || bytes > m_size - offset) return;
  for (const Window& w : m_windows) {
    if (offset >= w.offset && offset + bytes <= w.offset + w.bytes.size()) return;
  }
  Window window;
  window.offset = offset;
  window.bytes.resize(static_cast<size_t>(bytes));
  Piece piece{window.bytes.data(), window.bytes.size(), offset};
  fetch(std::span<Piece>(&piece, 1), false);
  if (piece.status) m_windows.push_back(std::move(window));
}

void HttpSource::readMany(std::span<const ByteRange> ranges, std::span<Status> statuses) const {
  const size_t n = std::min(ranges.size(), statuses.size());
  std::vector<Piece> pieces;
  std::vector<size_t> index;
  for (size_t i = 0; i < n; ++i) {
    const ByteRange& r = ranges[i];
    statuses[i] = okStatus();
    if (r.bytes == 0) continue;
    if (r.offset > m_size || r.bytes > m_size - r.offset) {
      statuses[i] = fail(ErrorCode::kTruncated,
                         "the file is " + std::to_string(m_size) + " bytes, needed " +
                             std::to_string(r.bytes) + " bytes from byte " +
                             std::to_string(r.offset));
      continue;
    }
    bool served = false;
    for (const Window& w : m_windows) {
      if (r.offset >= w.offset && r.offset + r.bytes <= w.offset + w.bytes.size()) {
        std::memcpy(r.data, w.bytes.data() + (r.offset - w.offset), r.bytes);
        served = true;
        break;
      }
    }
    if (served) continue;
    pieces.push_back(Piece{static_cast<uint8_t*>(r.data), r.bytes, r.offset});
    index.push_back(i);
  }
  if (pieces.empty()) return;
  fetch(pieces, false);
  for (size_t k = 0; k < pieces.size(); ++k) statuses[index[k]] = pieces[k].status;
}

Status HttpSource::read(void* data, size_t bytes, uint64_t offset) const {
  const ByteRange range{data, bytes, offset};
  Status status;
  readMany(std::span<const ByteRange>(&range, 1), std::span<Status>(&status, 1));
  return status;
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
  return okStatus();
}

}  // namespace clipstream
