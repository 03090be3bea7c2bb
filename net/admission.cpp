// Session admission: tokens, origins, per-address counts. See admission.h.
#include "net/admission.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/sha.h>

namespace tessera::admission {

namespace {

constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

int alphabet_index(char c) {
  if (c >= 'A' && c <= 'Z') return c - 'A';
  if (c >= 'a' && c <= 'z') return c - 'a' + 26;
  if (c >= '0' && c <= '9') return c - '0' + 52;
  if (c == '-') return 62;
  if (c == '_') return 63;
  return -1;
}

std::string trim(const std::string& s) {
  const char* ws = " \t\r\n\f\v";
  size_t a = s.find_first_not_of(ws), b = s.find_last_not_of(ws);
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool all_digits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// The URL-safe characters of RFC 3986 ("unreserved"): a token made of them goes into a query
// string as it is, and comes back unchanged.
bool unreserved(const std::string& s) {
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.' || c == '_' || c == '~';
  });
}

const std::string kSignedPrefix = std::string(kTokenVersion) + ".";

// Why a static token is not acceptable, or nullptr.
const char* static_token_problem(const std::string& token) {
  if (token.size() < kMinStaticTokenChars) return "a static token needs at least 16 characters";
  if (token.size() > kMaxTokenChars) return "a static token has at most 1024 characters";
  if (!unreserved(token)) return "a static token holds only A-Z a-z 0-9 - . _ ~";
  if (token.rfind(kSignedPrefix, 0) == 0) return "a static token must not start with \"tsr1.\" (signed tokens do)";
  return nullptr;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> parts;
  size_t at = 0;
  while (true) {
    size_t next = s.find(sep, at);
    parts.push_back(s.substr(at, next == std::string::npos ? std::string::npos : next - at));
    if (next == std::string::npos) return parts;
    at = next + 1;
  }
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument("cannot read " + path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

// --- Encoding and MACs ----------------------------------------------------------------------

std::string base64url_encode(const uint8_t* data, size_t size) {
  std::string out;
  out.reserve((size * 4 + 2) / 3);
  for (size_t i = 0; i < size; i += 3) {
    const uint32_t n = uint32_t(data[i]) << 16 | (i + 1 < size ? uint32_t(data[i + 1]) << 8 : 0) |
                       (i + 2 < size ? uint32_t(data[i + 2]) : 0);
    const size_t chars = std::min<size_t>(4, (size - i) * 4 / 3 + ((size - i) % 3 != 0));
    for (size_t k = 0; k < chars; ++k) out += kAlphabet[(n >> (18 - 6 * k)) & 63];
  }
  return out;
}

std::string base64url_encode(const std::string& bytes) {
  return base64url_encode(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
}

std::optional<std::string> base64url_decode(const std::string& text) {
  if (text.size() % 4 == 1) return std::nullopt;
  std::string out;
  uint32_t bits = 0;
  int held = 0;
  for (char c : text) {
    const int v = alphabet_index(c);
    if (v < 0) return std::nullopt;
    bits = (bits << 6) | uint32_t(v);
    held += 6;
    if (held >= 8) {
      held -= 8;
      out += char((bits >> held) & 0xff);
    }
  }
  // Left-over bits must be zero: each byte string has exactly one encoding, so two tokens
  // that differ in their text never carry the same bytes.
  if (held > 0 && (bits & ((1u << held) - 1)) != 0) return std::nullopt;
  return out;
}

Digest hmac_sha256(const std::string& key, const std::string& message) {
  Digest d{};
  unsigned int len = 0;
  HMAC(EVP_sha256(), key.data(), int(key.size()), reinterpret_cast<const unsigned char*>(message.data()),
       message.size(), d.data(), &len);
  return d;
}

Digest sha256(const std::string& bytes) {
  Digest d{};
  SHA256(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), d.data());
  return d;
}

bool same_digest(const Digest& a, const Digest& b) { return CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0; }

// --- Tokens ---------------------------------------------------------------------------------

std::string make_token(const std::string& key, int64_t expiry, const std::string& subject) {
  if (key.size() < kMinKeyBytes)
    throw std::invalid_argument("the key has " + std::to_string(key.size()) + " bytes; at least " +
                                std::to_string(kMinKeyBytes) + " are needed");
  if (subject.size() > kMaxSubjectBytes)
    throw std::invalid_argument("the subject has more than " + std::to_string(kMaxSubjectBytes) + " bytes");
  if (expiry < 0 || expiry > 999'999'999'999) throw std::invalid_argument("the expiry is out of range");
  const std::string body = kSignedPrefix + std::to_string(expiry) + "." + base64url_encode(subject);
  const Digest mac = hmac_sha256(key, body);
  return body + "." + base64url_encode(mac.data(), mac.size());
}

const char* verdict_name(Verdict v) {
  switch (v) {
    case Verdict::ok: return "ok";
    case Verdict::missing: return "missing";
    case Verdict::malformed: return "malformed";
    case Verdict::bad_signature: return "bad signature";
    case Verdict::unknown: return "unknown token";
    case Verdict::expired: return "expired";
  }
  return "unknown";
}

void TokenPolicy::set_key(std::string key) {
  if (key.size() < kMinKeyBytes)
    throw std::invalid_argument("the token key has " + std::to_string(key.size()) + " bytes; at least " +
                                std::to_string(kMinKeyBytes) + " are needed");
  key_ = std::move(key);
}

void TokenPolicy::add_static(const std::string& token) {
  if (const char* problem = static_token_problem(token)) throw std::invalid_argument(problem);
  static_digests_.push_back(sha256(token));
}

TokenCheck TokenPolicy::check(const std::string& token, int64_t now) const {
  if (!required()) return {Verdict::ok, "", 0};
  if (token.empty()) return {Verdict::missing, "", 0};
  if (token.size() > kMaxTokenChars) return {Verdict::malformed, "", 0};
  if (token.rfind(kSignedPrefix, 0) == 0) return key_ ? check_signed(token, now) : TokenCheck{Verdict::unknown, "", 0};
  if (!static_digests_.empty()) return check_static(token);
  return {Verdict::malformed, "", 0};  // only signed tokens are taken here
}

// The MAC is checked before anything the token claims, so a forged token learns nothing
// (not even whether its expiry would have passed).
TokenCheck TokenPolicy::check_signed(const std::string& token, int64_t now) const {
  const std::vector<std::string> parts = split(token, '.');
  if (parts.size() != 4 || !all_digits(parts[1]) || parts[1].size() > 12) return {Verdict::malformed, "", 0};
  const auto subject = base64url_decode(parts[2]);
  const auto mac = base64url_decode(parts[3]);
  if (!subject || !mac || mac->size() != Digest().size() || subject->size() > kMaxSubjectBytes)
    return {Verdict::malformed, "", 0};
  Digest given;
  std::copy(mac->begin(), mac->end(), given.begin());
  const Digest want = hmac_sha256(*key_, token.substr(0, token.rfind('.')));
  if (!same_digest(given, want)) return {Verdict::bad_signature, "", 0};
  const int64_t expiry = std::stoll(parts[1]);
  if (now > expiry + kClockSkewSeconds) return {Verdict::expired, *subject, expiry};
  return {Verdict::ok, *subject, expiry};
}

// Every stored digest is compared, whichever matches: the time taken does not say which
// token (or how much of one) was right. Comparing digests rather than the tokens also hides
// their lengths.
TokenCheck TokenPolicy::check_static(const std::string& token) const {
  const Digest given = sha256(token);
  bool found = false;
  for (const Digest& d : static_digests_) found |= same_digest(given, d);
  return {found ? Verdict::ok : Verdict::unknown, "", 0};
}

std::string read_key_file(const std::string& path) {
  const std::string key = trim(read_file(path));
  if (key.size() < kMinKeyBytes)
    throw std::invalid_argument("the key in " + path + " has " + std::to_string(key.size()) +
                                " bytes; at least " + std::to_string(kMinKeyBytes) +
                                " are needed (e.g. openssl rand -base64 48 > " + path + ")");
  return key;
}

std::vector<std::string> read_token_file(const std::string& path) {
  std::istringstream in(read_file(path));
  std::vector<std::string> tokens;
  std::string line;
  for (size_t number = 1; std::getline(in, line); ++number) {
    const std::string token = trim(line);
    if (token.empty() || token[0] == '#') continue;
    if (const char* problem = static_token_problem(token))
      throw std::invalid_argument(path + " line " + std::to_string(number) + ": " + problem);
    tokens.push_back(token);
  }
  if (tokens.empty()) throw std::invalid_argument(path + " holds no token");
  return tokens;
}

// --- Origins --------------------------------------------------------------------------------

std::optional<Origin> parse_origin(const std::string& text) {
  const size_t sep = text.find("://");
  if (sep == std::string::npos) return std::nullopt;
  Origin o;
  o.scheme = lower(text.substr(0, sep));
  if (o.scheme != "http" && o.scheme != "https") return std::nullopt;
  std::string rest = lower(text.substr(sep + 3)), port;
  if (!rest.empty() && rest[0] == '[') {  // an IPv6 literal
    const size_t close = rest.find(']');
    if (close == std::string::npos) return std::nullopt;
    o.host = rest.substr(1, close - 1);
    if (o.host.empty() || o.host.find_first_not_of("0123456789abcdef:.") != std::string::npos) return std::nullopt;
    rest = rest.substr(close + 1);
    if (!rest.empty() && rest[0] != ':') return std::nullopt;
    if (!rest.empty()) port = rest.substr(1);
  } else {
    const size_t colon = rest.find(':');
    o.host = rest.substr(0, colon);
    if (o.host.empty() || o.host.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789.-") != std::string::npos)
      return std::nullopt;
    if (colon != std::string::npos) port = rest.substr(colon + 1);
  }
  if (port.empty()) {
    o.port = o.scheme == "https" ? 443 : 80;
    return o;
  }
  if (!all_digits(port) || port.size() > 5 || std::stoi(port) < 1 || std::stoi(port) > 65535) return std::nullopt;
  o.port = uint16_t(std::stoi(port));
  return o;
}

bool loopback_host(const std::string& host) {
  if (host == "localhost" || host == "::1") return true;
  const std::vector<std::string> octets = split(host, '.');
  if (octets.size() != 4 || octets[0] != "127") return false;
  return std::all_of(octets.begin(), octets.end(),
                     [](const std::string& o) { return all_digits(o) && o.size() <= 3 && std::stoi(o) <= 255; });
}

std::string plain_address(const std::string& address) {
  const std::string mapped = "::ffff:";
  if (address.size() > mapped.size() && lower(address.substr(0, mapped.size())) == mapped &&
      address.find('.') != std::string::npos)
    return address.substr(mapped.size());
  return address;
}

OriginPolicy OriginPolicy::parse(const std::vector<std::string>& entries, bool require_origin) {
  OriginPolicy p;
  p.require_origin_ = require_origin;
  for (const std::string& e : entries) {
    if (e == "*") {
      p.any_ = true;
    } else if (e == "self") {
      p.self_ = true;
    } else if (e == "loopback") {
      p.loopback_ = true;
    } else if (auto o = parse_origin(e)) {
      p.listed_.push_back(*o);
    } else {
      throw std::invalid_argument("tessera.allowed-origins: '" + e +
                                  "' is not \"self\", \"loopback\", \"*\" or an origin such as "
                                  "\"https://app.example.com\" (scheme://host[:port], no path)");
    }
  }
  return p;
}

bool OriginPolicy::allows(const std::string& origin, const std::string& local_address, uint16_t local_port) const {
  if (origin.empty()) return !require_origin_;
  if (any_) return true;
  const auto o = parse_origin(origin);
  if (!o) return false;  // "null" (sandboxed frames, file: pages) and anything malformed
  if (loopback_ && loopback_host(o->host)) return true;
  if (self_ && o->host == lower(plain_address(local_address)) && o->port == local_port) return true;
  return std::find(listed_.begin(), listed_.end(), *o) != listed_.end();
}

std::vector<std::string> OriginPolicy::describe() const {
  std::vector<std::string> out;
  if (any_) out.push_back("*");
  if (self_) out.push_back("self");
  if (loopback_) out.push_back("loopback");
  for (const Origin& o : listed_) {
    const bool v6 = o.host.find(':') != std::string::npos;
    out.push_back(o.scheme + "://" + (v6 ? "[" + o.host + "]" : o.host) + ":" + std::to_string(o.port));
  }
  return out;
}

// --- Per-address connection counts ----------------------------------------------------------

bool AddressCounter::try_add(const std::string& address) {
  size_t& n = open_[address];
  if (limit_ > 0 && n >= limit_) return false;
  ++n;
  return true;
}

void AddressCounter::remove(const std::string& address) {
  auto it = open_.find(address);
  if (it == open_.end()) return;
  if (--it->second == 0) open_.erase(it);
}

size_t AddressCounter::count(const std::string& address) const {
  auto it = open_.find(address);
  return it == open_.end() ? 0 : it->second;
}

}  // namespace tessera::admission
