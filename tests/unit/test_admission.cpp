// Session admission's pure code (net/admission.h): base64url and HMAC-SHA256 against published
// vectors, signed tokens (expiry, clock skew, tampering), static tokens, the origin
// allow-list and per-address counts.
#include <catch2/catch.hpp>

#include <cstdio>
#include <fstream>

#include <unistd.h>

#include "net/admission.h"

using namespace tessera::admission;

namespace {

std::string hex(const Digest& d) {
  static const char* digits = "0123456789abcdef";
  std::string s;
  for (uint8_t b : d) {
    s += digits[b >> 4];
    s += digits[b & 15];
  }
  return s;
}

const std::string kKey = "0123456789abcdef0123456789abcdef-test-key";
constexpr int64_t kNow = 1'800'000'000;

// A file in /tmp with `text`, removed at the end of the scope.
struct TempFile {
  std::string path;
  explicit TempFile(const std::string& text) {
    path = "/tmp/tessera-test-access-" + std::to_string(getpid()) + "-" + std::to_string(counter()++);
    std::ofstream(path, std::ios::binary) << text;
  }
  ~TempFile() { std::remove(path.c_str()); }
  static int& counter() {
    static int n = 0;
    return n;
  }
};

}  // namespace

TEST_CASE("base64url encodes and decodes the RFC 4648 vectors, without padding", "[unit]") {
  const std::pair<const char*, const char*> vectors[] = {{"", ""},          {"f", "Zg"},         {"fo", "Zm8"},
                                                         {"foo", "Zm9v"},   {"foob", "Zm9vYg"}, {"fooba", "Zm9vYmE"},
                                                         {"foobar", "Zm9vYmFy"}};
  for (auto [plain, coded] : vectors) {
    CHECK(base64url_encode(plain) == coded);
    CHECK(base64url_decode(coded) == std::string(plain));
  }
  CHECK(base64url_encode(std::string("\xfb\xff", 2)) == "-_8");  // the URL-safe letters
  CHECK(base64url_decode("-_8") == std::string("\xfb\xff", 2));
  for (const char* bad : {"Zg==", "Z", "Zm9v+", "Zm9v/", "Zh", "Zm9"})  // padding, length 4k+1, other alphabet, stray bits
    CHECK_FALSE(base64url_decode(bad));
}

TEST_CASE("HMAC-SHA256 and SHA-256 give the published test vectors", "[unit]") {
  // RFC 4231, test cases 1 and 2; FIPS 180-2's "abc".
  CHECK(hex(hmac_sha256(std::string(20, '\x0b'), "Hi There")) ==
        "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7");
  CHECK(hex(hmac_sha256("Jefe", "what do ya want for nothing?")) ==
        "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843");
  CHECK(hex(sha256("abc")) == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  Digest a = sha256("x"), b = a;
  CHECK(same_digest(a, b));
  b[31] ^= 1;
  CHECK_FALSE(same_digest(a, b));
}

TEST_CASE("A signed token is accepted until its expiry plus the clock skew, and carries its subject", "[unit]") {
  TokenPolicy p;
  p.set_key(kKey);
  const std::string t = make_token(kKey, kNow + 300, "alice@example.com");
  CHECK(t.rfind("tsr1.1800000300.", 0) == 0);
  auto ok = p.check(t, kNow);
  CHECK(ok.verdict == Verdict::ok);
  CHECK(ok.subject == "alice@example.com");
  CHECK(ok.expiry == kNow + 300);
  CHECK(p.check(t, kNow + 300 + kClockSkewSeconds).verdict == Verdict::ok);
  auto late = p.check(t, kNow + 300 + kClockSkewSeconds + 1);
  CHECK(late.verdict == Verdict::expired);
  CHECK(late.subject == "alice@example.com");
  // A subject of any bytes, and none.
  CHECK(p.check(make_token(kKey, kNow + 1, std::string("a.b\n\"c\0", 7)), kNow).subject == std::string("a.b\n\"c\0", 7));
  CHECK(p.check(make_token(kKey, kNow + 1), kNow).verdict == Verdict::ok);
}

TEST_CASE("A tampered, foreign or malformed signed token is refused before its expiry is read", "[unit]") {
  TokenPolicy p;
  p.set_key(kKey);
  const std::string t = make_token(kKey, kNow + 300, "alice");
  const auto dot1 = t.find('.', 5), dot2 = t.rfind('.');
  // A later expiry, another subject, another key, a flipped MAC character: bad signature.
  std::string later = t;
  later.replace(5, dot1 - 5, std::to_string(kNow + 999999));
  CHECK(p.check(later, kNow).verdict == Verdict::bad_signature);
  std::string other_subject = t.substr(0, dot1 + 1) + base64url_encode("mallory") + t.substr(dot2);
  CHECK(p.check(other_subject, kNow).verdict == Verdict::bad_signature);
  CHECK(p.check(make_token(kKey + "x", kNow + 300, "alice"), kNow).verdict == Verdict::bad_signature);
  std::string flipped = t;
  flipped[dot2 + 1] = flipped[dot2 + 1] == 'A' ? 'B' : 'A';
  CHECK(p.check(flipped, kNow).verdict == Verdict::bad_signature);
  // An expired token with a bad MAC says "bad signature", not "expired".
  std::string old = make_token(kKey + "x", kNow - 3600, "alice");
  CHECK(p.check(old, kNow).verdict == Verdict::bad_signature);
  for (const std::string& bad : {std::string("tsr1."), std::string("tsr1.1.2"), t + ".x", t.substr(0, t.size() - 1),
                                 std::string("tsr1.-5.") + t.substr(dot1 + 1), std::string("tsr1.x.") + t.substr(dot1 + 1),
                                 std::string("tsr1.1800000300.!!.") + t.substr(dot2 + 1), std::string("hello-world-token"),
                                 std::string(kMaxTokenChars + 1, 'a')})
    CHECK(p.check(bad, kNow).verdict == Verdict::malformed);
  CHECK(p.check("", kNow).verdict == Verdict::missing);
}

TEST_CASE("Static tokens are compared by digest; no token configured asks for none", "[unit]") {
  TokenPolicy none;
  CHECK_FALSE(none.required());
  CHECK(none.check("", kNow).verdict == Verdict::ok);
  CHECK(none.check("anything", kNow).verdict == Verdict::ok);

  TokenPolicy p;
  p.add_static("static-token-0123456789");
  p.add_static("another.token_~-0123");
  CHECK(p.required());
  CHECK_FALSE(p.signed_tokens());
  CHECK(p.check("static-token-0123456789", kNow).verdict == Verdict::ok);
  CHECK(p.check("another.token_~-0123", kNow).verdict == Verdict::ok);
  CHECK(p.check("static-token-012345678", kNow).verdict == Verdict::unknown);
  CHECK(p.check("static-token-01234567890", kNow).verdict == Verdict::unknown);
  CHECK(p.check(make_token(kKey, kNow + 60), kNow).verdict == Verdict::unknown);  // no key here
  CHECK(p.check("", kNow).verdict == Verdict::missing);
  for (const char* bad : {"short", "has space in the token", "tsr1.looks-signed-token", "percent%20encoded-token"})
    CHECK_THROWS_AS(p.add_static(bad), std::invalid_argument);
  CHECK_THROWS_AS(p.set_key("too short"), std::invalid_argument);
  CHECK_THROWS_AS(make_token("too short", kNow), std::invalid_argument);
  CHECK_THROWS_AS(make_token(kKey, kNow, std::string(kMaxSubjectBytes + 1, 's')), std::invalid_argument);

  // Both kinds on one node.
  p.set_key(kKey);
  CHECK(p.check(make_token(kKey, kNow + 60), kNow).verdict == Verdict::ok);
  CHECK(p.check("static-token-0123456789", kNow).verdict == Verdict::ok);
}

TEST_CASE("Key and token files: trimmed, commented, and errors that never quote a secret", "[unit]") {
  TempFile key("  " + kKey + "\n");
  CHECK(read_key_file(key.path) == kKey);
  TempFile short_key("tiny-secret-key\n");
  try {
    read_key_file(short_key.path);
    FAIL("a short key was taken");
  } catch (const std::invalid_argument& e) {
    CHECK(std::string(e.what()).find(short_key.path) != std::string::npos);
    CHECK(std::string(e.what()).find("tiny-secret-key") == std::string::npos);
  }
  CHECK_THROWS_AS(read_key_file("/nonexistent/tessera.key"), std::invalid_argument);

  TempFile tokens("# operators' tokens\n\nfirst-static-token-0001\n  second-static-token-02  \r\n");
  CHECK(read_token_file(tokens.path) == std::vector<std::string>{"first-static-token-0001", "second-static-token-02"});
  TempFile bad("first-static-token-0001\nsecret with spaces in it\n");
  try {
    read_token_file(bad.path);
    FAIL("a bad token was taken");
  } catch (const std::invalid_argument& e) {
    CHECK(std::string(e.what()).find("line 2") != std::string::npos);
    CHECK(std::string(e.what()).find("secret") == std::string::npos);
  }
  TempFile empty("# nothing\n");
  CHECK_THROWS_AS(read_token_file(empty.path), std::invalid_argument);
}

TEST_CASE("Origins parse as browsers send them", "[unit]") {
  auto o = parse_origin("HTTPS://App.Example.com");
  REQUIRE(o);
  CHECK(o->scheme == "https");
  CHECK(o->host == "app.example.com");
  CHECK(o->port == 443);
  CHECK(parse_origin("http://10.0.0.2:8080")->port == 8080);
  CHECK(parse_origin("http://[::1]:9000")->host == "::1");
  CHECK(parse_origin("http://a.example") == parse_origin("http://a.example:80"));
  for (const char* bad : {"null", "", "file://", "ftp://a.example", "http://", "http://a.example/", "http://a.example/x",
                          "http://user@a.example", "http://a.example:0", "http://a.example:65536", "http://a.example:x",
                          "http://[::1", "http://[::1]x", "http://a b", "a.example"})
    CHECK_FALSE(parse_origin(bad));
}

TEST_CASE("The default origin policy takes the node's own origin and loopback pages, nothing else", "[unit]") {
  const auto p = OriginPolicy::parse({"self", "loopback"});
  // A node on 10.0.0.2:8080, its page opened by address.
  CHECK(p.allows("http://10.0.0.2:8080", "10.0.0.2", 8080));
  CHECK(p.allows("https://10.0.0.2:8080", "10.0.0.2", 8080));
  CHECK(p.allows("http://10.0.0.2:8080", "::ffff:10.0.0.2", 8080));  // a node listening on "::"
  CHECK_FALSE(p.allows("http://10.0.0.2:9999", "10.0.0.2", 8080));
  CHECK_FALSE(p.allows("http://10.0.0.3:8080", "10.0.0.2", 8080));
  // Pages on this machine.
  for (const char* local : {"http://localhost:3000", "http://127.0.0.1:8080", "https://127.1.2.3", "http://[::1]:8080"})
    CHECK(p.allows(local, "10.0.0.2", 8080));
  // Foreign pages, including a DNS-rebound name and the opaque origin of sandboxed frames.
  for (const char* foreign : {"http://evil.example", "http://evil.example:8080", "http://localhost.evil.example",
                              "http://127.0.0.1.evil.example", "null", "http://128.0.0.1:8080", "garbage"})
    CHECK_FALSE(p.allows(foreign, "127.0.0.1", 8080));
  // No Origin header: not a browser (tessera loadtest, curl); allowed unless asked otherwise.
  CHECK(p.allows("", "127.0.0.1", 8080));
  CHECK_FALSE(OriginPolicy::parse({"self", "loopback"}, true).allows("", "127.0.0.1", 8080));
}

TEST_CASE("allowed-origins lists origins, or '*' for any; bad entries are errors", "[unit]") {
  const auto listed = OriginPolicy::parse({"https://app.example.com", "http://10.0.0.2:8080"});
  CHECK(listed.allows("https://app.example.com", "10.0.0.9", 8080));
  CHECK(listed.allows("https://app.example.com:443", "10.0.0.9", 8080));
  CHECK(listed.allows("http://10.0.0.2:8080", "10.0.0.9", 8080));
  CHECK_FALSE(listed.allows("http://app.example.com", "10.0.0.9", 8080));  // another scheme
  CHECK_FALSE(listed.allows("http://localhost:8080", "10.0.0.9", 8080));   // loopback not listed
  CHECK_FALSE(listed.allows("http://10.0.0.9:8080", "10.0.0.9", 8080));    // self not listed
  CHECK(listed.describe() == std::vector<std::string>{"https://app.example.com:443", "http://10.0.0.2:8080"});
  const auto any = OriginPolicy::parse({"*"});
  CHECK(any.allows("http://evil.example", "127.0.0.1", 8080));
  CHECK(any.allows("null", "127.0.0.1", 8080));
  for (const char* bad : {"app.example.com", "https://app.example.com/", "self ", "null", ""})
    CHECK_THROWS_AS(OriginPolicy::parse({bad}), std::invalid_argument);
  CHECK_FALSE(loopback_host("localhost.evil.example"));
  CHECK(loopback_host("127.255.0.1"));
  CHECK_FALSE(loopback_host("127.0.0.256"));
}

TEST_CASE("Per-address counts refuse the connection past the limit and free slots on close", "[unit]") {
  AddressCounter c(2);
  CHECK(c.try_add("10.0.0.1"));
  CHECK(c.try_add("10.0.0.1"));
  CHECK_FALSE(c.try_add("10.0.0.1"));
  CHECK(c.count("10.0.0.1") == 2);
  CHECK(c.try_add("10.0.0.2"));  // another address is not affected
  c.remove("10.0.0.1");
  CHECK(c.try_add("10.0.0.1"));
  c.remove("10.0.0.9");  // never counted: nothing happens
  CHECK(c.count("10.0.0.9") == 0);
  AddressCounter unlimited;
  for (int i = 0; i < 100; ++i) CHECK(unlimited.try_add("10.0.0.1"));
}
