#pragma once
// HTTP helpers of the node's endpoint (pure code, no websocketpp): static file resolution
// without path traversal, MIME types, session tokens, and a minimal blocking HTTP client
// for tests and the load test (POSIX sockets).
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/static_path.h"

namespace tessera::http {

// MIME type from the file extension ("application/octet-stream" when unknown).
const char* mime_type(const std::string& path);

// resolve_static and target_path: core/static_path.h (the node also reads referenced scene
// files through them, update/asset_store.h).
using tessera::resolve_static;
using tessera::target_path;

// What the node serves of its web root: the web client (src/), the demo pages (demo/), the
// index page and the three.js build the pages import (node_modules/three/build/); never
// package.json, tools/, test/ or other packages. resolve_static, then this allow-list on the
// resolved path relative to the root (so neither a symlink nor an escape gets round it).
// `extra`: further public folders an operator named (ServerOptions::web_public, each ending
// in '/', e.g. "test/browser/pages/").
std::optional<std::string> resolve_public(const std::string& root, const std::string& target,
                                          const std::vector<std::string>& extra = {});
bool public_path(const std::string& relative, const std::vector<std::string>& extra = {});  // "demo/index.html" -> true

// A Range request header (RFC 9110 14.2) against a file of `size` bytes. Only one range of
// unit "bytes" is served: "a-b", "a-" or "-n" (the last n bytes).
enum class RangeKind {
  full,           // no Range, several ranges, or a header that does not parse: 200 with the whole file
  partial,        // 206 with `range`
  unsatisfiable,  // 416 (the range starts at or after the end, or "-0")
};
struct ByteRange {
  uint64_t first = 0, last = 0;  // inclusive
};
RangeKind parse_range(const std::string& header, uint64_t size, ByteRange& range);

// Session tokens (?session=TOKEN on the WebSocket, /mjpeg/TOKEN): 8..64 of [A-Za-z0-9_-].
bool valid_token(const std::string& token);
// The value of `key` in the target's query string ("" when absent).
std::string query_param(const std::string& target, const std::string& key);

// The plain HTTP port's redirect to HTTPS (ServerOptions::http_redirect_port). The host of a
// Host header, lower case and without its port ("Node.Example:8080" -> "node.example",
// "[::1]:80" -> "[::1]"); nullopt unless it is a DNS name (letters, digits, '-', '.'), an IPv4
// address or a bracketed IPv6 address, so that a hostile header never reaches a Location.
std::optional<std::string> redirect_host(const std::string& host_header);
// scheme://HOST[:PORT]TARGET: the port left out when it is the scheme's (443 for https and wss),
// TARGET ("/path?query") kept with every byte that may not stand in a URL percent-escaped (no
// CR, LF, space or quote gets through), "/" when it is not a path.
std::string location(const std::string& scheme, const std::string& host, uint16_t port, const std::string& target);

// --- Client side (tests, load test) -------------------------------------------------------

struct Response {
  int status = 0;
  std::string content_type;
  std::string head;  // status line and headers, each line ending in CRLF
  std::string body;
  // The value of header `name` (case-insensitive); nullopt when absent.
  std::optional<std::string> header(const std::string& name) const;
};
// HTTPS instead of HTTP (net/tls.h). ca_file "": any certificate is taken (a self-signed test
// node); else the server's must chain to it and name the host.
struct ClientTls {
  bool on = false;
  std::string ca_file;
};

// GET http://host:port/target; nullopt on connection failure or timeout.
std::optional<Response> get(const std::string& host, uint16_t port, const std::string& target, int timeout_ms = 5000,
                            const ClientTls& tls = {});
// Any method, with extra header lines ("Range: bytes=0-9\r\n"); reads until the server closes.
std::optional<Response> request(const std::string& host, uint16_t port, const std::string& method,
                                const std::string& target, const std::string& extra_headers = "",
                                int timeout_ms = 5000, const ClientTls& tls = {});

// GETs an absolute http(s) URL for the node's references (update/asset_store.h) as HTTP/1.0
// (no chunked bodies): HTTPS verified against the system's CAs and the URL's host. Anything
// but a 200 (a redirect included: it could lead anywhere), a body beyond max_bytes, or the
// timeout fails with why.
bool fetch_url(const std::string& url, uint64_t max_bytes, std::vector<uint8_t>& body, std::string& error,
               int timeout_ms = 30000);

// Reads `parts` JPEG parts from a multipart/x-mixed-replace stream (MJPEG), then closes.
// False and *error on failure or timeout.
bool read_mjpeg(const std::string& host, uint16_t port, const std::string& target, size_t parts,
                std::vector<std::vector<uint8_t>>& out, std::string* error, int timeout_ms = 10000,
                const ClientTls& tls = {});

// Reads a multipart/x-mixed-replace stream part by part: on_part gets each part's bytes and
// the frame number of its X-Tessera-Frame header (-1 without one; docs/protocol.md) as soon as
// the part is in. Returns true once on_part returns false or stop() is true (asked at least
// every 200 ms), false and *error when the connection fails, the answer is not such a stream,
// or it ends. The connection is made within connect_timeout_ms.
bool read_mjpeg_stream(const std::string& host, uint16_t port, const std::string& target,
                       const std::function<bool(std::vector<uint8_t>&& part, long frame)>& on_part,
                       const std::function<bool()>& stop, std::string* error, int connect_timeout_ms = 10000,
                       const ClientTls& tls = {});

}  // namespace tessera::http
