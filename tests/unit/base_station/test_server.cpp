// The HTTP/WebSocket server on real loopback sockets: pages, 400/404/405/503 with their counters, the
// RFC 6455 handshake (and a subprotocol picked by the handler), frames both ways, and a client that stops
// reading dropped while another keeps up.
// GCC 12 reports a false -Warray-bounds inside std::string for short literal payloads below.
#pragma GCC diagnostic ignored "-Warray-bounds"
#pragma GCC diagnostic ignored "-Wstringop-overflow"
#pragma GCC diagnostic ignored "-Wstringop-overread"
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>

#include "airground/drivers/net/http/server.hpp"
#include "http_client.hpp"

namespace ag::net::http {
namespace {
using base_station::test::Client;
using base_station::test::get_request;
using base_station::test::ws_upgrade;

// Serves "/" and pushes a numbered binary frame of `frame_bytes` to every WebSocket client each tick.
class TestHandler final : public HttpServer::Handler {
 public:
  HttpResponse get(const HttpRequest& r) override {
    if (r.path == "/") return {200, "text/html", "<html>hi</html>", {}};
    return {404, "text/plain", "no", {}};
  }
  void ws_open(HttpServer& s, HttpServer::ClientId id) override { s.ws_send_text(id, "hello"); }
  void ws_message(HttpServer& s, HttpServer::ClientId id, WsOpcode, std::span<const std::uint8_t> p) override {
    s.ws_send_text(id, "echo:" + std::string(p.begin(), p.end()));
  }
  void tick(HttpServer& s) override {
    if (frame_bytes.load() == 0) return;
    std::vector<std::uint8_t> f(frame_bytes.load(), 0xAB);
    for (auto id : s.ws_clients()) s.ws_send(id, WsOpcode::kBinary, f);
    ticks.fetch_add(1);
  }
  std::atomic<std::size_t> frame_bytes{0};
  std::atomic<int> ticks{0};
};

std::unique_ptr<HttpServer> start(TestHandler& h, std::size_t max_clients = 8, std::size_t buffer = 1u << 20, double slow_s = 5.0) {
  HttpServerParams p;
  p.bind = "127.0.0.1";
  p.port = 0;
  p.max_clients = max_clients;
  p.client_buffer_bytes = buffer;
  p.slow_client_s = slow_s;
  p.tick_ms = 10;
  auto s = HttpServer::start(p, h);
  EXPECT_TRUE(s.ok());
  for (int i = 0; i < 200 && s.value()->port() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  return std::move(s).value();
}

template <typename P>
bool eventually(P p, double s = 2.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<int>(s * 1000));
  while (std::chrono::steady_clock::now() < end) {
    if (p()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return p();
}

TEST(HttpServer, ServesGetKeepsAliveAndAnswers404And405) {
  TestHandler h;
  auto s = start(h);
  Client c(s->port());
  ASSERT_TRUE(c.ok());
  c.send(get_request("/", false) + get_request("/missing", false) + "DELETE / HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(c.read_contains("405 Method Not Allowed")) << c.buf;
  EXPECT_EQ(c.buf.find("HTTP/1.1 200 OK"), 0U) << c.buf;
  EXPECT_NE(c.buf.find("Content-Length: 15\r\n"), std::string::npos);
  EXPECT_NE(c.buf.find("<html>hi</html>HTTP/1.1 404 Not Found"), std::string::npos) << "pipelined on one connection";
  EXPECT_EQ(s->counters().requests.load(), 3U);
  EXPECT_EQ(s->counters().not_found.load(), 1U);
  EXPECT_EQ(s->counters().not_allowed.load(), 1U);
  EXPECT_EQ(s->counters().bad_requests.load(), 0U);
}

TEST(HttpServer, MalformedRequestsGet400AreCountedAndTheServerGoesOn) {
  TestHandler h;
  auto s = start(h);
  const char* bad[] = {"GARBAGE\r\n\r\n", "GET / HTTP/9.9\r\nHost: a\r\n\r\n", "GET / HTTP/1.1\r\n\r\n", "\x16\x03\x01\x02\x01\x01\x01\x01\xfc\x03\x03\r\n\r\n"};
  for (const char* b : bad) {
    Client c(s->port());
    c.send(std::string(b));
    ASSERT_TRUE(c.read_to_close()) << b;
    EXPECT_EQ(c.buf.find("HTTP/1.1 400 Bad Request"), 0U) << b << " -> " << c.buf;
  }
  {
    Client c(s->port());  // a head that never ends
    c.send(std::string(9000, 'A'));
    ASSERT_TRUE(c.read_to_close());
    EXPECT_NE(c.buf.find("400"), std::string::npos);
  }
  EXPECT_EQ(s->counters().bad_requests.load(), 5U);
  Client ok(s->port());
  ok.send(get_request("/"));
  ASSERT_TRUE(ok.read_to_close());
  EXPECT_EQ(ok.buf.find("HTTP/1.1 200 OK"), 0U);
}

TEST(HttpServer, WebSocketHandshakeFramesPingAndClose) {
  TestHandler h;
  auto s = start(h);
  Client c(s->port());
  c.send(ws_upgrade());
  ASSERT_TRUE(c.read_contains("hello")) << c.buf;
  EXPECT_EQ(c.buf.find("HTTP/1.1 101 Switching Protocols\r\n"), 0U);
  EXPECT_NE(c.buf.find("Sec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n"), std::string::npos);
  c.send(base_station::test::client_frame(1, "abc"));
  c.send(base_station::test::client_frame(9, "pp"));
  ASSERT_TRUE(c.read_until([](const std::string& b) { return base_station::test::ws_frames(b).size() >= 3; }));
  auto f = base_station::test::ws_frames(c.buf);
  EXPECT_EQ(f[0].opcode, 1);
  EXPECT_EQ(f[0].payload, "hello");
  EXPECT_EQ(f[1].payload, "echo:abc");
  EXPECT_EQ(f[2].opcode, 10);
  EXPECT_EQ(f[2].payload, "pp") << "pong echoes the ping";
  c.send(base_station::test::client_frame(8, std::string("\x03\xe8", 2)));
  ASSERT_TRUE(c.read_to_close());
  f = base_station::test::ws_frames(c.buf);
  EXPECT_EQ(f.back().opcode, 8);
  EXPECT_TRUE(eventually([&] { return s->counters().ws_closed.load() == 1 && s->counters().ws_clients.load() == 0; }));
}

TEST(HttpServer, BadHandshakesAndUnmaskedFramesAreRefused) {
  TestHandler h;
  auto s = start(h);
  {
    Client c(s->port());
    c.send("GET /ws HTTP/1.1\r\nHost: a\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n\r\n");  // no key
    ASSERT_TRUE(c.read_to_close());
    EXPECT_EQ(c.buf.find("HTTP/1.1 400"), 0U) << c.buf;
  }
  {
    Client c(s->port());
    std::string req = ws_upgrade();
    req.replace(req.find("Version: 13"), 11, "Version: 8");
    c.send(req);
    ASSERT_TRUE(c.read_to_close());
    EXPECT_EQ(c.buf.find("HTTP/1.1 426"), 0U) << c.buf;
    EXPECT_NE(c.buf.find("Sec-WebSocket-Version: 13"), std::string::npos);
  }
  EXPECT_EQ(s->counters().bad_requests.load(), 2U);
  Client c(s->port());
  c.send(ws_upgrade());
  ASSERT_TRUE(c.read_contains("hello"));
  c.send(base_station::test::client_frame(1, "x", false));
  ASSERT_TRUE(c.read_to_close());
  const auto f = base_station::test::ws_frames(c.buf);
  ASSERT_FALSE(f.empty());
  EXPECT_EQ(f.back().opcode, 8);
  EXPECT_EQ(f.back().payload, std::string("\x03\xea", 2)) << "close 1002 protocol error";
  EXPECT_EQ(s->counters().ws_bad_frames.load(), 1U);
}

TEST(HttpServer, AClientThatNeverCompletesARequestIsClosed) {
  TestHandler h;
  HttpServerParams p;
  p.bind = "127.0.0.1";
  p.port = 0;
  p.request_timeout_s = 0.3;
  p.tick_ms = 10;
  auto s = HttpServer::start(p, h).value();
  for (int i = 0; i < 200 && s->port() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  Client c(s->port());
  c.send(std::string("GET / HTTP/1.1\r\nHost:"));
  ASSERT_TRUE(c.read_to_close(2.0));
  EXPECT_EQ(s->counters().timed_out.load(), 1U);
}

TEST(HttpServer, ClientsBeyondTheLimitGet503) {
  TestHandler h;
  auto s = start(h, 2);
  Client a(s->port()), b(s->port());
  a.send(ws_upgrade());
  b.send(ws_upgrade());
  ASSERT_TRUE(a.read_contains("hello"));
  ASSERT_TRUE(b.read_contains("hello"));
  Client c(s->port());
  ASSERT_TRUE(c.read_to_close());
  EXPECT_EQ(c.buf.find("HTTP/1.1 503"), 0U) << c.buf;
  EXPECT_TRUE(eventually([&] { return s->counters().rejected_full.load() == 1; }));
}

TEST(HttpServer, ASlowClientIsDroppedWhileAFastOneKeepsUp) {
  TestHandler h;
  auto s = start(h, 8, 256u << 10, 0.5);
  Client slow(s->port(), 4096);  // small receive buffer, never read after the handshake
  slow.send(ws_upgrade());
  ASSERT_TRUE(slow.read_contains("hello"));
  Client fast(s->port());
  fast.send(ws_upgrade());
  ASSERT_TRUE(fast.read_contains("hello"));
  h.frame_bytes = 16384;  // 16 KiB every 10 ms = 1.6 MB/s per client
  std::size_t got = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(4000) && s->counters().slow_dropped.load() == 0) {
    fast.buf.clear();
    fast.read_until([](const std::string& b) { return b.size() > 100000; }, 0.05);
    got += fast.buf.size();
  }
  EXPECT_EQ(s->counters().slow_dropped.load(), 1U) << "the slow client is dropped";
  std::size_t after = 0;  // and the fast one goes on receiving
  for (int k = 0; k < 6; ++k) {
    fast.buf.clear();
    fast.read_until([](const std::string& b) { return b.size() > 100000; }, 0.05);
    after += fast.buf.size();
  }
  h.frame_bytes = 0;
  EXPECT_EQ(s->counters().ws_clients.load(), 1U) << "the fast one stays";
  EXPECT_GT(got, 256U << 10) << "the fast client received more than the slow one's whole budget meanwhile";
  EXPECT_GT(after, 16384U) << "the fast client kept receiving after the drop";
  EXPECT_FALSE(fast.closed);
}

TEST(HttpServer, AnInvalidBindAddressIsAnErrorAndABusyPortIsRetried) {
  TestHandler h;
  HttpServerParams p;
  p.bind = "not-an-ip";
  auto bad = HttpServer::start(p, h);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("not-an-ip"), std::string::npos);
  auto first = start(h);
  HttpServerParams q;
  q.bind = "127.0.0.1";
  q.port = first->port();
  TestHandler h2;
  auto second = HttpServer::start(q, h2);
  ASSERT_TRUE(second.ok()) << "a busy port does not stop the owner";
  EXPECT_EQ(second.value()->port(), 0);
  EXPECT_GE(second.value()->counters().bind_failures.load(), 1U);
  const int port = first->port();
  first.reset();  // the port frees: the retry takes it
  EXPECT_TRUE(eventually([&] { return second.value()->port() == port; }, 3.0));
}

}  // namespace
}  // namespace ag::net::http

namespace ag::net::http {
namespace {

// Accepts the subprotocol "chat.v2" (RFC 6455 §1.9) and greets each client with the one it was opened with.
class ProtocolHandler final : public HttpServer::Handler {
 public:
  HttpResponse get(const HttpRequest&) override { return {200, "text/html", "<html>page</html>", {}}; }
  std::string ws_subprotocol(const HttpRequest& r) override { return r.header_has_token("sec-websocket-protocol", "chat.v2") ? "chat.v2" : ""; }
  void ws_open(HttpServer& s, HttpServer::ClientId id) override { s.ws_send_text(id, "proto=" + std::string(s.ws_protocol(id)) + ";"); }
  void tick(HttpServer&) override {}
};

std::string upgrade_with(const std::string& path, const std::string& protocols, const std::string& key = "dGhlIHNhbXBsZSBub25jZQ==") {
  return "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: " + key +
         "\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: " + protocols + "\r\n\r\n";
}

TEST(HttpServer, ASubprotocolIsNegotiatedAtAnyPathTheHandlerAccepts) {
  ProtocolHandler h;
  HttpServerParams p;
  p.bind = "127.0.0.1";
  p.port = 0;
  auto started = HttpServer::start(p, h);
  ASSERT_TRUE(started.ok());
  auto s = std::move(started).value();
  for (int i = 0; i < 200 && s->port() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  // Offered among others at a path that is not ws_path: accepted, named in the 101, known per client.
  Client a(s->port());
  a.send(upgrade_with("/live", "x.v1, chat.v2"));
  ASSERT_TRUE(a.read_contains("proto=chat.v2;")) << a.buf;
  EXPECT_EQ(a.buf.find("HTTP/1.1 101 Switching Protocols"), 0U);
  EXPECT_NE(a.buf.find("\r\nSec-WebSocket-Protocol: chat.v2\r\n"), std::string::npos) << a.buf;
  // ws_path without one: upgraded with none, and no Sec-WebSocket-Protocol in the answer.
  Client b(s->port());
  b.send(base_station::test::ws_upgrade());
  ASSERT_TRUE(b.read_contains("proto=;")) << b.buf;
  EXPECT_EQ(b.buf.find("Sec-WebSocket-Protocol"), std::string::npos);
  // Only a subprotocol the handler does not speak, elsewhere: no upgrade, the handler's GET answers.
  Client c(s->port());
  c.send(upgrade_with("/live", "x.v1"));
  ASSERT_TRUE(c.read_contains("<html>page</html>")) << c.buf;
  EXPECT_EQ(c.buf.find("HTTP/1.1 200 OK"), 0U);
  // The subprotocol with a bad handshake: 400, counted.
  const auto bad0 = s->counters().bad_requests.load();
  Client d(s->port());
  d.send(upgrade_with("/live", "chat.v2", "short"));
  ASSERT_TRUE(d.read_contains("400 Bad Request")) << d.buf;
  EXPECT_EQ(s->counters().bad_requests.load(), bad0 + 1);
  EXPECT_EQ(s->counters().ws_opened.load(), 2U);
}

}  // namespace
}  // namespace ag::net::http
