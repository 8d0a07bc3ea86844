#include <clipstream/testing/net.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pwd.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <sstream>

namespace clipstream::test {
namespace {

// How long nginx may take to accept its first connection.
constexpr int kStartWaitMs = 10000;

std::string errnoText() { return std::strerror(errno); }

// A port nobody listens on right now (the kernel's choice for port 0).
Status freePort(uint16_t* port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return Status::error(ErrorCode::kIo, "socket: " + errnoText());
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(addr);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    const std::string why = errnoText();
    ::close(fd);
    return Status::error(ErrorCode::kIo, "bind 127.0.0.1:0: " + why);
  }
  *port = ntohs(addr.sin_port);
  ::close(fd);
  return okStatus();
}

int connectLoopback(uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(port);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return -1;
  }
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
  return fd;
}

bool writeAll(int fd, const char* data, size_t bytes) {
  while (bytes > 0) {
    const ssize_t put = ::send(fd, data, bytes, MSG_NOSIGNAL);
    if (put < 0 && errno == EINTR) continue;
    if (put <= 0) return false;
    data += put;
    bytes -= size_t(put);
  }
  return true;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

// ---------------------------------------------------------------------------
// NginxServer

Status NginxServer::start(const std::string& work_dir, const std::string& root_dir,
                          std::unique_ptr<NginxServer>* out, bool tls, bool http2) {
  std::unique_ptr<NginxServer> server(new NginxServer());
  server->m_work_dir = work_dir;
  server->m_root_dir = root_dir;
  server->m_tls = tls;
  server->m_http2 = tls && http2;
  if (tls) {
    const std::string command = "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj "
                                "/CN=127.0.0.1 -addext subjectAltName=IP:127.0.0.1 -keyout '" +
                                work_dir + "/key.pem' -out '" + work_dir + "/cert.pem' 2>/dev/null";
    if (std::system(command.c_str()) != 0) {
      return Status::error(ErrorCode::kIo, "openssl could not make a test certificate (the Debian "
                                           "package openssl; scripts/deps.sh installs it)");
    }
  }
  const char* env = std::getenv("CLIPSTREAM_NGINX");
  server->m_binary = env != nullptr && *env != '\0' ? env : "/usr/sbin/nginx";
  if (::access(server->m_binary.c_str(), X_OK) != 0) {
    return Status::error(ErrorCode::kNotFound,
                         "nginx not found at " + server->m_binary +
                             ": the HTTP tests need the Debian package nginx-light "
                             "(scripts/deps.sh installs it; CLIPSTREAM_NGINX names another binary)");
  }
  ::mkdir((work_dir + "/tmp").c_str(), 0700);
  // A port taken between freePort() and nginx's bind: try another.
  Status status;
  for (int attempt = 0; attempt < 5; ++attempt) {
    status = freePort(&server->m_port);
    if (!status) return status;
    status = server->launch();
    if (status) break;
  }
  if (!status) return status;
  *out = std::move(server);
  return okStatus();
}

Status NginxServer::launch() {
  const std::string& w = m_work_dir;
  std::ostringstream conf;
  conf << "daemon off;\n"
       << "worker_processes 1;\n"
       << "pid " << w << "/nginx.pid;\n"
       << "error_log " << w << "/error.log warn;\n";
  // As root, nginx's workers would switch to "nobody", which cannot read a
  // private temporary folder: keep the caller's user.
  if (::geteuid() == 0) {
    if (const passwd* pw = ::getpwuid(0)) conf << "user " << pw->pw_name << ";\n";
  }
  conf << "events { worker_connections 1024; }\n"
       << "http {\n"
       << "  default_type application/octet-stream;\n"
       << "  log_format ranges '$status\\t$body_bytes_sent\\t$uri\\t$http_range\\t$http_if_range\\t$server_protocol';\n"
       << "  access_log " << w << "/access.log ranges;\n"
       << "  client_body_temp_path " << w << "/tmp;\n"
       << "  proxy_temp_path " << w << "/tmp;\n"
       << "  fastcgi_temp_path " << w << "/tmp;\n"
       << "  uwsgi_temp_path " << w << "/tmp;\n"
       << "  scgi_temp_path " << w << "/tmp;\n"
       << "  keepalive_requests 100000;\n"
       << "  server {\n"
       << "    listen 127.0.0.1:" << m_port << (m_tls ? " ssl" : "") << (m_http2 ? " http2" : "")
       << ";\n"
       << "    root " << m_root_dir << ";\n"
       << (m_tls ? "    ssl_certificate " + w + "/cert.pem;\n    ssl_certificate_key " + w +
                       "/key.pem;\n"
                 : std::string())
       << "    location = /forbidden.cstore { return 403; }\n"
       << "    location = /failing.cstore { return 503; }\n"
       << "  }\n"
       << "}\n";
  const std::string conf_path = w + "/nginx.conf";
  {
    std::ofstream file(conf_path, std::ios::trunc);
    file << conf.str();
    if (!file) return Status::error(ErrorCode::kIo, "cannot write " + conf_path);
  }
  const std::string error_log = w + "/error.log";
  const pid_t pid = ::fork();
  if (pid < 0) return Status::error(ErrorCode::kIo, "fork: " + errnoText());
  if (pid == 0) {
    // -e: the start-up error log too goes to the temporary folder.
    ::execl(m_binary.c_str(), "nginx", "-e", error_log.c_str(), "-p", w.c_str(), "-c",
            conf_path.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  m_pid = pid;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(kStartWaitMs);
  while (std::chrono::steady_clock::now() < deadline) {
    int wstatus = 0;
    if (::waitpid(m_pid, &wstatus, WNOHANG) == m_pid) {
      m_pid = -1;
      return Status::error(ErrorCode::kIo, "nginx exited at start: " + errorLog());
    }
    const int fd = connectLoopback(m_port);
    if (fd >= 0) {
      ::close(fd);
      return okStatus();
    }
    ::usleep(10000);
  }
  stop();
  return Status::error(ErrorCode::kIo, "nginx did not accept connections on port " +
                                           std::to_string(m_port) + ": " + errorLog());
}

NginxServer::~NginxServer() { stop(); }

void NginxServer::stop() {
  if (m_pid <= 0) return;
  ::kill(m_pid, SIGTERM);
  int wstatus = 0;
  while (::waitpid(m_pid, &wstatus, 0) < 0 && errno == EINTR) {
  }
  m_pid = -1;
}

Status NginxServer::restart() {
  if (m_pid > 0) return okStatus();
  return launch();
}

std::string NginxServer::url(const std::string& name) const {
  return std::string(m_tls ? "https" : "http") + "://127.0.0.1:" + std::to_string(m_port) + "/" + name;
}

std::vector<LoggedRequest> NginxServer::requests(size_t at_least) const {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  for (;;) {
    std::vector<LoggedRequest> out = parseLog();
    if (out.size() >= at_least || std::chrono::steady_clock::now() > deadline) return out;
    ::usleep(5000);
  }
}

std::vector<LoggedRequest> NginxServer::parseLog() const {
  std::vector<LoggedRequest> out;
  std::istringstream lines(readFile(m_work_dir + "/access.log"));
  std::string line;
  while (std::getline(lines, line)) {
    std::vector<std::string> fields;
    size_t start = 0;
    for (;;) {
      const size_t tab = line.find('\t', start);
      fields.push_back(line.substr(start, tab == std::string::npos ? std::string::npos : tab - start));
      if (tab == std::string::npos) break;
      start = tab + 1;
    }
    if (fields.size() != 6) continue;
    LoggedRequest r;
    r.status = std::atoi(fields[0].c_str());
    r.body_bytes = std::strtoull(fields[1].c_str(), nullptr, 10);
    r.uri = fields[2];
    r.range = fields[3] == "-" ? "" : fields[3];
    r.if_range = fields[4] == "-" ? "" : fields[4];
    r.protocol = fields[5];
    out.push_back(std::move(r));
  }
  return out;
}

void NginxServer::clearLog() const { ::truncate((m_work_dir + "/access.log").c_str(), 0); }

std::string NginxServer::errorLog() const { return readFile(m_work_dir + "/error.log"); }

// ---------------------------------------------------------------------------
// DelayProxy

Status DelayProxy::start(uint16_t upstream_port, double delay_ms, std::unique_ptr<DelayProxy>* out) {
  std::unique_ptr<DelayProxy> proxy(new DelayProxy());
  proxy->m_upstream_port = upstream_port;
  proxy->setDelayMs(delay_ms);
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return Status::error(ErrorCode::kIo, "socket: " + errnoText());
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(addr);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 || ::listen(fd, 256) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
    const std::string why = errnoText();
    ::close(fd);
    return Status::error(ErrorCode::kIo, "proxy listen: " + why);
  }
  proxy->m_listen_fd = fd;
  proxy->m_port = ntohs(addr.sin_port);
  DelayProxy* self = proxy.get();
  proxy->m_acceptor = std::thread([self] { self->acceptLoop(); });
  *out = std::move(proxy);
  return okStatus();
}

DelayProxy::~DelayProxy() {
  m_stopping.store(true);
  if (m_acceptor.joinable()) m_acceptor.join();
  ::close(m_listen_fd);
  std::lock_guard<std::mutex> lock(m_mutex);
  for (std::thread& t : m_threads) t.join();
}

std::string DelayProxy::url(const std::string& name) const {
  return "http://127.0.0.1:" + std::to_string(m_port) + "/" + name;
}

void DelayProxy::acceptLoop() {
  while (!m_stopping.load()) {
    pollfd p{m_listen_fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const int client = ::accept4(m_listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
    if (client < 0) continue;
    m_connections.fetch_add(1);
    std::lock_guard<std::mutex> lock(m_mutex);
    m_threads.emplace_back([this, client] { serve(client); });
  }
}

void DelayProxy::serve(int client_fd) {
  const int one = 1;
  ::setsockopt(client_fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
  const int upstream_fd = connectLoopback(m_upstream_port);
  if (upstream_fd < 0) {
    ::close(client_fd);  // the client sees the connection refused as a reset
    return;
  }
  std::vector<char> buffer(size_t(256) << 10);
  // A connection chosen to be cut passes this many answer bytes, then closes.
  uint64_t answer_budget = UINT64_MAX;
  for (uint64_t left = m_cuts_left.load(); left > 0;) {
    if (m_cuts_left.compare_exchange_weak(left, left - 1)) {
      answer_budget = m_cut_after_bytes.load();
      break;
    }
  }
  // The client's bytes wait out the delay in this line, each chunk with its
  // time of release, while reading goes on: requests multiplexed on one
  // connection (HTTP/2) are each delayed once, not one after another.
  using Clock = std::chrono::steady_clock;
  std::deque<std::pair<Clock::time_point, std::vector<char>>> held;
  pollfd fds[2] = {{client_fd, POLLIN, 0}, {upstream_fd, POLLIN, 0}};
  bool open = true;
  while (open && !m_stopping.load()) {
    int timeout_ms = 50;
    if (!held.empty()) {
      const auto wait = std::chrono::ceil<std::chrono::milliseconds>(held.front().first - Clock::now());
      timeout_ms = int(std::clamp<int64_t>(wait.count(), 0, 50));
    }
    const int ready = ::poll(fds, 2, timeout_ms);
    if (ready > 0 && (fds[0].revents & (POLLIN | POLLHUP | POLLERR))) {
      const ssize_t got = ::recv(client_fd, buffer.data(), buffer.size(), 0);
      if (got <= 0) break;
      held.emplace_back(Clock::now() + std::chrono::microseconds(m_delay_us.load()),
                        std::vector<char>(buffer.data(), buffer.data() + got));
    }
    while (!held.empty() && held.front().first <= Clock::now()) {
      if (!writeAll(upstream_fd, held.front().second.data(), held.front().second.size())) {
        open = false;
        break;
      }
      held.pop_front();
    }
    if (ready > 0 && (fds[1].revents & (POLLIN | POLLHUP | POLLERR))) {
      const ssize_t got = ::recv(upstream_fd, buffer.data(), buffer.size(), 0);
      if (got <= 0) break;
      std::string from, to;
      {
        std::lock_guard<std::mutex> lock(m_mutex);
        from = m_rewrite_from, to = m_rewrite_to;
      }
      if (!from.empty()) {
        std::string chunk(buffer.data(), size_t(got));
        for (size_t at = chunk.find(from); at != std::string::npos; at = chunk.find(from, at + to.size()))
          chunk.replace(at, from.size(), to);
        const size_t pass = size_t(std::min<uint64_t>(chunk.size(), answer_budget));
        if (!writeAll(client_fd, chunk.data(), pass)) break;
        if (answer_budget != UINT64_MAX) answer_budget -= pass;
        if (answer_budget == 0) break;
        continue;
      }
      const size_t pass = size_t(std::min<uint64_t>(uint64_t(got), answer_budget));
      if (!writeAll(client_fd, buffer.data(), pass)) break;
      if (answer_budget != UINT64_MAX) answer_budget -= pass;
      if (answer_budget == 0) break;
    }
  }
  ::close(upstream_fd);
  ::close(client_fd);
}

}  // namespace clipstream::test
