#pragma once
// TLS for the node's one port (HTTPS and WSS; docs/operations.md, "TLS"): the OpenSSL
// contexts of the server (net/server.cpp) and of our own clients (net/ws_client.cpp, the
// HTTP client of net/http.h). Plain OpenSSL, no websocketpp: websocketpp's asio TLS config
// adopts the context made here.
//
// The server's policy: TLS 1.2 and 1.3 only; for TLS 1.2 only ECDHE key exchange with AEAD
// ciphers (AES-GCM, ChaCha20-Poly1305), as Mozilla's "intermediate" profile without its
// finite-field DHE suites; no compression, no renegotiation.
#include <cstdint>
#include <memory>
#include <string>

typedef struct ssl_ctx_st SSL_CTX;

namespace tessera::tls {

struct CtxDeleter {
  void operator()(SSL_CTX* ctx) const;
};
using CtxPtr = std::unique_ptr<SSL_CTX, CtxDeleter>;

// The TLS 1.2 cipher list of the server (TLS 1.3 suites are OpenSSL's, all AEAD).
extern const char* const kServerCiphers12;

// A server context from a PEM certificate (chain: the leaf first) and its PEM private key.
// Throws std::runtime_error naming the file and OpenSSL's reason when a file is missing,
// unreadable, not PEM, or the key does not belong to the certificate.
CtxPtr server_context(const std::string& cert_file, const std::string& key_file);

// What a log line may say of a certificate (never anything of its key).
struct CertInfo {
  std::string subject;    // RFC 2253: "O=Tessera node (self-signed),CN=localhost"
  std::string not_after;  // "2028-04-01T12:00:00Z"
  int64_t expires = 0;    // not_after as Unix time
  std::string sha256;     // SHA-256 of the DER certificate, "AB:CD:…" (as `openssl x509 -fingerprint -sha256`)
};
// The certificate the peer presented on an established connection (`ssl`: its SSL*).
CertInfo peer_certificate_info(const void* ssl);

// The server's context, whose certificate and key can be replaced while it serves (certificate
// reload, docs/operations.md "TLS"). Connections are made from one context whose settings never
// change; each TLS handshake (OpenSSL's certificate callback) presents the certificate, chain and
// key installed last, so connections accepted after a reload present the new certificate even
// when their SSL object was made before it, and established connections keep theirs.
// Thread-safe: reload may run on any thread while handshakes run on the network thread.
class ServerContext {
 public:
  // Loads the files as server_context does (and throws as it does).
  ServerContext(const std::string& cert_file, const std::string& key_file);
  // The context connections are made from; owned here (SSL_CTX_up_ref to share it).
  SSL_CTX* native() const { return ctx_.get(); }
  // Loads the files into a new context as at start and installs its certificate: later
  // handshakes present it. Throws std::runtime_error as server_context does, or when the
  // certificate has expired; the installed certificate stays then.
  CertInfo reload(const std::string& cert_file, const std::string& key_file);
  CertInfo current() const;

  struct Installed;  // the certificate handshakes present (tls.cpp)

 private:
  CtxPtr ctx_;
  std::shared_ptr<Installed> installed_;
};

// A client context with the same protocol floor. ca_file empty: the peer's certificate is
// not verified (tests and load tests against a self-signed node); else it must chain to a
// certificate in ca_file, and the host name is checked by the caller (verify_host).
// kSystemCas: the system's CA certificates (OpenSSL's default paths, Debian's ca-certificates).
CtxPtr client_context(const std::string& ca_file);
inline const std::string kSystemCas = "system";

// Makes a verifying client's handshake also check that the certificate names `host` (a DNS
// name, or an IP address against the certificate's IP entries). `ssl` is the connection's SSL*.
void expect_host(void* ssl, const std::string& host);

// OpenSSL's error queue as one line (and cleared); `fallback` when empty.
std::string last_error(const std::string& fallback);

// "TLSv1.3 TLS_AES_256_GCM_SHA384" of an established connection's SSL* (void* to keep
// OpenSSL's headers out of the callers).
std::string describe_session(const void* ssl);

}  // namespace tessera::tls
