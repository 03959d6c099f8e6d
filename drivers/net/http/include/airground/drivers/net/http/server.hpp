// The HTTP/1.1 + WebSocket server: one thread, non-blocking sockets, epoll. It serves what a Handler
// answers to GET, upgrades /ws to a WebSocket (and any path where the handler picks one of the client's
// subprotocols, RFC 6455 §1.9: e.g. foxglove.websocket.v1 at /), and calls the handler's tick() every
// tick period on the same thread, where the handler pushes frames to its clients.
//
// Bounds: at most max_clients connections (more get 503 and are closed); a request head above
// max_request_bytes, a malformed request or WebSocket frame gets 400 (or a close 1002) and is counted;
// each client's output is held to client_buffer_bytes: a frame that does not fit, or output that has not
// drained for slow_client_s, drops that client (counted) — nothing waits for a slow browser.
// If the port cannot be bound the server retries every second (counted) instead of failing its owner.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "airground/drivers/net/http/http_request.hpp"
#include "airground/drivers/net/http/websocket.hpp"
#include "airground/platform/result.hpp"

namespace ag::net::http {

struct HttpServerParams {
  std::string bind{"0.0.0.0"};
  int port{8080};  // 0 = any free port (tests), see HttpServer::port()
  std::size_t max_clients{16};
  std::size_t max_request_bytes{8192};
  std::size_t max_ws_in_frame{65536};
  std::size_t client_buffer_bytes{4u << 20};
  double slow_client_s{5.0};
  double request_timeout_s{10.0};        // an HTTP connection without a complete request this long is closed
  int socket_send_buffer{256 * 1024};    // [B] SO_SNDBUF of each client socket (bounds the kernel's share too)
  int tick_ms{50};
  std::string ws_path{"/ws"};
  std::string name{"web"};  // for log lines and the thread name
};

struct HttpResponse {
  int status{200};
  std::string content_type{"text/plain; charset=utf-8"};
  std::string body;
  std::string extra_headers;  // complete lines, each ending in \r\n
};

struct HttpServerCounters {
  std::atomic<std::uint64_t> connections{0}, requests{0}, responses_2xx{0};
  std::atomic<std::uint64_t> bad_requests{0};   // 400: malformed head, bad handshake
  std::atomic<std::uint64_t> not_found{0}, not_allowed{0};
  std::atomic<std::uint64_t> rejected_full{0};  // 503: max_clients reached
  std::atomic<std::uint64_t> ws_opened{0}, ws_closed{0}, ws_frames_out{0}, ws_frames_in{0}, ws_bad_frames{0};
  std::atomic<std::uint64_t> slow_dropped{0};   // clients dropped for not reading
  std::atomic<std::uint64_t> timed_out{0};      // HTTP connections closed for sending no complete request
  std::atomic<std::uint64_t> bytes_out{0}, bytes_in{0};
  std::atomic<std::uint64_t> bind_failures{0};
  std::atomic<std::uint32_t> clients{0}, ws_clients{0};
  std::atomic<bool> listening{false};
};

class HttpServer {
 public:
  using ClientId = std::uint64_t;

  // Called on the server thread only.
  class Handler {
   public:
    virtual ~Handler() = default;
    virtual HttpResponse get(const HttpRequest& req) = 0;
    // A POST without a body (its arguments in the query); 405 unless the handler takes POST.
    virtual HttpResponse post(const HttpRequest& /*req*/) { return {405, "text/plain; charset=utf-8", "only GET is served\n", "Allow: GET\r\n"}; }
    // A WebSocket client connected (after the 101 was queued): send it what it needs to start.
    virtual void ws_open(HttpServer& server, ClientId id) = 0;
    virtual void ws_close(ClientId /*id*/) {}
    virtual void ws_message(HttpServer& /*server*/, ClientId /*id*/, WsOpcode /*op*/, std::span<const std::uint8_t> /*payload*/) {}
    // A WebSocket upgrade: the subprotocol to accept from the client's Sec-WebSocket-Protocol list ("" =
    // none). A non-empty answer also accepts the upgrade at a path other than ws_path.
    virtual std::string ws_subprotocol(const HttpRequest& /*req*/) { return {}; }
    // Every tick_ms: push updates to the clients.
    virtual void tick(HttpServer& server) = 0;
  };

  // Creates the socket and starts the thread. A bind error is logged and retried (see above); only a
  // bad address or a failing epoll/thread is an error here.
  static Result<std::unique_ptr<HttpServer>> start(const HttpServerParams& p, Handler& handler);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;
  void stop() noexcept;

  // The bound port (0 while not listening).
  [[nodiscard]] int port() const noexcept { return bound_port_.load(std::memory_order_acquire); }
  [[nodiscard]] const HttpServerCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const HttpServerParams& params() const noexcept { return p_; }

  // ---- server thread only (from Handler callbacks)
  // Queues one frame; false if the client is gone or was dropped because the frame did not fit.
  bool ws_send(ClientId id, WsOpcode op, std::span<const std::uint8_t> payload);
  bool ws_send_text(ClientId id, std::string_view text) {
    return ws_send(id, WsOpcode::kText, {reinterpret_cast<const std::uint8_t*>(text.data()), text.size()});
  }
  // The subprotocol a WebSocket client was accepted with ("" none or unknown client).
  [[nodiscard]] std::string_view ws_protocol(ClientId id) const noexcept;
  // Bytes queued to a client and not yet written (SIZE_MAX if unknown).
  [[nodiscard]] std::size_t ws_pending(ClientId id) const noexcept;
  [[nodiscard]] const std::vector<ClientId>& ws_clients() const noexcept { return ws_ids_; }

 private:
  struct Conn;
  HttpServer(const HttpServerParams& p, Handler& h);
  void run() noexcept;
  bool try_listen() noexcept;
  void accept_all() noexcept;
  void on_readable(Conn& c) noexcept;
  void handle_http(Conn& c) noexcept;
  void handle_ws(Conn& c) noexcept;
  void upgrade(Conn& c, const HttpRequest& req, const std::string& protocol) noexcept;
  void respond(Conn& c, const HttpResponse& r, bool keep_alive) noexcept;
  void queue(Conn& c, std::span<const std::uint8_t> bytes) noexcept;
  void flush(Conn& c) noexcept;
  void update_interest(Conn& c) noexcept;
  void close_conn(ClientId id) noexcept;
  void check_slow(std::int64_t now_ns) noexcept;
  Conn* find(ClientId id) const noexcept;

  HttpServerParams p_;
  Handler& h_;
  HttpServerCounters c_;
  int epoll_fd_{-1}, listen_fd_{-1}, wake_fd_{-1};
  std::atomic<int> bound_port_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::vector<std::unique_ptr<Conn>> conns_;
  std::vector<ClientId> ws_ids_;
  std::vector<ClientId> to_close_;
  ClientId next_id_{1};
  std::int64_t last_bind_try_ns_{0};
};

[[nodiscard]] std::string_view status_text(int status) noexcept;

}  // namespace ag::net::http
