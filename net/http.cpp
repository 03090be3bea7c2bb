#include "net/http.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include <openssl/ssl.h>

#include "net/tls.h"

namespace tessera::http {

namespace fs = std::filesystem;

const char* mime_type(const std::string& path) {
  static const struct {
    const char* ext;
    const char* type;
  } kTypes[] = {
      {".html", "text/html; charset=utf-8"}, {".htm", "text/html; charset=utf-8"},
      {".xhtml", "application/xhtml+xml"},  // XML3D 4.x pages
      {".js", "text/javascript; charset=utf-8"}, {".mjs", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"}, {".json", "application/json"},
      {".png", "image/png"}, {".jpg", "image/jpeg"}, {".jpeg", "image/jpeg"}, {".gif", "image/gif"},
      {".svg", "image/svg+xml"}, {".ico", "image/x-icon"}, {".webp", "image/webp"},
      {".txt", "text/plain; charset=utf-8"}, {".md", "text/plain; charset=utf-8"},
      {".xml", "application/xml"}, {".wasm", "application/wasm"}, {".gltf", "model/gltf+json"},
      {".glb", "model/gltf-binary"}, {".bin", "application/octet-stream"}, {".map", "application/json"},
  };
  auto dot = path.rfind('.');
  if (dot == std::string::npos || path.find('/', dot) != std::string::npos) return "application/octet-stream";
  std::string ext = path.substr(dot);
  for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  for (const auto& t : kTypes)
    if (ext == t.ext) return t.type;
  return "application/octet-stream";
}

bool public_path(const std::string& rel, const std::vector<std::string>& extra) {
  static const char* kPrefixes[] = {"src/", "demo/", "node_modules/three/build/"};
  if (rel == "index.html") return true;
  for (const char* p : kPrefixes)
    if (rel.compare(0, std::strlen(p), p) == 0 && rel.size() > std::strlen(p)) return true;
  for (const std::string& p : extra)
    if (!p.empty() && p.back() == '/' && rel.compare(0, p.size(), p) == 0 && rel.size() > p.size()) return true;
  return false;
}

std::optional<std::string> resolve_public(const std::string& root, const std::string& target,
                                          const std::vector<std::string>& extra) {
  auto file = resolve_static(root, target);
  if (!file) return std::nullopt;
  std::error_code ec;
  const std::string base = fs::weakly_canonical(fs::path(root), ec).string();
  if (ec || file->size() <= base.size() + 1) return std::nullopt;
  return public_path(file->substr(base.size() + 1), extra) ? file : std::nullopt;
}

namespace {

// Digits only; saturates at UINT64_MAX. False when empty or not all digits.
bool parse_u64(const std::string& s, uint64_t& v) {
  if (s.empty()) return false;
  v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    const uint64_t d = uint64_t(c - '0');
    v = v > (UINT64_MAX - d) / 10 ? UINT64_MAX : v * 10 + d;
  }
  return true;
}

std::string trim(const std::string& s) {
  size_t a = s.find_first_not_of(" \t"), b = s.find_last_not_of(" \t");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

}  // namespace

RangeKind parse_range(const std::string& header, uint64_t size, ByteRange& range) {
  std::string h = trim(header);
  auto eq = h.find('=');
  if (eq == std::string::npos) return RangeKind::full;
  std::string unit = trim(h.substr(0, eq));
  for (auto& c : unit) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (unit != "bytes") return RangeKind::full;
  const std::string spec = trim(h.substr(eq + 1));
  if (spec.find(',') != std::string::npos) return RangeKind::full;  // several ranges: the whole file
  const auto dash = spec.find('-');
  if (dash == std::string::npos) return RangeKind::full;
  const std::string a = trim(spec.substr(0, dash)), b = trim(spec.substr(dash + 1));
  uint64_t first = 0, last = 0;
  if (a.empty()) {  // suffix: the last b bytes
    if (!parse_u64(b, last)) return RangeKind::full;
    if (last == 0 || size == 0) return RangeKind::unsatisfiable;
    range = {size - std::min(last, size), size - 1};
    return RangeKind::partial;
  }
  if (!parse_u64(a, first)) return RangeKind::full;
  if (b.empty()) {
    last = UINT64_MAX;
  } else if (!parse_u64(b, last) || last < first) {
    return RangeKind::full;  // invalid: ignored
  }
  if (first >= size) return RangeKind::unsatisfiable;
  range = {first, std::min(last, size - 1)};
  return RangeKind::partial;
}

bool valid_token(const std::string& t) {
  if (t.size() < 8 || t.size() > 64) return false;
  for (char c : t)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  return true;
}

std::string query_param(const std::string& target, const std::string& key) {
  auto q = target.find('?');
  if (q == std::string::npos) return "";
  std::string query = target.substr(q + 1, target.find('#', q) == std::string::npos ? std::string::npos
                                                                                       : target.find('#', q) - q - 1);
  size_t i = 0;
  while (i <= query.size()) {
    size_t j = query.find('&', i);
    if (j == std::string::npos) j = query.size();
    std::string kv = query.substr(i, j - i);
    auto eq = kv.find('=');
    if (kv.substr(0, eq) == key) return eq == std::string::npos ? "" : kv.substr(eq + 1);
    i = j + 1;
  }
  return "";
}

std::optional<std::string> redirect_host(const std::string& header) {
  std::string h = trim(header);
  if (h.empty() || h.size() > 300) return std::nullopt;
  for (auto& c : h) c = char(std::tolower(static_cast<unsigned char>(c)));
  std::string port;
  if (h.front() == '[') {  // [IPv6]:port
    const size_t close = h.find(']');
    if (close == std::string::npos) return std::nullopt;
    port = h.substr(close + 1);
    h = h.substr(0, close + 1);
    in6_addr a6;
    if (!port.empty() && port.front() != ':') return std::nullopt;
    // inet_pton reads up to a NUL: "[::1\0junk]" would pass it with the junk kept, so the
    // literal's characters are checked first.
    const std::string literal = h.substr(1, h.size() - 2);
    for (char c : literal)
      if (!(std::isxdigit(static_cast<unsigned char>(c)) || c == ':' || c == '.')) return std::nullopt;
    if (inet_pton(AF_INET6, literal.c_str(), &a6) != 1) return std::nullopt;
  } else {
    const size_t colon = h.find(':');
    if (colon != std::string::npos) {
      port = h.substr(colon);
      h = h.substr(0, colon);
    }
    if (h.empty() || h.size() > 253 || h.front() == '.' || h.front() == '-') return std::nullopt;
    for (char c : h)
      if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '.')) return std::nullopt;
  }
  if (!port.empty()) {  // ":" and up to 5 digits, or nothing
    uint64_t p = 0;
    if (port.size() > 6 || (port.size() > 1 && (!parse_u64(port.substr(1), p) || p > 65535))) return std::nullopt;
  }
  return h;
}

std::string location(const std::string& scheme, const std::string& host, uint16_t port, const std::string& target) {
  const bool default_port = port == ((scheme == "https" || scheme == "wss") ? 443 : 80);
  std::string out = scheme + "://" + host + (default_port ? "" : ":" + std::to_string(port));
  if (target.empty() || target.front() != '/') return out + "/";
  static const char* kHex = "0123456789ABCDEF";
  auto hex = [](char c) { return std::isxdigit(static_cast<unsigned char>(c)) != 0; };
  for (size_t i = 0; i < target.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(target[i]);
    // RFC 3986 unreserved, sub-delims, ':', '@', '/', '?', and '%' where it starts an escape.
    const bool keep = (c < 0x80 && std::isalnum(c)) || (c != 0 && std::strchr("-._~!$&'()*+,;=:@/?", c)) ||
                      (c == '%' && i + 2 < target.size() && hex(target[i + 1]) && hex(target[i + 2]));
    if (keep) {
      out += char(c);
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

// --- Client -----------------------------------------------------------------------------

namespace {

using Clock = std::chrono::steady_clock;

int connect_to(const std::string& host, uint16_t port) {
  addrinfo hints{}, *res = nullptr;
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res) != 0) return -1;
  int fd = -1;
  for (addrinfo* a = res; a; a = a->ai_next) {
    fd = ::socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) continue;
    if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) break;
    ::close(fd);
    fd = -1;
  }
  freeaddrinfo(res);
  return fd;
}

// One client connection: a TCP socket, with TLS over it when asked for. The socket stays
// blocking; every wait is a poll() against the caller's deadline.
class Stream {
 public:
  ~Stream() {
    if (ssl_) SSL_free(ssl_);
    if (fd_ >= 0) ::close(fd_);
  }
  // False and *error when the connection or the TLS handshake fails.
  bool open(const std::string& host, uint16_t port, const ClientTls& tls, Clock::time_point deadline,
            std::string* error) {
    fd_ = connect_to(host, port);
    if (fd_ < 0) return fail(error, "cannot connect");
    if (!tls.on) return true;
    // A blocking SSL_connect or SSL_read waits at most until the deadline.
    auto left = std::chrono::duration_cast<std::chrono::microseconds>(deadline - Clock::now()).count();
    timeval tv{time_t(std::max<long long>(left, 1000) / 1000000), suseconds_t(std::max<long long>(left, 1000) % 1000000)};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    ::setsockopt(fd_, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    try {
      ctx_ = tls::client_context(tls.ca_file);
    } catch (const std::exception& e) {
      return fail(error, e.what());
    }
    ssl_ = SSL_new(ctx_.get());
    if (!ssl_) return fail(error, tls::last_error("SSL_new failed"));
    SSL_set_fd(ssl_, fd_);
    in6_addr ip{};
    const bool literal = inet_pton(AF_INET, host.c_str(), &ip) == 1 || inet_pton(AF_INET6, host.c_str(), &ip) == 1;
    if (!literal) SSL_set_tlsext_host_name(ssl_, host.c_str());  // SNI names hosts, never addresses (RFC 6066)
    if (!tls.ca_file.empty()) tls::expect_host(ssl_, host);
    while (true) {
      int r = SSL_connect(ssl_);
      if (r == 1) return true;
      int e = SSL_get_error(ssl_, r);
      if ((e != SSL_ERROR_WANT_READ && e != SSL_ERROR_WANT_WRITE) || !wait(e == SSL_ERROR_WANT_WRITE, deadline))
        return fail(error, "TLS handshake: " + tls::last_error("failed"));
    }
  }
  bool write_all(const std::string& data) {
    if (!ssl_) return ::send(fd_, data.data(), data.size(), MSG_NOSIGNAL) == ssize_t(data.size());
    return SSL_write(ssl_, data.data(), int(data.size())) == int(data.size());
  }
  // Reads more bytes into buf; false on EOF, error or deadline.
  bool read_some(std::string& buf, Clock::time_point deadline) {
    char tmp[65536];
    if (!ssl_) {
      if (!wait(false, deadline)) return false;
      ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
      if (n <= 0) return false;
      buf.append(tmp, size_t(n));
      return true;
    }
    while (true) {
      if (SSL_pending(ssl_) == 0 && !wait(false, deadline)) return false;
      int n = SSL_read(ssl_, tmp, int(sizeof tmp));
      if (n > 0) {
        buf.append(tmp, size_t(n));
        return true;
      }
      int e = SSL_get_error(ssl_, n);
      if (e != SSL_ERROR_WANT_READ && e != SSL_ERROR_WANT_WRITE) return false;  // closed or failed
    }
  }

 private:
  bool wait(bool for_write, Clock::time_point deadline) {
    // Rounded up: a wait that times out ends at the deadline, not before it (read_mjpeg_stream
    // tells a timeout from a closed stream by the time).
    const auto left_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - Clock::now()).count();
    if (left_ns <= 0) return false;
    const long long left = (left_ns + 999'999) / 1'000'000;
    pollfd p{fd_, short(for_write ? POLLOUT : POLLIN), 0};
    return ::poll(&p, 1, int(left)) > 0;
  }
  static bool fail(std::string* error, const std::string& why) {
    if (error) *error = why;
    return false;
  }
  int fd_ = -1;
  tls::CtxPtr ctx_;
  SSL* ssl_ = nullptr;
};

std::string request_text(const std::string& host, const std::string& target, const std::string& method = "GET",
                         const std::string& extra = "") {
  return method + " " + target + " HTTP/1.1\r\nHost: " + host + "\r\nConnection: close\r\n" + extra + "\r\n";
}

std::string header_value(const std::string& head, const std::string& name) {
  std::string lower = head;
  for (auto& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
  std::string key = "\r\n" + name + ":";
  auto p = lower.find(key);
  if (p == std::string::npos) return "";
  p += key.size();
  auto e = head.find("\r\n", p);
  std::string v = head.substr(p, e - p);
  while (!v.empty() && v.front() == ' ') v.erase(v.begin());
  return v;
}

}  // namespace

std::optional<std::string> Response::header(const std::string& name) const {
  std::string lower = head, key = name;
  for (auto& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
  for (auto& c : key) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (lower.find("\r\n" + key + ":") == std::string::npos) return std::nullopt;
  return header_value(head, key);
}

std::optional<Response> get(const std::string& host, uint16_t port, const std::string& target, int timeout_ms,
                            const ClientTls& tls) {
  return request(host, port, "GET", target, "", timeout_ms, tls);
}

std::optional<Response> request(const std::string& host, uint16_t port, const std::string& method,
                                const std::string& target, const std::string& extra_headers, int timeout_ms,
                                const ClientTls& tls) {
  auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  Stream stream;
  if (!stream.open(host, port, tls, deadline, nullptr)) return std::nullopt;
  std::string buf;
  if (!stream.write_all(request_text(host, target, method, extra_headers))) return std::nullopt;
  while (stream.read_some(buf, deadline)) {}
  auto he = buf.find("\r\n\r\n");
  if (buf.compare(0, 5, "HTTP/") != 0 || he == std::string::npos) return std::nullopt;
  Response r;
  r.status = std::atoi(buf.c_str() + buf.find(' ') + 1);
  r.head = buf.substr(0, he + 2);
  r.content_type = header_value(r.head, "content-type");
  r.body = buf.substr(he + 4);
  return r;
}

bool fetch_url(const std::string& url, uint64_t max_bytes, std::vector<uint8_t>& body, std::string& error,
               int timeout_ms) {
  const size_t colon = url.find("://");
  const std::string scheme = colon == std::string::npos ? "" : url.substr(0, colon);
  if (scheme != "http" && scheme != "https") {
    error = "not an http(s) URL";
    return false;
  }
  const size_t start = colon + 3, end = url.find_first_of("/?#", start);
  const std::string authority = url.substr(start, end == std::string::npos ? std::string::npos : end - start);
  std::string target = end == std::string::npos ? "/" : url.substr(end);
  target = target.substr(0, target.find('#'));
  if (target.empty() || target[0] != '/') target = "/" + target;
  std::string host = authority;
  uint16_t port = scheme == "https" ? 443 : 80;
  const size_t bracket = authority.rfind(']'), last = authority.rfind(':');
  if (last != std::string::npos && (bracket == std::string::npos || last > bracket)) {
    host = authority.substr(0, last);
    port = uint16_t(std::atoi(authority.c_str() + last + 1));
  }
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  Stream stream;
  if (!stream.open(host, port, ClientTls{scheme == "https", scheme == "https" ? tls::kSystemCas : ""}, deadline, &error)) {
    error = url + ": " + error;
    return false;
  }
  if (!stream.write_all("GET " + target + " HTTP/1.0\r\nHost: " + authority + "\r\nUser-Agent: tessera\r\n\r\n")) {
    error = url + ": cannot send the request";
    return false;
  }
  // Until the server closes, or the body reaches its Content-Length (a server may keep the
  // connection open even for HTTP/1.0).
  std::string buf;
  size_t he = std::string::npos, want = std::string::npos;
  while (true) {
    if (buf.size() > max_bytes + 65536) {
      error = url + ": the body exceeds " + std::to_string(max_bytes) + " bytes";
      return false;
    }
    if (he == std::string::npos && (he = buf.find("\r\n\r\n")) != std::string::npos) {
      const std::string length = header_value(buf.substr(0, he + 2), "content-length");
      if (!length.empty()) want = he + 4 + size_t(std::strtoull(length.c_str(), nullptr, 10));
    }
    if (want != std::string::npos && buf.size() >= want) break;
    if (!stream.read_some(buf, deadline)) {
      if (Clock::now() >= deadline) {
        error = url + ": no complete answer within " + std::to_string(timeout_ms) + " ms";
        return false;
      }
      break;
    }
  }
  if (want != std::string::npos && buf.size() > want) buf.resize(want);
  he = buf.find("\r\n\r\n");
  if (buf.compare(0, 5, "HTTP/") != 0 || he == std::string::npos) {
    error = url + ": not an HTTP answer";
    return false;
  }
  const int status = std::atoi(buf.c_str() + buf.find(' ') + 1);
  if (status != 200) {
    error = url + ": HTTP " + std::to_string(status);
    return false;
  }
  if (buf.size() - he - 4 > max_bytes) {
    error = url + ": the body exceeds " + std::to_string(max_bytes) + " bytes";
    return false;
  }
  const std::string length = header_value(buf.substr(0, he + 2), "content-length");
  if (!length.empty() && std::strtoull(length.c_str(), nullptr, 10) != buf.size() - he - 4) {
    error = url + ": the body ended before its Content-Length";
    return false;
  }
  body.assign(buf.begin() + std::ptrdiff_t(he + 4), buf.end());
  return true;
}

bool read_mjpeg(const std::string& host, uint16_t port, const std::string& target, size_t parts,
                std::vector<std::vector<uint8_t>>& out, std::string* error, int timeout_ms, const ClientTls& tls) {
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  const bool ok = read_mjpeg_stream(
      host, port, target,
      [&](std::vector<uint8_t>&& part, long) {
        out.push_back(std::move(part));
        return out.size() < parts;
      },
      [&] { return Clock::now() >= deadline; }, error, timeout_ms, tls);
  if (ok && out.size() < parts) {
    if (error) *error = "timed out after " + std::to_string(out.size()) + " parts";
    return false;
  }
  return ok;
}

bool read_mjpeg_stream(const std::string& host, uint16_t port, const std::string& target,
                       const std::function<bool(std::vector<uint8_t>&& part, long frame)>& on_part,
                       const std::function<bool()>& stop, std::string* error, int connect_timeout_ms,
                       const ClientTls& tls) {
  auto fail = [&](const std::string& e) {
    if (error) *error = e;
    return false;
  };
  Stream stream;
  if (!stream.open(host, port, tls, Clock::now() + std::chrono::milliseconds(connect_timeout_ms), error)) return false;
  if (!stream.write_all(request_text(host, target))) return fail("cannot send the request");
  std::string buf;
  // One read of at most 200 ms: false with `stopped` when stop() says so, false when the stream
  // ended or failed.
  bool stopped = false;
  auto more = [&] {
    while (true) {
      if (stop()) {
        stopped = true;
        return false;
      }
      const auto until = Clock::now() + std::chrono::milliseconds(200);
      if (stream.read_some(buf, until)) return true;
      if (Clock::now() < until) return false;  // ended or failed before the time was up
    }
  };
  size_t he;
  while ((he = buf.find("\r\n\r\n")) == std::string::npos)
    if (!more()) return stopped || fail("no response header");
  std::string head = buf.substr(0, he + 2);
  if (std::atoi(buf.c_str() + buf.find(' ') + 1) != 200) return fail("status: " + head.substr(0, head.find('\r')));
  std::string ct = header_value(head, "content-type");
  auto bp = ct.find("boundary=");
  if (ct.find("multipart/x-mixed-replace") != 0 || bp == std::string::npos) return fail("content type: " + ct);
  std::string boundary = "--" + ct.substr(bp + 9);
  buf.erase(0, he + 4);
  for (size_t n = 0;; ++n) {
    size_t b, ph;
    while ((b = buf.find(boundary)) == std::string::npos || (ph = buf.find("\r\n\r\n", b)) == std::string::npos)
      if (!more()) return stopped || fail("stream ended after " + std::to_string(n) + " parts");
    std::string part_head = buf.substr(b + boundary.size(), ph + 2 - b - boundary.size());
    long len = std::atol(header_value(part_head, "content-length").c_str());
    if (len <= 0) return fail("part without Content-Length");
    const std::string frame = header_value(part_head, "x-tessera-frame");
    while (buf.size() < ph + 4 + size_t(len))
      if (!more()) return stopped || fail("part truncated");
    std::vector<uint8_t> part(buf.begin() + long(ph + 4), buf.begin() + long(ph + 4 + size_t(len)));
    buf.erase(0, ph + 4 + size_t(len));
    // A frame number the client can look up, else -1 (absent, not a number, out of range).
    char* end = nullptr;
    const long n_frame = frame.empty() ? -1 : std::strtol(frame.c_str(), &end, 10);
    const bool valid = !frame.empty() && end && *end == '\0' && n_frame >= 0 && n_frame <= long(UINT32_MAX);
    if (!on_part(std::move(part), valid ? n_frame : -1)) return true;
  }
}

}  // namespace tessera::http
