// Real servers for the HTTP tests and benchmarks: an nginx started from its
// Debian package with its own configuration in a temporary folder, bound to
// 127.0.0.1 on a free port, and a delaying TCP proxy that adds a round trip
// to every request. No GoogleTest here: the benchmarks link it too.
//
// Thread rule: an NginxServer belongs to the thread that started it; its
// requests() may be read from any thread. A DelayProxy serves connections
// on its own threads; setDelayMs() and the counters may be called from any
// thread.
#pragma once

#include <clipstream/store/types.h>

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace clipstream::test {

// One line of the access log.
struct LoggedRequest {
  int status = 0;           // 206, 200, 404, ...
  std::string uri;          // "/store.cstore"
  std::string range;        // the Range header, "" if none
  std::string if_range;     // the If-Range header, "" if none
  uint64_t body_bytes = 0;  // $body_bytes_sent
  std::string protocol;     // "HTTP/1.1", "HTTP/2.0"
};

// nginx serving `root_dir` at http://127.0.0.1:PORT/. Extra locations:
// /forbidden.cstore answers 403, /failing.cstore answers 503. Optionally
// over TLS.
class NginxServer {
 public:
  // Writes nginx.conf into `work_dir` (logs, pid and temporaries go there
  // too), picks a free port and starts nginx in the foreground (daemon off)
  // as a child of this process; returns once it accepts connections.
  // kNotFound naming the package when no nginx binary is installed
  // ($CLIPSTREAM_NGINX, else /usr/sbin/nginx).
  // With `tls`, serves https:// with a self-signed certificate for
  // 127.0.0.1 made by the openssl program (certificateFile() names it);
  // with `tls` and `http2`, offers HTTP/2 too (ALPN, `listen ... ssl http2`).
  static Status start(const std::string& work_dir, const std::string& root_dir,
                      std::unique_ptr<NginxServer>* out, bool tls = false, bool http2 = false);
  ~NginxServer();  // stop()
  NginxServer(const NginxServer&) = delete;
  NginxServer& operator=(const NginxServer&) = delete;

  // Fast shutdown (SIGTERM): open connections are cut. Waits for the exit.
  void stop();
  // Starts the same configuration again, on the same port.
  Status restart();
  bool running() const { return m_pid > 0; }

  uint16_t port() const { return m_port; }
  std::string url(const std::string& name) const;  // http(s)://127.0.0.1:PORT/name
  std::string certificateFile() const { return m_work_dir + "/cert.pem"; }
  // The access log so far. nginx writes a line after the answer is sent,
  // so a client may see its answer before the line exists: with
  // `at_least`, waits (up to 5 s) until that many lines are there.
  std::vector<LoggedRequest> requests(size_t at_least = 0) const;
  void clearLog() const;
  std::string errorLog() const;

 private:
  NginxServer() = default;
  Status launch();
  std::vector<LoggedRequest> parseLog() const;

  std::string m_work_dir, m_root_dir, m_binary;
  bool m_tls = false;
  bool m_http2 = false;
  uint16_t m_port = 0;
  pid_t m_pid = -1;
};

// A TCP proxy on 127.0.0.1 in front of `upstream_port`: every chunk the
// client sends (an HTTP request) is held for the delay before it is passed
// on, so each request costs one extra round trip of that length; answers
// pass at once. Chunks are held in a delay line, not one after another, so
// requests multiplexed on one connection (HTTP/2) each wait the delay once.
// Bytes pass unchanged (TLS too). One thread per connection.
class DelayProxy {
 public:
  static Status start(uint16_t upstream_port, double delay_ms, std::unique_ptr<DelayProxy>* out);
  ~DelayProxy();  // closes every connection and joins the threads
  DelayProxy(const DelayProxy&) = delete;
  DelayProxy& operator=(const DelayProxy&) = delete;

  uint16_t port() const { return m_port; }
  std::string url(const std::string& name) const;
  void setDelayMs(double delay_ms) { m_delay_us.store(uint64_t(delay_ms * 1000.0)); }
  // The next `connections` connections are closed after passing this many
  // bytes of the server's answers: a server that dies mid-answer.
  void cutConnections(uint64_t connections, uint64_t after_bytes) {
    m_cut_after_bytes.store(after_bytes);
    m_cuts_left.store(connections);
  }
  uint64_t connections() const { return m_connections.load(); }
  // Every later answer chunk has `from` replaced by `to` (a header
  // rewritten: a server that answers differently). Set before requests.
  void rewriteAnswers(std::string from, std::string to) {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_rewrite_from = std::move(from);
    m_rewrite_to = std::move(to);
  }

 private:
  DelayProxy() = default;
  void acceptLoop();
  void serve(int client_fd);

  uint16_t m_upstream_port = 0;
  uint16_t m_port = 0;
  int m_listen_fd = -1;
  std::atomic<uint64_t> m_delay_us{0};
  std::atomic<uint64_t> m_connections{0};
  std::atomic<uint64_t> m_cuts_left{0}, m_cut_after_bytes{0};
  std::atomic<bool> m_stopping{false};
  std::thread m_acceptor;
  std::mutex m_mutex;  // guards m_threads, m_rewrite_*
  std::vector<std::thread> m_threads;
  std::string m_rewrite_from, m_rewrite_to;
};

}  // namespace clipstream::test
