// End to end, HTTPS and WSS (issue 21 part 1; net/tls.h, docs/operations.md "TLS"): a real node
// with a self-signed certificate from scripts/tls-cert.sh and real clients. Over WSS a client
// without an access token, or with an expired one, is refused with its reason; a valid token
// gets frames; a foreign Origin is refused; the MJPEG stream is served over HTTPS too. The port
// speaks TLS only: plain HTTP and plain WebSocket clients get nothing (and are logged as failed
// handshakes) while the node goes on serving; TLS 1.1 and TLS 1.2 without an AEAD cipher are
// refused. A client that verifies takes the certificate for the names it holds and refuses it
// for another name or with another CA. A missing or mismatched certificate or key stops the
// start with an error naming the file.
//
// Issue 21's rest: a renewed certificate is reloaded without a restart (new connections present
// it, an open session goes on; a missing, mismatched, invalid or expired pair is refused and
// logged, and the node serves on with the one it had); HSTS (`hsts-max-age`) on every HTTPS
// response and never over plain HTTP; the plain HTTP redirect port (`http-redirect-port`): a 308
// to the same path over https at the request's host (a hostile Host header falls back to the
// node's address), 405 for other methods, no WebSocket and no content.
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include <cstdio>
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

// The SHA-256 fingerprint of a PEM certificate file as `openssl x509 -fingerprint -sha256` prints
// it (what an operator compares with the node's log), "AB:CD:...".
std::string cli_fingerprint(const std::string& cert) {
  std::FILE* p = ::popen(("openssl x509 -noout -fingerprint -sha256 -in " + cert).c_str(), "r");
  REQUIRE(p);
  std::string out;
  char buf[256];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  REQUIRE(::pclose(p) == 0);
  const auto eq = out.find('=');
  REQUIRE(eq != std::string::npos);
  out = out.substr(eq + 1);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

// The files a node reads its certificate from, replaced the way a renewal does (a new file
// renamed over the old one).
struct LiveCert {
  std::string dir;
  LiveCert() {
    char tmpl[] = "/tmp/tessera-tls-live-XXXXXX";
    REQUIRE(mkdtemp(tmpl));
    dir = tmpl;
  }
  ~LiveCert() { std::filesystem::remove_all(dir); }
  std::string cert() const { return dir + "/live.crt"; }
  std::string key() const { return dir + "/live.key"; }
  void put(const std::string& file, const std::string& content) const {
    const std::string tmp = file + ".new";
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      out << content;
      REQUIRE(out);
    }
    std::filesystem::rename(tmp, file);
  }
  static std::string read(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    REQUIRE(in);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  void install(const std::string& cert_file, const std::string& key_file) const {
    put(cert(), read(cert_file));
    put(key(), read(key_file));
  }
};

// A self-signed certificate for localhost that expired yesterday, and its key (OpenSSL's
// command line cannot date one in the past).
void write_expired(const std::string& cert, const std::string& key) {
  EVP_PKEY* pkey = EVP_EC_gen("P-256");
  REQUIRE(pkey);
  X509* x = X509_new();
  X509_set_version(x, 2);
  ASN1_INTEGER_set(X509_get_serialNumber(x), 7);
  X509_gmtime_adj(X509_getm_notBefore(x), -2 * 86400);
  X509_gmtime_adj(X509_getm_notAfter(x), -86400);
  X509_NAME* name = X509_get_subject_name(x);
  X509_NAME_add_entry_by_txt(name, "CN", MBSTRING_ASC, reinterpret_cast<const unsigned char*>("localhost"), -1, -1, 0);
  X509_set_issuer_name(x, name);
  X509_set_pubkey(x, pkey);
  REQUIRE(X509_sign(x, pkey, EVP_sha256()) > 0);
  std::FILE* f = std::fopen(cert.c_str(), "w");
  REQUIRE(f);
  PEM_write_X509(f, x);
  std::fclose(f);
  f = std::fopen(key.c_str(), "w");
  REQUIRE(f);
  PEM_write_PrivateKey(f, pkey, nullptr, nullptr, 0, nullptr, nullptr);
  std::fclose(f);
  X509_free(x);
  EVP_PKEY_free(pkey);
}

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

int tcp_connect(const char* address, uint16_t port) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  REQUIRE(fd >= 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  ::inet_pton(AF_INET, address, &a.sin_addr);
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// One exchange over a raw TLS connection that takes any certificate: what the node presented
// (its SHA-256), and what it answered to `request` until it closed, or until `until` appeared
// (a response that stays open: a 101, an MJPEG stream).
struct TlsExchange {
  bool handshake = false;
  std::string sha256, response;
};
TlsExchange tls_exchange(uint16_t port, const std::string& request = "", const std::string& until = "") {
  TlsExchange x;
  tls::CtxPtr ctx(SSL_CTX_new(TLS_client_method()));
  REQUIRE(ctx);
  SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_NONE, nullptr);
  const int fd = tcp_connect("127.0.0.1", port);
  REQUIRE(fd >= 0);
  SSL* ssl = SSL_new(ctx.get());
  SSL_set_fd(ssl, fd);
  x.handshake = SSL_connect(ssl) == 1;
  if (x.handshake) {
    x.sha256 = tls::peer_certificate_info(ssl).sha256;
    if (!request.empty() && SSL_write(ssl, request.data(), int(request.size())) == int(request.size())) {
      char buf[4096];
      int n;
      while ((until.empty() || x.response.find(until) == std::string::npos) && (n = SSL_read(ssl, buf, sizeof buf)) > 0)
        x.response.append(buf, size_t(n));
    }
  }
  SSL_free(ssl);
  ::close(fd);
  return x;
}
std::string presented(uint16_t port) { return tls_exchange(port).sha256; }

// A plain HTTP exchange, written as given (a hostile client's bytes included): the response
// until the node closes; "" when nothing could connect.
std::string plain_exchange(uint16_t port, const std::string& request, const char* address = "127.0.0.1") {
  const int fd = tcp_connect(address, port);
  if (fd < 0) return "";
  std::string response;
  if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) == ssize_t(request.size())) {
    char buf[4096];
    ssize_t n;
    while ((n = ::recv(fd, buf, sizeof buf, 0)) > 0) response.append(buf, size_t(n));
  }
  ::close(fd);
  return response;
}
int status_of(const std::string& response) {
  return response.compare(0, 5, "HTTP/") == 0 ? std::atoi(response.c_str() + response.find(' ') + 1) : 0;
}
// The value of header `name` in a response head (exact case, as the node writes it); nullopt if absent.
std::optional<std::string> header_of(const std::string& response, const std::string& name) {
  const std::string head = response.substr(0, response.find("\r\n\r\n") + 2);
  const auto at = head.find("\r\n" + name + ": ");
  if (at == std::string::npos) return std::nullopt;
  const auto from = at + name.size() + 4;
  return head.substr(from, head.find("\r\n", from) - from);
}
std::string body_of(const std::string& response) {
  const auto at = response.find("\r\n\r\n");
  return at == std::string::npos ? "" : response.substr(at + 4);
}

// The node's log lines: what an operator reads.
std::string log_text(TestNode& node) {
  std::string text;
  for (Ev kind : {Ev::tls_certificate, Ev::rejected, Ev::opened, Ev::closed})
    for (const Event& e : node.events(kind)) text += to_json_line(e) + "\n";
  return text;
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
    settings->log = [](const Event&) {};
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

TEST_CASE("A reloaded certificate is presented to new connections while an open session goes on; a missing, "
          "mismatched, invalid or expired pair is refused and logged, and the node serves on with the one it had",
          "[e2e]") {
  CertDir a, b("renewed.example");
  LiveCert live;
  live.install(a.cert(), a.key());
  auto node = std::make_unique<TestNode>(8, [&](NodeSettings&, ServerOptions& o) {
    o.tls_cert = live.cert();
    o.tls_key = live.key();
  });
  const uint16_t port = node->port();
  const std::string fa = cli_fingerprint(a.cert()), fb = cli_fingerprint(b.cert());
  REQUIRE(fa != fb);
  CHECK(presented(port) == fa);
  auto loaded = node->events(Ev::tls_certificate);
  REQUIRE(loaded.size() == 1);
  CHECK(loaded[0].value == Json("loaded"));
  CHECK(has(loaded[0], "sha256", fa));
  CHECK(has(loaded[0], "subject", "CN=localhost"));
  CHECK(has(loaded[0], "cert", live.cert()));

  // A session that trusts only the first certificate, open across every reload below.
  ProtoClient open;
  open.ws.use_tls(a.cert());
  std::string error;
  REQUIRE(open.ws.connect("127.0.0.1", port, "/ws", &error));
  REQUIRE(gets_frame(open, 1));
  uint32_t frame = 1;
  auto open_goes_on = [&] {
    ++frame;
    auto f = open.render(pavilion_loop().camera(frame % 4), frame);
    return f && f->frame == frame && !f->payload.empty();
  };

  // The renewal: new files, then the reload. The next connection presents the new certificate
  // (also the one websocketpp made before the reload to accept it with).
  live.install(b.cert(), b.key());
  REQUIRE(node->server->reload_tls(&error));
  CHECK(presented(port) == fb);
  CHECK(presented(port) == fb);
  CHECK(open_goes_on());
  auto events = node->events(Ev::tls_certificate);
  REQUIRE(events.size() == 2);
  CHECK(events[1].value == Json("reloaded"));
  CHECK(has(events[1], "sha256", fb));
  CHECK(has(events[1], "subject", "CN=renewed.example"));
  CHECK(events[1].field("not_after"));
  // Clients that verify: one that trusts the new certificate connects, one that trusts only the old one does not.
  ProtoClient renewed;
  renewed.ws.use_tls(b.cert());
  REQUIRE(renewed.ws.connect("127.0.0.1", port, "/ws", &error));
  CHECK(gets_frame(renewed));
  auto page = http::get("127.0.0.1", port, "/", 5000, {true, b.cert()});
  REQUIRE(page);
  CHECK(page->status == 200);
  CHECK_FALSE(http::get("127.0.0.1", port, "/", 5000, {true, a.cert()}));

  // Broken renewals: each refused with its reason, the node presents the renewed certificate still.
  CertDir other;
  char tmpl[] = "/tmp/tessera-tls-expired-XXXXXX";
  REQUIRE(mkdtemp(tmpl));
  const std::string expired_dir = tmpl;
  write_expired(expired_dir + "/node.crt", expired_dir + "/node.key");
  struct Broken {
    std::string what, why;
    std::function<void()> make;
  };
  const std::vector<Broken> broken{
      {"a key of another certificate", "does not belong to the certificate",
       [&] { live.install(b.cert(), other.key()); }},
      {"no key file", "tls-key " + live.key() + ": cannot load a PEM private key",
       [&] {
         live.install(b.cert(), b.key());
         std::filesystem::remove(live.key());
       }},
      {"a certificate that is no PEM", "tls-cert " + live.cert() + ": cannot load a PEM certificate",
       [&] {
         live.put(live.cert(), "this is no certificate\n");
         live.put(live.key(), LiveCert::read(b.key()));
       }},
      {"the key as the certificate", "tls-cert " + live.cert() + ": cannot load a PEM certificate",
       [&] { live.install(b.key(), b.key()); }},
      {"an expired certificate", "the certificate expired at",
       [&] { live.install(expired_dir + "/node.crt", expired_dir + "/node.key"); }},
  };
  size_t failures = 0;
  for (const Broken& x : broken) {
    INFO(x.what);
    x.make();
    std::string why;
    CHECK_FALSE(node->server->reload_tls(&why));
    CHECK(why.find(x.why) != std::string::npos);
    ++failures;
    auto failed = node->events(Ev::tls_certificate);
    REQUIRE(failed.size() == 2 + failures);
    CHECK(failed.back().value == Json("reload_failed"));
    CHECK(has(failed.back(), "error", x.why));
    CHECK(has(failed.back(), "serving_sha256", fb));
    CHECK(presented(port) == fb);
    CHECK(open_goes_on());
  }
  std::filesystem::remove_all(expired_dir);
  CHECK(http::get("127.0.0.1", port, "/", 5000, {true, b.cert()}));
  CHECK(renewed.render(pavilion_loop().camera(1), 2));

  // From an ECDSA to an RSA certificate: new connections present the RSA one only (no ECDSA
  // certificate is left behind for OpenSSL to prefer).
  const std::string rsa_cert = live.dir + "/rsa.crt", rsa_key = live.dir + "/rsa.key";
  REQUIRE(std::system(("openssl req -x509 -newkey rsa:2048 -nodes -days 30 -subj /CN=localhost -addext "
                       "subjectAltName=IP:127.0.0.1 -keyout " + rsa_key + " -out " + rsa_cert + " 2>/dev/null")
                          .c_str()) == 0);
  live.install(rsa_cert, rsa_key);
  REQUIRE(node->server->reload_tls(&error));
  const std::string frsa = cli_fingerprint(rsa_cert);
  CHECK(presented(port) == frsa);
  CHECK(handshake_with(port, [](SSL_CTX* c) {  // a client that would rather have ECDSA
    SSL_CTX_set1_sigalgs_list(c, "ECDSA+SHA256:RSA-PSS+SHA256:RSA+SHA256");
  }));
  CHECK(tls_exchange(port).sha256 == frsa);
  auto rsa_page = http::get("127.0.0.1", port, "/", 5000, {true, rsa_cert});
  REQUIRE(rsa_page);
  CHECK(rsa_page->status == 200);
  CHECK(open_goes_on());
  CHECK(node->server->sessions() == 2);
  CHECK(node->count(Ev::closed) == 0);

  // The log names files, subjects and fingerprints, never anything of a key.
  const std::string text = log_text(*node);
  INFO(text);
  CHECK(text.find("PRIVATE KEY") == std::string::npos);
  for (const std::string& key_file : {a.key(), b.key(), other.key(), rsa_key}) {
    std::string k = LiveCert::read(key_file);
    k = k.substr(k.find('\n') + 1, 40);  // the key's first base64 characters
    CHECK(text.find(k) == std::string::npos);
  }
}

TEST_CASE("A server without TLS refuses a certificate reload and logs why", "[e2e]") {
  TestNode node;
  std::string why;
  CHECK_FALSE(node.server->reload_tls(&why));
  CHECK(why.find("no TLS") != std::string::npos);
  CHECK(node.count(Ev::tls_certificate, [](const Event& e) { return e.value == Json("reload_failed"); }) == 1);
  CHECK(http::get("127.0.0.1", node.port(), "/"));
}

TEST_CASE("With hsts-max-age every HTTPS response and the WebSocket upgrade carry Strict-Transport-Security; "
          "without it, or over plain HTTP, none does",
          "[e2e]") {
  auto node = std::make_unique<TestNode>(8, [](NodeSettings&, ServerOptions& o) {
    o.tls_cert = certs().cert();
    o.tls_key = certs().key();
    o.hsts_max_age = 600;
  });
  const uint16_t port = node->port();
  const std::optional<std::string> hsts("max-age=600");
  auto request = [&](const std::string& method, const std::string& target, const std::string& headers = "") {
    return tls_exchange(port, method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + headers + "\r\n").response;
  };
  for (const auto& [method, target, status] : std::vector<std::tuple<std::string, std::string, int>>{
           {"GET", "/", 200}, {"HEAD", "/", 200}, {"GET", "/no/such/page", 404}, {"POST", "/", 405},
           {"GET", "/ws", 426}, {"GET", "/mjpeg/nosuchsession", 404}}) {
    const std::string r = request(method, target);
    INFO(method << " " << target << "\n" << r.substr(0, 400));
    CHECK(status_of(r) == status);
    CHECK(header_of(r, "Strict-Transport-Security") == hsts);
  }
  // The WebSocket upgrade (101) and a refused one (a foreign origin: 403).
  const std::string upgrade =
      "Connection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Key: "
      "dGhlIHNhbXBsZSBub25jZQ==\r\n";
  const std::string accepted = tls_exchange(port, "GET /ws?session=hstsmjpeg1 HTTP/1.1\r\nHost: 127.0.0.1\r\n" + upgrade + "\r\n",
                                            "\r\n\r\n").response;
  INFO(accepted);
  CHECK(status_of(accepted) == 101);
  CHECK(header_of(accepted, "Strict-Transport-Security") == hsts);
  const std::string refused = request("GET", "/ws", upgrade + "Origin: https://evil.example\r\n");
  CHECK(status_of(refused) == 403);
  CHECK(header_of(refused, "Strict-Transport-Security") == hsts);
  // An MJPEG stream's head.
  ProtoClient c;
  c.ws.use_tls();
  std::string error;
  REQUIRE(c.ws.connect("127.0.0.1", port, "/ws?session=hstsmjpeg2", &error));
  REQUIRE(c.handshake(DisplayKind::mjpeg, 64, 48));
  const std::string stream = tls_exchange(port, "GET /mjpeg/hstsmjpeg2 HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", "\r\n\r\n").response;
  CHECK(status_of(stream) == 200);
  CHECK(header_of(stream, "Content-Type") == std::optional<std::string>("multipart/x-mixed-replace; boundary=tesseraframe"));
  CHECK(header_of(stream, "Strict-Transport-Security") == hsts);

  // Without the setting (the default) HTTPS responses carry none.
  auto off = tls_node(false);
  const std::string plain_tls = tls_exchange(off->port(), "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").response;
  CHECK(status_of(plain_tls) == 200);
  CHECK_FALSE(header_of(plain_tls, "Strict-Transport-Security"));
  // Over plain HTTP never, whatever the options say.
  TestNode plain(8, [](NodeSettings&, ServerOptions& o) { o.hsts_max_age = 600; });
  for (const char* target : {"/", "/no/such/page"}) {
    auto r = http::get("127.0.0.1", plain.port(), target);
    REQUIRE(r);
    CHECK_FALSE(r->header("Strict-Transport-Security"));
  }
}

TEST_CASE("The plain HTTP redirect port answers GET and HEAD with a 308 to the same path over https, never with "
          "content or a WebSocket, and takes only a well-formed Host",
          "[e2e]") {
  auto node = std::make_unique<TestNode>(8, [](NodeSettings&, ServerOptions& o) {
    o.tls_cert = certs().cert();
    o.tls_key = certs().key();
    o.hsts_max_age = 600;
    o.http_redirect_port = 0;  // any free port
  });
  const uint16_t port = node->port(), rport = node->server->redirect_port();
  REQUIRE(rport != 0);
  REQUIRE(rport != port);
  const std::string tls_port = std::to_string(port);
  auto get = [&](const std::string& target, const std::string& host_line, const std::string& method = "GET",
                 const std::string& version = "HTTP/1.1") {
    return plain_exchange(rport, method + " " + target + " " + version + "\r\n" + host_line + "\r\n");
  };
  struct Case {
    std::string target, host_line, location;
  };
  for (const Case& c : std::vector<Case>{
           {"/demo/index.html?x=1&y=%20z", "Host: localhost:" + std::to_string(rport),
            "https://localhost:" + tls_port + "/demo/index.html?x=1&y=%20z"},
           {"/", "Host: Node.Example", "https://node.example:" + tls_port + "/"},
           {"/a", "Host: [::1]:" + std::to_string(rport), "https://[::1]:" + tls_port + "/a"},
           {"/src/xml3d.js", "Host: 10.0.0.2", "https://10.0.0.2:" + tls_port + "/src/xml3d.js"},
           {"/a\"b<c>'", "Host: localhost", "https://localhost:" + tls_port + "/a%22b%3Cc%3E'"},
           // A hostile Host: the node's own address.
           {"/x?y", "Host: \"evil\"", "https://127.0.0.1:" + tls_port + "/x?y"},
           {"/", "Host: evil.example/@x", "https://127.0.0.1:" + tls_port + "/"},
           {"/", "Host: <script>alert(1)</script>", "https://127.0.0.1:" + tls_port + "/"},
           {"/", "Host: a b.example", "https://127.0.0.1:" + tls_port + "/"},
           {"/", "Host: evil.example\nX-Injected: 1", "https://127.0.0.1:" + tls_port + "/"},
       }) {
    const std::string r = get(c.target, c.host_line + "\r\n");
    INFO(c.target << " with " << c.host_line << "\n" << r);
    const int status = status_of(r);
    CHECK(status == 308);
    CHECK(r.rfind("HTTP/1.1 308 Permanent Redirect\r\n", 0) == 0);
    CHECK(header_of(r, "Location") == std::optional<std::string>(c.location));
    CHECK(r.find("\nX-Injected") == std::string::npos);
    CHECK(r.find("evil") == std::string::npos);
    CHECK_FALSE(header_of(r, "Strict-Transport-Security"));  // plain HTTP: never
    CHECK(body_of(r).find("<html") == std::string::npos);     // no content
    CHECK(body_of(r).find("XML3D") == std::string::npos);
  }
  // No Host, or one whose port is no number: websocketpp's parser refuses the request itself
  // (400), with no Location.
  for (const std::string& request : {std::string("GET /x HTTP/1.0\r\n\r\n"), std::string("GET /x HTTP/1.1\r\n\r\n"),
                                     std::string("GET / HTTP/1.1\r\nHost: evil.example\nLocation: https://evil.example/\r\n\r\n")}) {
    const std::string r = plain_exchange(rport, request);
    INFO(request << "\n" << r);
    CHECK(status_of(r) == 400);
    CHECK(r.find("Location") == std::string::npos);
  }
  // HEAD: the same redirect without a body.
  const std::string head = get("/demo/", "Host: localhost\r\n", "HEAD");
  CHECK(status_of(head) == 308);
  CHECK(header_of(head, "Location") == std::optional<std::string>("https://localhost:" + tls_port + "/demo/"));
  CHECK(body_of(head).empty());
  // Other methods: 405, no Location.
  for (const char* method : {"POST", "PUT", "DELETE", "OPTIONS"}) {
    const std::string r = plain_exchange(rport, std::string(method) + " /ws HTTP/1.1\r\nHost: localhost\r\nContent-Length: 5\r\n\r\nhello");
    INFO(method << "\n" << r);
    CHECK(status_of(r) == 405);
    CHECK(header_of(r, "Allow") == std::optional<std::string>("GET, HEAD"));
    CHECK_FALSE(header_of(r, "Location"));
  }
  // A WebSocket upgrade: refused with 403 and where the secure one is; no session opens.
  ProtoClient ws;
  std::string error;
  CHECK_FALSE(ws.ws.connect("127.0.0.1", rport, "/ws", &error, 3000));
  CHECK(ws.ws.http_status() == 403);
  const std::string upgrade = get("/ws", "Host: localhost\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n"
                                          "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n");
  CHECK(status_of(upgrade) == 403);
  CHECK(body_of(upgrade).find("wss://localhost:" + tls_port + "/ws") != std::string::npos);
  CHECK(node->server->sessions() == 0);
  CHECK(node->count(Ev::opened) == 0);
  CHECK(wait_for([&] { return rejections(*node, "plain WebSocket on the redirect port") == 2; }, 3000));
  // Bound to the node's address only (127.0.0.1 here), like the TLS port.
  CHECK(plain_exchange(rport, "GET / HTTP/1.1\r\nHost: x\r\n\r\n", "127.0.0.2").empty());
  // The TLS port serves as before, and speaks no plain HTTP.
  auto page = http::get("127.0.0.1", port, "/", 5000, kAnyCert);
  REQUIRE(page);
  CHECK(page->status == 200);
  CHECK_FALSE(http::get("127.0.0.1", port, "/", 3000));
  ProtoClient secure;
  secure.ws.use_tls();
  REQUIRE(secure.ws.connect("127.0.0.1", port, "/ws", &error));
  CHECK(gets_frame(secure));

  // Without TLS there is nothing to redirect to: the start fails and says why.
  TestConfig cfg;
  caf::actor_system sys{cfg};
  ServerOptions o;
  o.port = 0;
  o.http_redirect_port = 0;
  auto quiet = std::make_shared<NodeSettings>();
  quiet->log = [](const Event&) {};
  Server plain(sys, quiet, o);
  try {
    plain.start();
    FAIL("a plain server started with a redirect port");
  } catch (const std::runtime_error& e) {
    CHECK(std::string(e.what()).find("tessera.http-redirect-port needs TLS") != std::string::npos);
  }
}
