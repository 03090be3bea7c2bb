// End to end, session admission (issue 21 part 2; docs/operations.md, "Admission"): a real
// node and real WebSocket and HTTP clients. A client without an access token, with an expired
// one or with one signed by another key is refused with its reason: a non-browser by HTTP 401
// and a body, a browser (it sends Origin) by an upgrade closed at once with 4401 and the
// reason; a valid token gets frames; a foreign Origin gets HTTP 403 and no WebSocket, the
// node's own and loopback origins get in; the per-address limit refuses the N+1th connection
// while the others keep working; /mjpeg/ asks for the token too; and the node's log holds one
// `rejected` event per refusal and never a token or the key.
#include <catch2/catch.hpp>

#include <ctime>
#include <future>

#include "net/admission.h"
#include "net/http.h"
#include "tests/e2e/node_fixture.h"

using namespace tessera;
using namespace tessera::test;
using protocol::DisplayKind;

namespace {

const std::string kKey = "e2e-admission-key-0123456789abcdef-0123";

int64_t now() { return int64_t(std::time(nullptr)); }

std::string valid_token(const std::string& subject = "e2e-viewer") {
  return admission::make_token(kKey, now() + 600, subject);
}
std::string expired_token() { return admission::make_token(kKey, now() - 3600, "e2e-late"); }
std::string foreign_token() { return admission::make_token(kKey + "-other", now() + 600, "e2e-forger"); }

// A node that asks for signed tokens made with kKey.
std::unique_ptr<TestNode> node_with_key(size_t per_ip = 0) {
  return std::make_unique<TestNode>(8, [per_ip](NodeSettings&, ServerOptions& o) {
    o.tokens.set_key(kKey);
    o.max_connections_per_ip = per_ip;
  });
}

using Headers = std::vector<std::pair<std::string, std::string>>;

// What a browser on the node's own page sends.
Headers own_origin(uint16_t port) { return {{"Origin", "http://127.0.0.1:" + std::to_string(port)}}; }

// A WebSocket upgrade by hand, for the status, headers and body of a refusal (the node closes
// the connection after them).
http::Response refused_upgrade(uint16_t port, const std::string& resource, const std::string& extra = "") {
  auto r = http::request("127.0.0.1", port, "GET", resource,
                         "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                         "Sec-WebSocket-Version: 13\r\n" + extra,
                         3000);
  REQUIRE(r);
  return *r;
}

// Handshake, then one frame of the empty scene: the session works.
bool gets_frame(ProtoClient& c, uint32_t frame = 1) {
  if (!c.handshake(DisplayKind::jpeg, 64, 48)) return false;
  auto f = c.render(pavilion_loop().camera(0), frame);
  return f && f->frame == frame && !f->payload.empty();
}

// A browser-like client refused for its token: the upgrade completes, and the node closes the
// WebSocket at once with 4401 and `reason`, before any message.
void check_closed_for_token(ProtoClient& c, const std::string& reason) {
  REQUIRE(wait_for([&] { return c.ws.closed(); }, 3000));
  CHECK_FALSE(c.ws.receive(0));
  CHECK(c.ws.close_code() == 4401);
  CHECK(c.ws.close_reason() == reason);
}

size_t rejections(TestNode& node, const std::string& reason) {
  return node.count(Ev::rejected, [&](const Event& e) { return e.value == Json(reason); });
}

// No line of the node's log holds any of `secrets` (tokens, their MACs, the key).
void check_log_holds_none_of(TestNode& node, const std::vector<std::string>& secrets) {
  flush_logger(node.sys, node.logger);
  std::lock_guard<std::mutex> l(node.log->mu);
  REQUIRE_FALSE(node.log->events.empty());
  for (const Event& e : node.log->events) {
    const std::string line = to_json_line(e);
    for (const std::string& s : secrets) {
      INFO(line);
      CHECK(line.find(s) == std::string::npos);
    }
  }
}

// A token and its MAC (the part that is the secret): neither may be logged.
std::vector<std::string> secrets_of(const std::vector<std::string>& tokens) {
  std::vector<std::string> out{kKey};
  for (const std::string& t : tokens) {
    out.push_back(t);
    out.push_back(t.substr(t.rfind('.') + 1));
  }
  return out;
}

}  // namespace

TEST_CASE("A client without an access token is refused with its reason, over HTTP or as a close", "[e2e]") {
  auto node = node_with_key();
  // Not a browser (no Origin): HTTP 401 with the reason and a WWW-Authenticate challenge.
  auto r = refused_upgrade(node->port(), "/ws");
  CHECK(r.status == 401);
  CHECK(r.body == "access token required\n");
  CHECK(r.header("WWW-Authenticate") == std::string("Bearer realm=\"tessera\""));
  ProtoClient plain;
  std::string error;
  CHECK_FALSE(plain.ws.connect("127.0.0.1", node->port(), "/ws", &error));
  CHECK(plain.ws.http_status() == 401);
  // A browser: a page reads nothing of a refused upgrade, so it gets a close frame with the reason.
  ProtoClient browser;
  REQUIRE(browser.ws.connect("127.0.0.1", node->port(), "/ws", &error, 5000, own_origin(node->port())));
  check_closed_for_token(browser, "access token required");
  // No session was opened for either; one event per refusal.
  CHECK(node->count(Ev::opened) == 0);
  CHECK(rejections(*node, "access token required") == 3);
  // Then a valid token gets in, on the same node, with and without Origin.
  ProtoClient ok, ok_browser;
  const std::string token = valid_token();
  REQUIRE(ok.ws.connect("127.0.0.1", node->port(), "/ws?access_token=" + token, &error));
  CHECK(gets_frame(ok));
  REQUIRE(ok_browser.ws.connect("127.0.0.1", node->port(), "/ws?session=admitted01&access_token=" + token, &error,
                                5000, own_origin(node->port())));
  CHECK(gets_frame(ok_browser, 2));
  CHECK(node->server->sessions() == 2);
  check_log_holds_none_of(*node, secrets_of({token}));
}

TEST_CASE("An expired token and a token signed with another key are refused, and nothing logs them", "[e2e]") {
  auto node = node_with_key();
  const std::string expired = expired_token(), forged = foreign_token();
  auto r = refused_upgrade(node->port(), "/ws?access_token=" + expired);
  CHECK(r.status == 401);
  CHECK(r.body == "access token expired\n");
  r = refused_upgrade(node->port(), "/ws?access_token=" + forged);
  CHECK(r.status == 401);
  CHECK(r.body == "access token invalid\n");
  r = refused_upgrade(node->port(), "/ws?access_token=not-a-token-at-all");
  CHECK(r.status == 401);
  CHECK(r.body == "access token invalid\n");
  ProtoClient late, forger;
  std::string error;
  REQUIRE(late.ws.connect("127.0.0.1", node->port(), "/ws?access_token=" + expired, &error, 5000,
                          own_origin(node->port())));
  check_closed_for_token(late, "access token expired");
  REQUIRE(forger.ws.connect("127.0.0.1", node->port(), "/ws?access_token=" + forged, &error, 5000,
                            own_origin(node->port())));
  check_closed_for_token(forger, "access token invalid");
  CHECK(node->count(Ev::opened) == 0);
  // The log says why, and whose token expired (the subject of a genuine token), escaped.
  auto events = node->events(Ev::rejected);
  REQUIRE(events.size() == 5);
  CHECK(rejections(*node, "access token expired") == 2);
  CHECK(node->count(Ev::rejected, [](const Event& e) { return has(e, "subject", "e2e-late"); }) == 2);
  CHECK(node->count(Ev::rejected, [](const Event& e) { return has(e, "why", "bad signature"); }) == 2);
  CHECK(node->count(Ev::rejected, [](const Event& e) { return has(e, "why", "malformed"); }) == 1);
  CHECK(node->count(Ev::rejected, [](const Event& e) { return has(e, "subject", "e2e-forger"); }) == 0);
  check_log_holds_none_of(*node, secrets_of({expired, forged}));
}

TEST_CASE("A foreign Origin gets HTTP 403 and no WebSocket; the node's own and loopback origins get in", "[e2e]") {
  TestNode node;  // no token configured: the origin check is on by default all the same
  for (const char* foreign : {"http://evil.example", "http://127.0.0.1.evil.example:8080", "null"}) {
    auto r = refused_upgrade(node.port(), "/ws", std::string("Origin: ") + foreign + "\r\n");
    INFO(foreign);
    CHECK(r.status == 403);
    CHECK(r.body == "origin not allowed\n");
    ProtoClient c;
    std::string error;
    CHECK_FALSE(c.ws.connect("127.0.0.1", node.port(), "/ws", &error, 5000, {{"Origin", foreign}}));
    CHECK(c.ws.http_status() == 403);
  }
  CHECK(node.count(Ev::opened) == 0);
  CHECK(rejections(node, "origin not allowed") == 6);
  CHECK(node.count(Ev::rejected, [](const Event& e) { return has(e, "origin", "http://evil.example"); }) == 2);
  // The node's own page, another page on this machine, and a client that is no browser.
  const Headers allowed[] = {own_origin(node.port()), {{"Origin", "http://localhost:3000"}},
                             {{"Origin", "http://[::1]:8080"}}, {}};
  uint32_t frame = 1;
  for (const Headers& h : allowed) {
    ProtoClient c;
    std::string error;
    INFO((h.empty() ? "no Origin" : h[0].second));
    REQUIRE(c.ws.connect("127.0.0.1", node.port(), "/ws", &error, 5000, h));
    CHECK(gets_frame(c, frame++));
  }
}

TEST_CASE("allowed-origins replaces the default: only the listed origins, and require-origin refuses non-browsers",
          "[e2e]") {
  TestNode node(8, [](NodeSettings&, ServerOptions& o) {
    o.origins = admission::OriginPolicy::parse({"https://app.example.com"}, true);
  });
  std::string error;
  ProtoClient app;
  REQUIRE(app.ws.connect("127.0.0.1", node.port(), "/ws", &error, 5000, {{"Origin", "https://app.example.com"}}));
  CHECK(gets_frame(app));
  for (const char* other : {"http://app.example.com", "http://localhost:3000"}) {
    auto r = refused_upgrade(node.port(), "/ws", std::string("Origin: ") + other + "\r\n");
    INFO(other);
    CHECK(r.status == 403);
  }
  CHECK(refused_upgrade(node.port(), "/ws", "Origin: http://127.0.0.1:" + std::to_string(node.port()) + "\r\n").status ==
        403);
  auto bare = refused_upgrade(node.port(), "/ws");
  CHECK(bare.status == 403);
  CHECK(bare.body == "origin required\n");
}

TEST_CASE("The per-address limit refuses the N+1th connection with 429 while the others keep working", "[e2e]") {
  auto node = node_with_key(2);
  const std::string token = valid_token();
  const std::string ws = "/ws?access_token=" + token;
  ProtoClient a, b;
  std::string error;
  REQUIRE(a.ws.connect("127.0.0.1", node->port(), ws, &error));
  REQUIRE(b.ws.connect("127.0.0.1", node->port(), ws, &error, 5000, own_origin(node->port())));
  CHECK(gets_frame(a, 1));
  CHECK(gets_frame(b, 1));
  auto r = refused_upgrade(node->port(), ws);
  CHECK(r.status == 429);
  CHECK(r.body == "too many connections from this address: 2 (max-connections-per-ip)\n");
  CHECK(r.header("Retry-After") == std::string("5"));
  ProtoClient c;
  CHECK_FALSE(c.ws.connect("127.0.0.1", node->port(), ws, &error));
  CHECK(c.ws.http_status() == 429);
  CHECK(rejections(*node, "too many connections from this address") == 2);
  // The two admitted sessions are untouched.
  CHECK(a.render(pavilion_loop().camera(10), 2));
  CHECK(b.render(pavilion_loop().camera(10), 2));
  // One leaves: its slot is free again.
  a.ws.close();
  std::unique_ptr<ProtoClient> d;
  CHECK(wait_for([&] {
    d = std::make_unique<ProtoClient>();  // a WsClient connects once
    return d->ws.connect("127.0.0.1", node->port(), ws, &error);
  }, 5000));
  CHECK(gets_frame(*d, 1));
  check_log_holds_none_of(*node, secrets_of({token}));
}

TEST_CASE("An MJPEG stream asks for the access token too", "[e2e]") {
  auto node = node_with_key();
  const std::string token = valid_token(), expired = expired_token();
  ProtoClient c;
  std::string error;
  REQUIRE(c.ws.connect("127.0.0.1", node->port(), "/ws?session=mjpegadmit01&access_token=" + token, &error));
  REQUIRE(c.handshake(DisplayKind::mjpeg, 64, 48));
  REQUIRE(c.render(pavilion_loop().camera(0), 1));
  const std::string stream = "/mjpeg/mjpegadmit01";
  const std::pair<std::string, std::string> refused[] = {
      {stream, "access token required"},
      {stream + "?access_token=" + expired, "access token expired"},
      {stream + "?access_token=" + foreign_token(), "access token invalid"},
      {"/mjpeg/nosuchsession", "access token required"},  // no token: not even whether it exists
  };
  for (const auto& [target, reason] : refused) {
    auto r = http::get("127.0.0.1", node->port(), target);
    REQUIRE(r);
    INFO(target);
    CHECK(r->status == 401);
    CHECK(r->body == reason + "\n");
  }
  auto head = http::request("127.0.0.1", node->port(), "HEAD", stream);
  REQUIRE(head);
  CHECK(head->status == 401);
  CHECK(head->body.empty());
  auto foreign = http::request("127.0.0.1", node->port(), "GET", stream + "?access_token=" + token,
                               "Origin: http://evil.example\r\n");
  REQUIRE(foreign);
  CHECK(foreign->status == 403);
  CHECK(node->server->mjpeg_viewers() == 0);
  // With the token the stream opens (from an <img>: no Origin) and shows the frames.
  std::vector<std::vector<uint8_t>> parts;
  auto reader = std::async(std::launch::async, [&] {
    return http::read_mjpeg("127.0.0.1", node->port(), stream + "?access_token=" + token, 2, parts, &error, 20000);
  });
  uint32_t n = 2;
  while (reader.wait_for(std::chrono::milliseconds(0)) != std::future_status::ready && n < 40)
    REQUIRE(c.render(pavilion_loop().camera(0), n++));
  INFO(error);
  REQUIRE(reader.get());
  CHECK(parts.size() == 2);
  CHECK(rejections(*node, "access token required") == 3);  // HEAD counts too
  check_log_holds_none_of(*node, secrets_of({token, expired}));
}

TEST_CASE("Static tokens from a list are taken beside signed ones", "[e2e]") {
  const std::string fixed = "static-e2e-token-0123456789";
  TestNode node(8, [&](NodeSettings&, ServerOptions& o) {
    o.tokens.add_static(fixed);
    o.tokens.set_key(kKey);
  });
  std::string error;
  ProtoClient s, k;
  REQUIRE(s.ws.connect("127.0.0.1", node.port(), "/ws?access_token=" + fixed, &error));
  CHECK(gets_frame(s));
  REQUIRE(k.ws.connect("127.0.0.1", node.port(), "/ws?access_token=" + valid_token(), &error));
  CHECK(gets_frame(k));
  auto r = refused_upgrade(node.port(), "/ws?access_token=" + fixed + "x");
  CHECK(r.status == 401);
  CHECK(node.count(Ev::rejected, [](const Event& e) { return has(e, "why", "unknown token"); }) == 1);
  check_log_holds_none_of(node, {fixed, kKey});
}
