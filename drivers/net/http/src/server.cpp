#include "airground/drivers/net/http/server.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <pthread.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "airground/drivers/net/http/sha1.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/log.hpp"

namespace ag::net::http {

namespace {
constexpr std::uint64_t kListenTag = ~std::uint64_t{0};
constexpr std::uint64_t kWakeTag = ~std::uint64_t{0} - 1;
constexpr std::int64_t kNsPerSecond = 1'000'000'000;
}  // namespace

std::string_view status_text(int s) noexcept {
  switch (s) {
    case 101: return "Switching Protocols";
    case 200: return "OK";
    case 202: return "Accepted";
    case 400: return "Bad Request";
    case 404: return "Not Found";
    case 405: return "Method Not Allowed";
    case 426: return "Upgrade Required";
    case 500: return "Internal Server Error";
    case 503: return "Service Unavailable";
    default: return "Unknown";
  }
}

struct HttpServer::Conn {
  int fd{-1};
  ClientId id{0};
  std::string in;
  std::vector<std::uint8_t> out;
  std::size_t out_off{0};
  bool ws{false};
  bool close_after_flush{false};
  bool dead{false};
  bool want_out{false};
  std::string protocol;  // the WebSocket subprotocol accepted ("" none)
  std::int64_t last_progress_ns{0};  // last time output drained a byte (or became non-empty)
  std::int64_t last_request_ns{0};   // accept or the last complete request
  char peer[48]{};
  [[nodiscard]] std::size_t pending() const noexcept { return out.size() - out_off; }
};

HttpServer::HttpServer(const HttpServerParams& p, Handler& h) : p_(p), h_(h) {}

Result<std::unique_ptr<HttpServer>> HttpServer::start(const HttpServerParams& p, Handler& handler) {
  in_addr addr{};
  if (::inet_pton(AF_INET, p.bind.c_str(), &addr) != 1)
    return Error::make(ErrorCode::kInvalidArgument, p.name + ".bind: '" + p.bind + "' is not an IPv4 address");
  if (p.port < 0 || p.port > 65535)
    return Error::make(ErrorCode::kInvalidArgument, p.name + ".port: " + std::to_string(p.port) + " is outside [0, 65535]");
  std::unique_ptr<HttpServer> s(new HttpServer(p, handler));
  s->epoll_fd_ = ::epoll_create1(EPOLL_CLOEXEC);
  s->wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (s->epoll_fd_ < 0 || s->wake_fd_ < 0)
    return Error::make(ErrorCode::kIo, p.name + ": epoll/eventfd: " + std::string(std::strerror(errno)));
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.u64 = kWakeTag;
  ::epoll_ctl(s->epoll_fd_, EPOLL_CTL_ADD, s->wake_fd_, &ev);
  s->try_listen();  // a failure is retried from the thread
  s->thread_ = std::thread([raw = s.get()] { raw->run(); });
  return s;
}

HttpServer::~HttpServer() {
  stop();
  for (auto& c : conns_)
    if (c->fd >= 0) ::close(c->fd);
  if (listen_fd_ >= 0) ::close(listen_fd_);
  if (wake_fd_ >= 0) ::close(wake_fd_);
  if (epoll_fd_ >= 0) ::close(epoll_fd_);
}

void HttpServer::stop() noexcept {
  stop_.store(true, std::memory_order_release);
  if (wake_fd_ >= 0) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(wake_fd_, &one, sizeof one);
  }
  if (thread_.joinable()) thread_.join();
}

bool HttpServer::try_listen() noexcept {
  last_bind_try_ns_ = monotonic_now();
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(static_cast<std::uint16_t>(p_.port));
  ::inet_pton(AF_INET, p_.bind.c_str(), &sa.sin_addr);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof sa) != 0 || ::listen(fd, 64) != 0) {
    const int e = errno;
    ::close(fd);
    if (c_.bind_failures.fetch_add(1, std::memory_order_relaxed) % 60 == 0)
      AG_LOG_ERROR(p_.name.c_str(), "cannot listen on %s:%d: %s (retrying every second; the page is off meanwhile) failures=%llu",
                   p_.bind.c_str(), p_.port, std::strerror(e),
                   static_cast<unsigned long long>(c_.bind_failures.load(std::memory_order_relaxed)));
    return false;
  }
  socklen_t len = sizeof sa;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  listen_fd_ = fd;
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.u64 = kListenTag;
  ::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, fd, &ev);
  bound_port_.store(ntohs(sa.sin_port), std::memory_order_release);
  c_.listening.store(true, std::memory_order_release);
  AG_LOG_INFO(p_.name.c_str(), "serving http://%s:%d/ (WebSocket %s) max_clients=%zu", p_.bind.c_str(),
              static_cast<int>(ntohs(sa.sin_port)), p_.ws_path.c_str(), p_.max_clients);
  return true;
}

void HttpServer::run() noexcept {
  ::pthread_setname_np(::pthread_self(), "ag-web");
  epoll_event evs[64];
  const std::int64_t tick = static_cast<std::int64_t>(p_.tick_ms) * 1'000'000;
  std::int64_t next_tick = monotonic_now();
  while (!stop_.load(std::memory_order_acquire)) {
    std::int64_t now = monotonic_now();
    if (listen_fd_ < 0 && now - last_bind_try_ns_ >= kNsPerSecond) try_listen();
    const int timeout = next_tick > now ? static_cast<int>((next_tick - now) / 1'000'000) + 1 : 0;
    const int n = ::epoll_wait(epoll_fd_, evs, 64, timeout);
    for (int i = 0; i < n; ++i) {
      const std::uint64_t tag = evs[i].data.u64;
      if (tag == kListenTag) {
        accept_all();
      } else if (tag == kWakeTag) {
        std::uint64_t v;
        [[maybe_unused]] const ssize_t r = ::read(wake_fd_, &v, sizeof v);
      } else if (Conn* c = find(tag)) {
        if ((evs[i].events & (EPOLLIN | EPOLLHUP | EPOLLERR)) != 0) on_readable(*c);
        if (!c->dead && (evs[i].events & EPOLLOUT) != 0) flush(*c);
      }
    }
    now = monotonic_now();
    if (now >= next_tick) {
      h_.tick(*this);
      check_slow(now);
      next_tick = now + tick;
    }
    for (ClientId id : to_close_) close_conn(id);
    to_close_.clear();
  }
}

HttpServer::Conn* HttpServer::find(ClientId id) const noexcept {
  for (const auto& c : conns_)
    if (c->id == id && !c->dead) return c.get();
  return nullptr;
}

void HttpServer::accept_all() noexcept {
  for (;;) {
    sockaddr_in sa{};
    socklen_t len = sizeof sa;
    const int fd = ::accept4(listen_fd_, reinterpret_cast<sockaddr*>(&sa), &len, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;
    c_.connections.fetch_add(1, std::memory_order_relaxed);
    if (conns_.size() >= p_.max_clients) {
      static constexpr char kFull[] =
          "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: 24\r\nConnection: close\r\n\r\n"
          "too many clients, retry\n";
      c_.rejected_full.fetch_add(1, std::memory_order_relaxed);
      [[maybe_unused]] const ssize_t w = ::send(fd, kFull, sizeof kFull - 1, MSG_NOSIGNAL);
      ::close(fd);
      continue;
    }
    const int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    if (p_.socket_send_buffer > 0) ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &p_.socket_send_buffer, sizeof p_.socket_send_buffer);
    auto c = std::make_unique<Conn>();
    c->fd = fd;
    c->id = next_id_++;
    c->last_progress_ns = monotonic_now();
    c->last_request_ns = c->last_progress_ns;
    char ip[INET_ADDRSTRLEN] = "?";
    ::inet_ntop(AF_INET, &sa.sin_addr, ip, sizeof ip);
    std::snprintf(c->peer, sizeof c->peer, "%s:%d", ip, static_cast<int>(ntohs(sa.sin_port)));
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = c->id;
    ::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, fd, &ev);
    conns_.push_back(std::move(c));
    c_.clients.store(static_cast<std::uint32_t>(conns_.size()), std::memory_order_relaxed);
  }
}

void HttpServer::on_readable(Conn& c) noexcept {
  char buf[16384];
  for (;;) {
    const ssize_t n = ::recv(c.fd, buf, sizeof buf, 0);
    if (n > 0) {
      c_.bytes_in.fetch_add(static_cast<std::uint64_t>(n), std::memory_order_relaxed);
      c.in.append(buf, static_cast<std::size_t>(n));
      // Never hold more than one request head or one frame of input.
      if (c.in.size() > p_.max_request_bytes + p_.max_ws_in_frame + kWsMaxHeader) break;
      continue;
    }
    if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
      c.dead = true;
      to_close_.push_back(c.id);
      return;
    }
    if (errno == EINTR) continue;
    break;
  }
  if (c.ws) handle_ws(c);
  else handle_http(c);
}

void HttpServer::handle_http(Conn& c) noexcept {
  while (!c.dead && !c.ws && !c.close_after_flush && !c.in.empty()) {
    HttpRequest req;
    std::size_t used = 0;
    std::string why;
    const HttpParse r = parse_http_request(c.in, p_.max_request_bytes, req, used, why);
    if (r == HttpParse::kNeedMore) return;
    if (r == HttpParse::kBad) {
      const auto bad = c_.bad_requests.fetch_add(1, std::memory_order_relaxed) + 1;
      AG_LOG_WARN(p_.name.c_str(), "400 to %s: %s bad_requests=%llu", c.peer, why.c_str(), static_cast<unsigned long long>(bad));
      respond(c, HttpResponse{400, "text/plain; charset=utf-8", "bad request: " + why + "\n", {}}, false);
      c.in.clear();
      return;
    }
    c_.requests.fetch_add(1, std::memory_order_relaxed);
    c.last_request_ns = monotonic_now();
    c.in.erase(0, used);
    if (req.method == "POST") {
      HttpResponse resp = h_.post(req);
      if (resp.status == 405) c_.not_allowed.fetch_add(1, std::memory_order_relaxed);
      if (resp.status == 404) c_.not_found.fetch_add(1, std::memory_order_relaxed);
      respond(c, resp, req.keep_alive());
      continue;
    }
    if (req.method != "GET") {
      c_.not_allowed.fetch_add(1, std::memory_order_relaxed);
      respond(c, HttpResponse{405, "text/plain; charset=utf-8", "only GET and POST are served\n", "Allow: GET, POST\r\n"}, req.keep_alive());
      continue;
    }
    const bool wants_ws = req.header_has_token("upgrade", "websocket");
    std::string protocol;
    if (wants_ws && !req.header("sec-websocket-protocol").empty()) protocol = h_.ws_subprotocol(req);
    if (req.path == p_.ws_path || (wants_ws && !protocol.empty())) {
      upgrade(c, req, protocol);
      return;
    }
    HttpResponse resp = h_.get(req);
    if (resp.status == 404) c_.not_found.fetch_add(1, std::memory_order_relaxed);
    respond(c, resp, req.keep_alive());
  }
}

void HttpServer::upgrade(Conn& c, const HttpRequest& req, const std::string& protocol) noexcept {
  const std::string_view key = req.header("sec-websocket-key");
  if (!req.header_has_token("upgrade", "websocket") || !req.header_has_token("connection", "upgrade") || key.size() != 24 ||
      key.substr(22) != "==" || req.version_minor != 1) {
    c_.bad_requests.fetch_add(1, std::memory_order_relaxed);
    respond(c, HttpResponse{400, "text/plain; charset=utf-8", "bad WebSocket handshake (RFC 6455 §4.2.1)\n", {}}, false);
    return;
  }
  if (req.header("sec-websocket-version") != "13") {
    c_.bad_requests.fetch_add(1, std::memory_order_relaxed);
    respond(c, HttpResponse{426, "text/plain; charset=utf-8", "WebSocket version 13 only\n", "Sec-WebSocket-Version: 13\r\n"}, false);
    return;
  }
  const std::string head = "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: " +
                           websocket_accept(key) + "\r\n" + (protocol.empty() ? "" : "Sec-WebSocket-Protocol: " + protocol + "\r\n") + "\r\n";
  queue(c, {reinterpret_cast<const std::uint8_t*>(head.data()), head.size()});
  c.ws = true;
  c.protocol = protocol;
  ws_ids_.push_back(c.id);
  c_.ws_opened.fetch_add(1, std::memory_order_relaxed);
  c_.ws_clients.store(static_cast<std::uint32_t>(ws_ids_.size()), std::memory_order_relaxed);
  h_.ws_open(*this, c.id);
  if (!c.dead && !c.in.empty()) handle_ws(c);
}

void HttpServer::handle_ws(Conn& c) noexcept {
  while (!c.dead && !c.close_after_flush) {
    WsFrame f;
    const char* why = "";
    const auto* data = reinterpret_cast<const std::uint8_t*>(c.in.data());
    const WsParse r = ws_parse_header({data, c.in.size()}, p_.max_ws_in_frame, true, f, &why);
    if (r == WsParse::kNeedMore) return;
    if (r == WsParse::kError) {
      const auto bad = c_.ws_bad_frames.fetch_add(1, std::memory_order_relaxed) + 1;
      AG_LOG_WARN(p_.name.c_str(), "WebSocket protocol error from %s: %s ws_bad_frames=%llu", c.peer, why, static_cast<unsigned long long>(bad));
      const std::uint8_t close[4] = {0x88, 2, 0x03, 0xEA};  // 1002 protocol error
      queue(c, close);
      c.close_after_flush = true;
      flush(c);
      c.in.clear();
      return;
    }
    const std::size_t total = f.header_len + static_cast<std::size_t>(f.payload_len);
    if (c.in.size() < total) return;
    std::span<std::uint8_t> payload(reinterpret_cast<std::uint8_t*>(c.in.data()) + f.header_len, static_cast<std::size_t>(f.payload_len));
    ws_apply_mask(payload, f.mask);
    c_.ws_frames_in.fetch_add(1, std::memory_order_relaxed);
    switch (f.opcode) {
      case WsOpcode::kClose: {
        std::uint8_t hdr[kWsMaxHeader];
        const std::size_t hl = ws_frame_header(hdr, WsOpcode::kClose, payload.size() >= 2 ? 2 : 0);
        queue(c, {hdr, hl});
        if (payload.size() >= 2) queue(c, payload.first(2));
        c.close_after_flush = true;
        flush(c);
        break;
      }
      case WsOpcode::kPing: ws_send(c.id, WsOpcode::kPong, payload); break;
      case WsOpcode::kPong: break;
      default: h_.ws_message(*this, c.id, f.opcode, payload); break;
    }
    if (c.dead) return;
    c.in.erase(0, total);
  }
}

void HttpServer::respond(Conn& c, const HttpResponse& r, bool keep_alive) noexcept {
  if (r.status >= 200 && r.status < 300) c_.responses_2xx.fetch_add(1, std::memory_order_relaxed);
  std::string head = "HTTP/1.1 " + std::to_string(r.status) + " " + std::string(status_text(r.status)) + "\r\nContent-Type: " +
                     r.content_type + "\r\nContent-Length: " + std::to_string(r.body.size()) +
                     "\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n" + r.extra_headers +
                     (keep_alive ? "" : "Connection: close\r\n") + "\r\n";
  queue(c, {reinterpret_cast<const std::uint8_t*>(head.data()), head.size()});
  queue(c, {reinterpret_cast<const std::uint8_t*>(r.body.data()), r.body.size()});
  if (!keep_alive) c.close_after_flush = true;
  flush(c);
}

void HttpServer::queue(Conn& c, std::span<const std::uint8_t> bytes) noexcept {
  if (c.pending() == 0) {
    c.out.clear();
    c.out_off = 0;
    c.last_progress_ns = monotonic_now();
  }
  c.out.insert(c.out.end(), bytes.begin(), bytes.end());
}

bool HttpServer::ws_send(ClientId id, WsOpcode op, std::span<const std::uint8_t> payload) {
  Conn* c = find(id);
  if (c == nullptr || !c->ws || c->close_after_flush) return false;
  std::uint8_t hdr[kWsMaxHeader];
  const std::size_t hl = ws_frame_header(hdr, op, payload.size());
  if (c->pending() + hl + payload.size() > p_.client_buffer_bytes) {
    const auto n = c_.slow_dropped.fetch_add(1, std::memory_order_relaxed) + 1;
    AG_LOG_WARN(p_.name.c_str(), "dropping %s: %zu B waiting, a %zu B frame does not fit client_buffer_bytes=%zu slow_dropped=%llu",
                c->peer, c->pending(), payload.size(), p_.client_buffer_bytes, static_cast<unsigned long long>(n));
    c->dead = true;
    to_close_.push_back(id);
    return false;
  }
  queue(*c, {hdr, hl});
  queue(*c, payload);
  c_.ws_frames_out.fetch_add(1, std::memory_order_relaxed);
  flush(*c);
  return !c->dead;
}

std::string_view HttpServer::ws_protocol(ClientId id) const noexcept {
  const Conn* c = find(id);
  return c == nullptr ? std::string_view{} : std::string_view(c->protocol);
}

std::size_t HttpServer::ws_pending(ClientId id) const noexcept {
  const Conn* c = find(id);
  return c == nullptr ? SIZE_MAX : c->pending();
}

void HttpServer::flush(Conn& c) noexcept {
  while (c.pending() > 0) {
    const ssize_t n = ::send(c.fd, c.out.data() + c.out_off, c.pending(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      c.out_off += static_cast<std::size_t>(n);
      c.last_progress_ns = monotonic_now();
      c_.bytes_out.fetch_add(static_cast<std::uint64_t>(n), std::memory_order_relaxed);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) break;
    c.dead = true;
    to_close_.push_back(c.id);
    return;
  }
  if (c.pending() == 0) {
    c.out.clear();
    c.out_off = 0;
    if (c.close_after_flush) {
      c.dead = true;
      to_close_.push_back(c.id);
      return;
    }
  } else if (c.out_off > (1u << 16) && c.out_off * 2 > c.out.size()) {
    c.out.erase(c.out.begin(), c.out.begin() + static_cast<std::ptrdiff_t>(c.out_off));
    c.out_off = 0;
  }
  update_interest(c);
}

void HttpServer::update_interest(Conn& c) noexcept {
  const bool want = c.pending() > 0;
  if (want == c.want_out) return;
  epoll_event ev{};
  ev.events = EPOLLIN | (want ? EPOLLOUT : 0u);
  ev.data.u64 = c.id;
  ::epoll_ctl(epoll_fd_, EPOLL_CTL_MOD, c.fd, &ev);
  c.want_out = want;
}

void HttpServer::check_slow(std::int64_t now) noexcept {
  const auto limit = static_cast<std::int64_t>(p_.slow_client_s * 1e9);
  const auto idle = static_cast<std::int64_t>(p_.request_timeout_s * 1e9);
  for (auto& c : conns_) {
    if (!c->dead && !c->ws && c->pending() == 0 && now - c->last_request_ns >= idle) {
      c_.timed_out.fetch_add(1, std::memory_order_relaxed);
      c->dead = true;
      to_close_.push_back(c->id);
      continue;
    }
    if (c->dead || c->pending() == 0 || now - c->last_progress_ns < limit) continue;
    const auto n = c_.slow_dropped.fetch_add(1, std::memory_order_relaxed) + 1;
    AG_LOG_WARN(p_.name.c_str(), "dropping %s: %zu B not drained for %.1f s slow_dropped=%llu", c->peer, c->pending(), p_.slow_client_s,
                static_cast<unsigned long long>(n));
    c->dead = true;
    to_close_.push_back(c->id);
  }
}

void HttpServer::close_conn(ClientId id) noexcept {
  for (std::size_t i = 0; i < conns_.size(); ++i) {
    if (conns_[i]->id != id) continue;
    Conn& c = *conns_[i];
    ::epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, c.fd, nullptr);
    ::close(c.fd);
    if (c.ws) {
      for (std::size_t k = 0; k < ws_ids_.size(); ++k)
        if (ws_ids_[k] == id) {
          ws_ids_.erase(ws_ids_.begin() + static_cast<std::ptrdiff_t>(k));
          break;
        }
      c_.ws_closed.fetch_add(1, std::memory_order_relaxed);
      c_.ws_clients.store(static_cast<std::uint32_t>(ws_ids_.size()), std::memory_order_relaxed);
      h_.ws_close(id);
    }
    conns_.erase(conns_.begin() + static_cast<std::ptrdiff_t>(i));
    c_.clients.store(static_cast<std::uint32_t>(conns_.size()), std::memory_order_relaxed);
    return;
  }
}

}  // namespace ag::net::http
