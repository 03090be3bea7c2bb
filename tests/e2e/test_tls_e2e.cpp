// End to end, HTTPS and WSS (issue 21 part 1; net/tls.h, docs/operations.md "TLS"): a real node
// with a self-signed certificate from scripts/tls-cert.sh and real clients. Over WSS a client
// without an access token, or with an expired one, is refused with its reason; a valid token
// gets frames; a foreign Origin is refused; the MJPEG stream is served over HTTPS too. The port
// speaks TLS only: plain HTTP and plain WebSocket clients get nothing (and are logged as failed
// handshakes) while the node goes on serving; TLS 1.1 and TLS 1.2 without an AEAD cipher are
// refused. A client that verifies takes the certificate for the names it holds and refuses it
// for another name or with another CA. A missing or mismatched certificate or key stops the
// start with an error naming the file.
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <openssl/ssl.h>

#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <future>

#include "net/admission.h"
#include "net/http.h"
#include "net/tls.h"
#include "tests/e2e/node_fixture.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

const std::string kKey = "e2e-tls-key-0123456789abcdef-0123456789";

// A temporary folder with a self-signed certificate made by scripts/tls-cert.sh.
struct CertDir {
  std::string dir;
  explicit CertDir(const std::string& names = "") {
    char tmpl[] = "/tmp/tessera-tls-XXXXXX";
    REQUIRE(mkdtemp(tmpl));
    dir = tmpl;
    const std::string cmd = "scripts/tls-cert.sh " + dir + " " + names + " >/dev/null";
    REQUIRE(std::system(cmd.c_str()) == 0);
  }
  ~CertDir() { std::filesystem::remove_all(dir); }
  std::string cert() const { return dir + "/node.crt"; }
  std::string key() const { return dir + "/node.key"; }
};

const CertDir& certs() {
  static CertDir c;
  return c;
}

// A node on HTTPS/WSS that asks for signed tokens made with kKey.
std::unique_ptr<TestNode> tls_node(bool tokens = true) {
  return std::make_unique<TestNode>(8, [tokens](NodeSettings&, ServerOptions& o) {
    o.tls_cert = certs().cert();
    o.tls_key = certs().key();
    if (tokens) o.tokens.set_key(kKey);
  });
}

std::string valid_token() { return admission::make_token(kKey, int64_t(std::time(nullptr)) + 600, "tls-viewer"); }
std::string expired_token() { return admission::make_token(kKey, int64_t(std::time(nullptr)) - 3600, "tls-late"); }

using Headers = std::vector<std::pair<std::string, std::string>>;
Headers own_origin(uint16_t port) { return {{"Origin", "https://127.0.0.1:" + std::to_string(port)}}; }

bool gets_frame(ProtoClient& c, uint32_t frame = 1) {
  if (!c.handshake(DisplayKind::jpeg, 64, 48)) return false;
  auto f = c.render(pavilion_loop().camera(0), frame);
  return f && f->frame == frame && !f->payload.empty();
}

size_t rejections(TestNode& node, const std::string& reason) {
  return node.count(Ev::rejected, [&](const Event& e) { return e.value == Json(reason); });
}

const http::ClientTls kAnyCert{true, ""};

// A raw TLS handshake with the node, the client context set up by `configure`: whether it
// succeeds.
bool handshake_with(uint16_t port, const std::function<void(SSL_CTX*)>& configure) {
  tls::CtxPtr ctx(SSL_CTX_new(TLS_client_method()));
  REQUIRE(ctx);
  SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_NONE, nullptr);
  configure(ctx.get());
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  SSL* ssl = SSL_new(ctx.get());
  SSL_set_fd(ssl, fd);
  const bool ok = SSL_connect(ssl) == 1;
  SSL_free(ssl);
  ::close(fd);
  return ok;
}

}  // namespace

TEST_CASE("Over WSS a client without a token or with an expired one is refused with its reason, a valid token gets "
          "frames",
          "[e2e]") {
  auto node = tls_node();
  std::string error;
  // Not a browser: HTTP 401 and the reason, inside TLS.
  ProtoClient plain;
  plain.ws.use_tls();
  CHECK_FALSE(plain.ws.connect("127.0.0.1", node->port(), "/ws", &error));
  CHECK(plain.ws.http_status() == 401);
  // A browser on the node's own https origin: the upgrade closes at once with 4401 and the reason.
  for (const auto& [resource, reason] :
       std::vector<std::pair<std::string, std::string>>{{"/ws", "access token required"},
                                                        {"/ws?access_token=" + expired_token(), "access token expired"}}) {
    ProtoClient browser;
    browser.ws.use_tls();
    INFO(reason);
    REQUIRE(browser.ws.connect("127.0.0.1", node->port(), resource, &error, 5000, own_origin(node->port())));
    REQUIRE(wait_for([&] { return browser.ws.closed(); }, 3000));
    CHECK(browser.ws.close_code() == 4401);
    CHECK(browser.ws.close_reason() == reason);
  }
  CHECK(rejections(*node, "access token required") == 2);
  CHECK(rejections(*node, "access token expired") == 1);
  CHECK(node->count(Ev::opened) == 0);
  // A valid token gets frames, over TLS 1.2 or later.
  ProtoClient ok;
  ok.ws.use_tls();
  REQUIRE(ok.ws.connect("127.0.0.1", node->port(), "/ws?access_token=" + valid_token(), &error, 5000,
                        own_origin(node->port())));
  CHECK(gets_frame(ok));
  const std::string session = ok.ws.tls_session();
  INFO(session);
  CHECK((session.rfind("TLSv1.3 ", 0) == 0 || session.rfind("TLSv1.2 ", 0) == 0));
  // A foreign page's origin is refused over TLS as over plain HTTP.
  ProtoClient foreign;
  foreign.ws.use_tls();
  CHECK_FALSE(foreign.ws.connect("127.0.0.1", node->port(), "/ws?access_token=" + valid_token(), &error, 5000,
                                 {{"Origin", "https://evil.example"}}));
  CHECK(foreign.ws.http_status() == 403);
  CHECK(rejections(*node, "origin not allowed") == 1);
  CHECK(node->server->sessions() == 1);
}

TEST_CASE("The MJPEG stream and the pages are served over HTTPS, with the access token asked for", "[e2e]") {
  auto node = tls_node();
  const std::string token = valid_token();
  ProtoClient c;
  c.ws.use_tls();
  std::string error;
  REQUIRE(c.ws.connect("127.0.0.1", node->port(), "/ws?session=tlsmjpeg01&access_token=" + token, &error));
  REQUIRE(c.handshake(DisplayKind::mjpeg, 64, 48));
  REQUIRE(c.render(pavilion_loop().camera(0), 1));
  auto page = http::get("127.0.0.1", node->port(), "/src/xml3d.js", 5000, kAnyCert);
  REQUIRE(page);
  CHECK(page->status == 200);
  auto refused = http::get("127.0.0.1", node->port(), "/mjpeg/tlsmjpeg01", 5000, kAnyCert);
  REQUIRE(refused);
  CHECK(refused->status == 401);
  CHECK(refused->body == "access token required\n");
  std::vector<std::vector<uint8_t>> parts;
  auto reader = std::async(std::launch::async, [&] {
    return http::read_mjpeg("127.0.0.1", node->port(), "/mjpeg/tlsmjpeg01?access_token=" + token, 2, parts, &error,
                            20000, kAnyCert);
  });
  uint32_t n = 2;
  while (reader.wait_for(std::chrono::milliseconds(0)) != std::future_status::ready && n < 40)
    REQUIRE(c.render(pavilion_loop().camera(0), n++));
  INFO(error);
  REQUIRE(reader.get());
  REQUIRE(parts.size() == 2);
  CHECK(decode_jpeg(parts[1]).width == 64);
}

TEST_CASE("A TLS port speaks nothing else: plain HTTP and WebSocket, TLS 1.1 and non-AEAD ciphers are refused, and "
          "the node serves on",
          "[e2e]") {
  auto node = tls_node(false);
  // Plain HTTP: no answer at all (the bytes are not a TLS hello), the connection is closed.
  CHECK_FALSE(http::get("127.0.0.1", node->port(), "/", 3000));
  ProtoClient plain;
  std::string error;
  CHECK_FALSE(plain.ws.connect("127.0.0.1", node->port(), "/ws", &error, 3000));
  CHECK(plain.ws.http_status() == 0);  // never an HTTP response
  // Old protocol versions and TLS 1.2 suites without forward secrecy or AEAD.
  CHECK_FALSE(handshake_with(node->port(), [](SSL_CTX* c) {
    SSL_CTX_set_security_level(c, 0);
    SSL_CTX_set_min_proto_version(c, TLS1_VERSION);
    SSL_CTX_set_max_proto_version(c, TLS1_1_VERSION);
  }));
  CHECK_FALSE(handshake_with(node->port(), [](SSL_CTX* c) {
    SSL_CTX_set_max_proto_version(c, TLS1_2_VERSION);
    SSL_CTX_set_cipher_list(c, "AES128-SHA:AES256-GCM-SHA384:ECDHE-ECDSA-AES128-SHA");
  }));
  // What is allowed: TLS 1.2 with ECDHE and AES-GCM, and TLS 1.3.
  CHECK(handshake_with(node->port(), [](SSL_CTX* c) {
    SSL_CTX_set_max_proto_version(c, TLS1_2_VERSION);
    SSL_CTX_set_cipher_list(c, "ECDHE-ECDSA-AES128-GCM-SHA256");
  }));
  CHECK(handshake_with(node->port(), [](SSL_CTX* c) { SSL_CTX_set_min_proto_version(c, TLS1_3_VERSION); }));
  // Each refused handshake is one `rejected` event with the client's address.
  CHECK(wait_for([&] { return rejections(*node, "TLS handshake failed") >= 4; }, 3000));
  CHECK(node->count(Ev::rejected, [](const Event& e) { return has(e, "address", "127.0.0.1"); }) ==
        rejections(*node, "TLS handshake failed"));
  // And the node goes on serving.
  ProtoClient ok;
  ok.ws.use_tls();
  REQUIRE(ok.ws.connect("127.0.0.1", node->port(), "/ws", &error));
  CHECK(gets_frame(ok));
}

TEST_CASE("A verifying client takes the node's certificate for its names only, and only from its CA", "[e2e]") {
  auto node = tls_node(false);
  std::string error;
  for (const char* host : {"127.0.0.1", "localhost"}) {
    ProtoClient c;
    c.ws.use_tls(certs().cert());
    INFO(host);
    REQUIRE(c.ws.connect(host, node->port(), "/ws", &error));
    CHECK(gets_frame(c));
    auto r = http::get(host, node->port(), "/", 5000, {true, certs().cert()});
    REQUIRE(r);
    CHECK(r->status == 200);
  }
  // Another certificate as the trusted one: the node's does not chain to it.
  CertDir other;
  ProtoClient stranger;
  stranger.ws.use_tls(other.cert());
  CHECK_FALSE(stranger.ws.connect("127.0.0.1", node->port(), "/ws", &error));
  CHECK_FALSE(http::get("127.0.0.1", node->port(), "/", 5000, {true, other.cert()}));
  // An address the certificate does not hold: the same certificate on a node reached at
  // 127.0.0.2 (loopback, but the certificate names 127.0.0.1, ::1 and localhost only).
  auto elsewhere = std::make_unique<TestNode>(8, [&](NodeSettings&, ServerOptions& o) {
    o.host = "127.0.0.2";
    o.tls_cert = certs().cert();
    o.tls_key = certs().key();
  });
  CHECK_FALSE(http::get("127.0.0.2", elsewhere->port(), "/", 5000, {true, certs().cert()}));
  ProtoClient misnamed;
  misnamed.ws.use_tls(certs().cert());
  CHECK_FALSE(misnamed.ws.connect("127.0.0.2", elsewhere->port(), "/ws", &error));
  auto unchecked = http::get("127.0.0.2", elsewhere->port(), "/", 5000, kAnyCert);
  REQUIRE(unchecked);
  CHECK(unchecked->status == 200);
}

TEST_CASE("A node with a missing, unreadable or mismatched certificate or key does not start, naming the file",
          "[e2e]") {
  CertDir other;
  auto start_with = [](const std::string& cert, const std::string& key) {
    TestConfig cfg;
    caf::actor_system sys{cfg};
    auto settings = std::make_shared<NodeSettings>();
    ServerOptions o;
    o.port = 0;
    o.tls_cert = cert;
    o.tls_key = key;
    Server s(sys, settings, o);
    try {
      s.start();
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("started");
  };
  CHECK(start_with("/nonexistent/node.crt", certs().key()).find("tls-cert /nonexistent/node.crt") != std::string::npos);
  CHECK(start_with(certs().cert(), "/nonexistent/node.key").find("tls-key /nonexistent/node.key") != std::string::npos);
  CHECK(start_with(certs().key(), certs().key()).find("tls-cert " + certs().key()) != std::string::npos);
  CHECK(start_with(certs().cert(), other.key()).find("does not belong to the certificate") != std::string::npos);
  CHECK(start_with(certs().cert(), certs().key()) == "started");
}
