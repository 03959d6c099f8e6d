// SHA-1 (FIPS 180 test vectors), base64 (RFC 4648 §10), the WebSocket accept key (RFC 6455 §1.3's
// example), frame headers and the HTTP request parser.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "airground/drivers/net/http/http_request.hpp"
#include "airground/drivers/net/http/sha1.hpp"
#include "airground/drivers/net/http/websocket.hpp"

namespace ag::net::http {
namespace {

std::string hex(const std::array<std::uint8_t, 20>& h) {
  std::string s;
  char b[3];
  for (auto v : h) {
    std::snprintf(b, sizeof b, "%02x", v);
    s += b;
  }
  return s;
}
std::string b64(const std::string& s) { return base64_encode({reinterpret_cast<const std::uint8_t*>(s.data()), s.size()}); }

TEST(Sha1, FipsVectorsIncludingTheTwoBlockPaddingCase) {
  EXPECT_EQ(hex(sha1("abc")), "a9993e364706816aba3e25717850c26c9cd0d89d");
  EXPECT_EQ(hex(sha1("")), "da39a3ee5e6b4b0d3255bfef95601890afd80709");
  EXPECT_EQ(hex(sha1("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq")), "84983e441c3bd26ebaae4aa1f95129e5e54670f1");
  EXPECT_EQ(hex(sha1(std::string(1000000, 'a'))), "34aa973cd4c4daa4f61eeb2bdbad27316534016f");
  EXPECT_EQ(hex(sha1("The quick brown fox jumps over the lazy dog")), "2fd4e1c67a2d28fced849ee1bb76e7391b93eb12");
}

TEST(Base64, Rfc4648Vectors) {
  EXPECT_EQ(b64(""), "");
  EXPECT_EQ(b64("f"), "Zg==");
  EXPECT_EQ(b64("fo"), "Zm8=");
  EXPECT_EQ(b64("foo"), "Zm9v");
  EXPECT_EQ(b64("foob"), "Zm9vYg==");
  EXPECT_EQ(b64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(b64("foobar"), "Zm9vYmFy");
}

TEST(WebSocket, AcceptKeyOfRfc6455Example) {
  EXPECT_EQ(websocket_accept("dGhlIHNhbXBsZSBub25jZQ=="), "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");
}

TEST(WebSocket, FrameHeadersUseTheShortestLengthForm) {
  std::uint8_t h[kWsMaxHeader];
  ASSERT_EQ(ws_frame_header(h, WsOpcode::kText, 5), 2U);
  EXPECT_EQ(h[0], 0x81);
  EXPECT_EQ(h[1], 5);
  ASSERT_EQ(ws_frame_header(h, WsOpcode::kBinary, 125), 2U);
  ASSERT_EQ(ws_frame_header(h, WsOpcode::kBinary, 126), 4U);
  EXPECT_EQ(h[0], 0x82);
  EXPECT_EQ(h[1], 126);
  EXPECT_EQ(h[2], 0);
  EXPECT_EQ(h[3], 126);
  ASSERT_EQ(ws_frame_header(h, WsOpcode::kBinary, 65536), 10U);
  EXPECT_EQ(h[1], 127);
  EXPECT_EQ(h[7], 1);  // 0x00 00 00 00 00 01 00 00
  EXPECT_EQ(h[8], 0);
}

TEST(WebSocket, ParsesRfc6455MaskedHelloAndRejectsProtocolErrors) {
  // RFC 6455 §5.7: a single-frame masked text message "Hello".
  std::vector<std::uint8_t> f = {0x81, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58};
  WsFrame fr;
  const char* why = "";
  ASSERT_EQ(ws_parse_header(f, 1024, true, fr, &why), WsParse::kOk) << why;
  EXPECT_TRUE(fr.fin);
  EXPECT_EQ(fr.opcode, WsOpcode::kText);
  EXPECT_EQ(fr.header_len, 6U);
  ASSERT_EQ(fr.payload_len, 5U);
  std::span<std::uint8_t> p(f.data() + 6, 5);
  ws_apply_mask(p, fr.mask);
  EXPECT_EQ(std::string(f.begin() + 6, f.end()), "Hello");
  // Partial headers wait for more.
  EXPECT_EQ(ws_parse_header(std::span<const std::uint8_t>(f.data(), 1), 1024, true, fr, &why), WsParse::kNeedMore);
  EXPECT_EQ(ws_parse_header(std::span<const std::uint8_t>(f.data(), 4), 1024, true, fr, &why), WsParse::kNeedMore);
  // Unmasked client frame (RFC 6455 §5.1: the server must close).
  const std::vector<std::uint8_t> unmasked = {0x81, 0x05, 'H', 'e', 'l', 'l', 'o'};
  EXPECT_EQ(ws_parse_header(unmasked, 1024, true, fr, &why), WsParse::kError);
  EXPECT_STREQ(why, "client frame not masked");
  EXPECT_EQ(ws_parse_header(unmasked, 1024, false, fr, &why), WsParse::kOk);
  // Reserved bits, unknown opcode, long or fragmented control frames, too large frames.
  EXPECT_EQ(ws_parse_header(std::vector<std::uint8_t>{0xC1, 0x80, 0, 0, 0, 0}, 1024, true, fr, &why), WsParse::kError);
  EXPECT_EQ(ws_parse_header(std::vector<std::uint8_t>{0x83, 0x80, 0, 0, 0, 0}, 1024, true, fr, &why), WsParse::kError);
  EXPECT_EQ(ws_parse_header(std::vector<std::uint8_t>{0x89, 0xFE, 0, 200, 0, 0, 0, 0}, 1024, true, fr, &why), WsParse::kError);
  EXPECT_EQ(ws_parse_header(std::vector<std::uint8_t>{0x09, 0x80, 0, 0, 0, 0}, 1024, true, fr, &why), WsParse::kError);
  EXPECT_EQ(ws_parse_header(std::vector<std::uint8_t>{0x82, 0xFE, 0x10, 0x00, 0, 0, 0, 0}, 1024, true, fr, &why), WsParse::kError);
  EXPECT_STREQ(why, "frame larger than the server accepts");
  // 16-bit length form.
  EXPECT_EQ(ws_parse_header(std::vector<std::uint8_t>{0x82, 0xFE, 0x01, 0x00, 1, 2, 3, 4}, 1024, true, fr, &why), WsParse::kOk);
  EXPECT_EQ(fr.payload_len, 256U);
  EXPECT_EQ(fr.header_len, 8U);
}

TEST(HttpRequest, ParsesAGetWithHeadersAndQuery) {
  const std::string r = "GET /api/state?x=1 HTTP/1.1\r\nHost: base:8080\r\nConnection: keep-alive, Upgrade\r\nX-Empty:\r\n\r\nGET / HTTP/1.1\r\n";
  HttpRequest req;
  std::size_t used = 0;
  std::string why;
  ASSERT_EQ(parse_http_request(r, 8192, req, used, why), HttpParse::kOk) << why;
  EXPECT_EQ(req.method, "GET");
  EXPECT_EQ(req.path, "/api/state");
  EXPECT_EQ(req.query, "x=1");
  EXPECT_EQ(req.header("host"), "base:8080");
  EXPECT_TRUE(req.header_has_token("connection", "upgrade"));
  EXPECT_TRUE(req.keep_alive());
  EXPECT_EQ(used, r.find("GET /", 5));
}

TEST(HttpRequest, WaitsForTheBlankLineAndRefusesMalformedHeads) {
  HttpRequest req;
  std::size_t used = 0;
  std::string why;
  EXPECT_EQ(parse_http_request("GET / HTTP/1.1\r\nHost: a\r\n", 8192, req, used, why), HttpParse::kNeedMore);
  const char* bad[] = {
      "GARBAGE\r\n\r\n",                                   // no target, no version
      "GET / HTTP/2.0\r\nHost: a\r\n\r\n",                 // unsupported version
      "GET relative HTTP/1.1\r\nHost: a\r\n\r\n",          // not an absolute path
      "GET / HTTP/1.1\r\n\r\n",                            // 1.1 without Host
      "GET / HTTP/1.1\r\nHost a\r\n\r\n",                  // header without ':'
      "GET / HTTP/1.1\r\nHo st: a\r\n\r\n",                // space in a header name
      "POST / HTTP/1.1\r\nHost: a\r\nContent-Length: 5\r\n\r\nhello",  // a body
      "GET /a\x01 HTTP/1.1\r\nHost: a\r\n\r\n",            // control byte in the target
      "GET / HTTP/1.1\nHost: a\n\n",                       // bare LF
  };
  for (const char* b : bad) EXPECT_EQ(parse_http_request(b, 8192, req, used, why), HttpParse::kBad) << b;
  EXPECT_EQ(parse_http_request(std::string(9000, 'A'), 8192, req, used, why), HttpParse::kBad) << "over-long head";
  HttpRequest old;
  ASSERT_EQ(parse_http_request("GET / HTTP/1.0\r\n\r\n", 8192, old, used, why), HttpParse::kOk);
  EXPECT_FALSE(old.keep_alive()) << "HTTP/1.0 closes unless asked";
}

}  // namespace
}  // namespace ag::net::http
