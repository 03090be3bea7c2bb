// Static file resolution, MIME types and session tokens of the node's HTTP endpoint.
#include <catch2/catch.hpp>

#include "net/http.h"

using namespace tessera::http;

TEST_CASE("Static targets resolve inside the web root and nowhere else", "[unit]") {
  // Run from the repository root (CTest's working directory).
  auto demo = resolve_static("web", "/demo/index.html?x=1");
  REQUIRE(demo);
  CHECK(demo->find("/web/demo/index.html") != std::string::npos);
  CHECK(resolve_static("web", "/demo/"));
  CHECK(resolve_static("web", "/demo"));  // a directory means its index.html
  for (const char* bad : {"", "demo/index.html", "/../CMakeLists.txt", "/demo/../../CMakeLists.txt",
                          "/%2e%2e/CMakeLists.txt", "/%2E%2E%2FCMakeLists.txt", "/.hidden", "/demo/%00",
                          "/demo/index.html%00.png", "/%zz", "/demo\\..\\..\\CMakeLists.txt", "/nonexistent.html"})
    CHECK_FALSE(resolve_static("web", bad));
}

TEST_CASE("MIME types follow the file extension", "[unit]") {
  CHECK(std::string(mime_type("a/b.html")) == "text/html; charset=utf-8");
  CHECK(std::string(mime_type("x.JS")) == "text/javascript; charset=utf-8");
  CHECK(std::string(mime_type("x.png")) == "image/png");
  CHECK(std::string(mime_type("x.wasm")) == "application/wasm");
  CHECK(std::string(mime_type("old/page.XHTML")) == "application/xhtml+xml");
  CHECK(std::string(mime_type("dir.d/noext")) == "application/octet-stream");
}

TEST_CASE("Session tokens and query parameters", "[unit]") {
  CHECK(valid_token("abcdEFGH_-09"));
  CHECK_FALSE(valid_token("short"));
  CHECK_FALSE(valid_token("has space in it"));
  CHECK_FALSE(valid_token(std::string(65, 'a')));
  CHECK(query_param("/ws?session=abc&x=1", "session") == "abc");
  CHECK(query_param("/ws?x=1&session=abc#f", "session") == "abc");
  CHECK(query_param("/ws", "session").empty());
  CHECK(target_path("/a/b?c#d") == "/a/b");
}

TEST_CASE("Only the client, the demo pages, the index page and the three.js build are public", "[unit]") {
  for (const char* ok : {"index.html", "src/xml3d.js", "src/net/Protocol.js", "demo/index.html", "demo/demo.css",
                         "node_modules/three/build/three.module.js", "node_modules/three/build/three.core.js"})
    CHECK(public_path(ok));
  for (const char* no : {"package.json", "package-lock.json", "tools/static-server.js", "test/run-unit.js",
                         "node_modules/ws/index.js", "node_modules/three/package.json", "node_modules/three/src/Three.js",
                         "src", "demo/", "srcx/a.js", "index.htm"})
    CHECK_FALSE(public_path(no));
  // Run from the repository root (CTest's working directory).
  CHECK(resolve_public("web", "/demo/index.html"));
  CHECK(resolve_public("web", "/src/xml3d.js"));
  CHECK(resolve_public("web", "/demo/"));
  for (const char* no : {"/package.json", "/package-lock.json", "/tools/static-server.js", "/test/run-unit.js",
                         "/%70ackage.json", "/demo/../package.json", "/src/../tools/static-server.js"})
    CHECK_FALSE(resolve_public("web", no));
  // An operator's further public folders (tessera.web-public) add exactly those folders.
  const std::vector<std::string> extra{"test/browser/pages/"};
  CHECK(public_path("test/browser/pages/node.html", extra));
  CHECK_FALSE(public_path("test/browser/pages/node.html"));
  CHECK_FALSE(public_path("test/browser/node-e2e.test.js", extra));
  CHECK_FALSE(public_path("test/browser/pages", extra));
  CHECK(resolve_public("web", "/test/browser/pages/node.html", extra));
  CHECK_FALSE(resolve_public("web", "/test/browser/pages/../node-e2e.test.js", extra));
}

TEST_CASE("Range headers: one byte range is served, several or malformed ones mean the whole file", "[unit]") {
  ByteRange r;
  CHECK(parse_range("", 100, r) == RangeKind::full);
  CHECK(parse_range("bytes=0-9", 100, r) == RangeKind::partial);
  CHECK((r.first == 0 && r.last == 9));
  CHECK(parse_range("bytes=90-", 100, r) == RangeKind::partial);
  CHECK((r.first == 90 && r.last == 99));
  CHECK(parse_range("bytes=50-1000", 100, r) == RangeKind::partial);  // clamped to the end
  CHECK((r.first == 50 && r.last == 99));
  CHECK(parse_range("bytes=-10", 100, r) == RangeKind::partial);  // the last 10 bytes
  CHECK((r.first == 90 && r.last == 99));
  CHECK(parse_range("bytes=-1000", 100, r) == RangeKind::partial);
  CHECK((r.first == 0 && r.last == 99));
  CHECK(parse_range(" Bytes = 5 - 5 ", 100, r) == RangeKind::partial);
  CHECK((r.first == 5 && r.last == 5));
  CHECK(parse_range("bytes=99999999999999999999999-", 100, r) == RangeKind::unsatisfiable);
  CHECK(parse_range("bytes=100-", 100, r) == RangeKind::unsatisfiable);
  CHECK(parse_range("bytes=-0", 100, r) == RangeKind::unsatisfiable);
  CHECK(parse_range("bytes=0-", 0, r) == RangeKind::unsatisfiable);
  for (const char* full : {"bytes=0-1,5-6", "items=0-5", "bytes=5-1", "bytes=a-b", "bytes=", "bytes=-", "bytes 0-5",
                           "bytes=1-2-3"})
    CHECK(parse_range(full, 100, r) == RangeKind::full);
}

TEST_CASE("The redirect to HTTPS takes a Host header's host only when it is a host name or an address", "[unit]") {
  CHECK(redirect_host("node.example") == std::optional<std::string>("node.example"));
  CHECK(redirect_host("Node.Example:8080") == std::optional<std::string>("node.example"));
  CHECK(redirect_host(" localhost:80 ") == std::optional<std::string>("localhost"));
  CHECK(redirect_host("10.0.0.2:8080") == std::optional<std::string>("10.0.0.2"));
  CHECK(redirect_host("[::1]:8080") == std::optional<std::string>("[::1]"));
  CHECK(redirect_host("[2001:DB8::7]") == std::optional<std::string>("[2001:db8::7]"));
  CHECK(redirect_host("xn--bcher-kva.example:") == std::optional<std::string>("xn--bcher-kva.example"));
  for (const char* hostile :
       {"", " ", "evil.example\r\nSet-Cookie: a=1", "evil.example\nX-Injected: 1", "a b.example", "evil.example/@x",
        "user@evil.example", "evil.example?x", "evil.example#x", "\"evil\"", "<script>", "evil.example:99999",
        "evil.example:80:81", "evil.example:8o", ":8080", "::1", "[::1", "[::1]x", "[::1]:80x", "[zz::1]",
        "[::1%25eth0]", ".example", "-evil.example", "ex%61mple.com", "b\xc3\xbc" "cher.example", "evil.example\x01"}) {
    INFO(hostile);
    CHECK_FALSE(redirect_host(hostile));
  }
  CHECK_FALSE(redirect_host(std::string(254, 'a')));
  // A NUL inside an IPv6 literal: inet_pton stops reading there (found by fuzz_http).
  CHECK_FALSE(redirect_host(std::string("[::1\0junk]:8080", 16)));
  CHECK_FALSE(redirect_host(std::string("[::1\0]", 6)));
  CHECK_FALSE(redirect_host(std::string("node\0.example", 13)));
}

TEST_CASE("The redirect's Location keeps the path and query and escapes what may not stand in a URL", "[unit]") {
  CHECK(location("https", "node.example", 8443, "/demo/index.html?a=1&b=%20x") ==
        "https://node.example:8443/demo/index.html?a=1&b=%20x");
  CHECK(location("https", "node.example", 443, "/") == "https://node.example/");  // https's own port left out
  CHECK(location("wss", "[::1]", 443, "/ws") == "wss://[::1]/ws");
  CHECK(location("wss", "[::1]", 8443, "/ws") == "wss://[::1]:8443/ws");
  CHECK(location("https", "h", 8443, "") == "https://h:8443/");
  CHECK(location("https", "h", 8443, "*") == "https://h:8443/");
  CHECK(location("https", "h", 8443, "http://evil.example/x") == "https://h:8443/");  // not origin-form
  CHECK(location("https", "h", 8443, "//evil.example/x") == "https://h:8443//evil.example/x");  // a path on h
  static const char kTarget[] = "/a b\"<c>\r\nSet-Cookie:x\x7f\xff%zz%4\0#";
  const std::string escaped = location("https", "h", 8443, std::string(kTarget, sizeof kTarget - 1));
  CHECK(escaped == "https://h:8443/a%20b%22%3Cc%3E%0D%0ASet-Cookie:x%7F%FF%25zz%254%00%23");
  for (char c : escaped) CHECK((c > 0x20 && c < 0x7f));
}
