#pragma once
// Session admission (issue 21, part 2): who may open a WebSocket session or an MJPEG stream on
// a node. Pure code over strings, no sockets, so that it is tested alone
// (tests/unit/test_admission.cpp); net/server.cpp applies it to each request and `tessera token`
// makes signed tokens with it. HMAC-SHA256 and SHA-256 come from OpenSSL's libcrypto.
//
// - Access tokens (docs/protocol.md, "Access tokens"): a signed token
//   "tsr1.<expiry>.<base64url(subject)>.<base64url(HMAC-SHA256(key, everything before the
//   last dot))>" made from a key file (any web back-end can make them), and/or static tokens
//   from a file. No key and no static tokens configured: no token is asked for.
// - Origins: the allow-list of page origins a browser may open a session from.
// - Per-address connection counts.
// Nothing here writes a token or a key anywhere; callers must not log them either.
#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace tessera::admission {

// --- Encoding and MACs ----------------------------------------------------------------------

// base64url (RFC 4648 section 5) without padding.
std::string base64url_encode(const uint8_t* data, size_t size);
std::string base64url_encode(const std::string& bytes);
// nullopt on characters outside the alphabet, padding, or an impossible length (4k+1).
std::optional<std::string> base64url_decode(const std::string& text);

using Digest = std::array<uint8_t, 32>;
Digest hmac_sha256(const std::string& key, const std::string& message);
Digest sha256(const std::string& bytes);
// Equal digests, in time that does not depend on where they differ (CRYPTO_memcmp).
bool same_digest(const Digest& a, const Digest& b);

// --- Tokens ---------------------------------------------------------------------------------

constexpr const char* kTokenVersion = "tsr1";
// A node accepts a signed token until this many seconds after its expiry: the clocks of the
// back-end that makes tokens and of the node may differ by this much.
constexpr int64_t kClockSkewSeconds = 60;
constexpr size_t kMaxTokenChars = 1024;    // longer: malformed, before any decoding
constexpr size_t kMaxSubjectBytes = 256;
constexpr size_t kMinKeyBytes = 32;        // a key file's content, whitespace trimmed
constexpr size_t kMinStaticTokenChars = 16;

// A signed token for `subject` (any bytes, at most kMaxSubjectBytes) valid until `expiry`
// (Unix seconds). Throws std::invalid_argument on a short key or a long subject.
std::string make_token(const std::string& key, int64_t expiry, const std::string& subject = "");

// What checking a presented token found. Everything but `ok` refuses the request.
enum class Verdict {
  ok,
  missing,        // no token, and the node asks for one
  malformed,      // not a token of either kind's shape
  bad_signature,  // a signed token whose MAC does not match the node's key
  unknown,        // not one of the static tokens
  expired,        // a genuine signed token past its expiry (plus the skew allowance)
};
struct TokenCheck {
  Verdict verdict = Verdict::missing;
  std::string subject;  // of a genuine signed token (also when expired); empty otherwise
  int64_t expiry = 0;   // of a genuine signed token
};
// For the log: "missing", "malformed", "bad signature", "unknown token", "expired".
const char* verdict_name(Verdict v);

// The tokens a node accepts.
class TokenPolicy {
 public:
  // Signed tokens made with this key (throws std::invalid_argument below kMinKeyBytes).
  void set_key(std::string key);
  // A static token (throws std::invalid_argument when it is shorter than kMinStaticTokenChars,
  // holds characters outside A-Z a-z 0-9 - . _ ~, or starts like a signed token). Only its
  // SHA-256 is kept.
  void add_static(const std::string& token);
  // Whether the node asks for a token at all (a key or at least one static token).
  bool required() const { return key_.has_value() || !static_digests_.empty(); }
  bool signed_tokens() const { return key_.has_value(); }
  size_t static_tokens() const { return static_digests_.size(); }
  // Checks `token` ("" = none given) at Unix time `now`. Without a key or static tokens every
  // request is `ok`.
  TokenCheck check(const std::string& token, int64_t now) const;

 private:
  TokenCheck check_signed(const std::string& token, int64_t now) const;
  TokenCheck check_static(const std::string& token) const;
  std::optional<std::string> key_;
  std::vector<Digest> static_digests_;
};

// A key file: its bytes with surrounding whitespace trimmed (e.g. `openssl rand -base64 48`).
// Throws std::invalid_argument when it cannot be read or is shorter than kMinKeyBytes; the
// message names the file, never its content.
std::string read_key_file(const std::string& path);
// A static token file: one token per line; blank lines and lines starting with '#' are
// skipped, surrounding whitespace trimmed. Throws std::invalid_argument (naming the file and
// line, never the token) on an unreadable file, a bad token or a file without tokens.
std::vector<std::string> read_token_file(const std::string& path);

// --- Origins --------------------------------------------------------------------------------

// An origin (RFC 6454) as a browser sends it: scheme "http" or "https", a lower-case host
// (an IPv6 address without brackets), the port (the scheme's default when absent).
struct Origin {
  std::string scheme, host;
  uint16_t port = 0;
  bool operator==(const Origin& o) const { return scheme == o.scheme && host == o.host && port == o.port; }
};
// nullopt unless `text` is exactly scheme://host[:port] (no path, user info, query or
// fragment; "null" and other schemes are not origins here).
std::optional<Origin> parse_origin(const std::string& text);

// Which page origins may open a session. Entries of `allowed-origins`:
//   "self"      the node itself: http(s)://A:P where A is the address the client connected to
//               and P the node's port (a page served by this node and opened by address);
//   "loopback"  http(s)://localhost, 127.x.x.x or [::1], any port (pages on this machine);
//   "*"         any origin (the check is off);
//   an origin   "https://app.example.com", "http://10.0.0.2:8080" (port: the scheme's default
//               when absent); a page opened by host name needs its origin listed.
// The Host header is not trusted: under DNS rebinding an attacker's page has Origin and Host
// both naming the attacker's host, so "same as Host" would let it in.
class OriginPolicy {
 public:
  // Throws std::invalid_argument naming a bad entry.
  static OriginPolicy parse(const std::vector<std::string>& entries, bool require_origin = false);
  // `origin`: the request's Origin header ("" when absent); `local_address`: the address the
  // client connected to; `local_port`: the node's port.
  bool allows(const std::string& origin, const std::string& local_address, uint16_t local_port) const;
  bool any() const { return any_; }
  bool require_origin() const { return require_origin_; }
  std::vector<std::string> describe() const;  // the entries, for the listening line

 private:
  bool any_ = false, self_ = false, loopback_ = false, require_origin_ = false;
  std::vector<Origin> listed_;
};
bool loopback_host(const std::string& host);  // "localhost", 127.0.0.0/8, ::1
// A socket address as text without IPv6's mapping of IPv4 ("::ffff:10.0.0.2" -> "10.0.0.2"),
// so that a node listening on "::" compares and counts IPv4 clients by their own address.
std::string plain_address(const std::string& address);

// --- Per-address connection counts ----------------------------------------------------------

// Open connections per client address, against a limit (0: no limit).
class AddressCounter {
 public:
  explicit AddressCounter(size_t limit = 0) : limit_(limit) {}
  // Counts one more connection from `address`; false (and nothing counted) at the limit.
  bool try_add(const std::string& address);
  void remove(const std::string& address);
  size_t count(const std::string& address) const;
  size_t limit() const { return limit_; }

 private:
  size_t limit_;
  std::map<std::string, size_t> open_;
};

}  // namespace tessera::admission
