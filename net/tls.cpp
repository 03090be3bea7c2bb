#include "net/tls.h"

#include <ctime>
#include <mutex>
#include <stdexcept>

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

namespace tessera::tls {

void CtxDeleter::operator()(SSL_CTX* ctx) const { SSL_CTX_free(ctx); }

const char* const kServerCiphers12 =
    "ECDHE-ECDSA-AES128-GCM-SHA256:ECDHE-RSA-AES128-GCM-SHA256:"
    "ECDHE-ECDSA-AES256-GCM-SHA384:ECDHE-RSA-AES256-GCM-SHA384:"
    "ECDHE-ECDSA-CHACHA20-POLY1305:ECDHE-RSA-CHACHA20-POLY1305";

std::string last_error(const std::string& fallback) {
  std::string out;
  while (unsigned long e = ERR_get_error()) {
    char buf[256];
    ERR_error_string_n(e, buf, sizeof buf);
    if (!out.empty()) out += "; ";
    out += buf;
  }
  return out.empty() ? fallback : out;
}

namespace {

CtxPtr new_context(const SSL_METHOD* method) {
  ERR_clear_error();
  CtxPtr ctx(SSL_CTX_new(method));
  if (!ctx) throw std::runtime_error("TLS: cannot make a context: " + last_error("SSL_CTX_new failed"));
  if (SSL_CTX_set_min_proto_version(ctx.get(), TLS1_2_VERSION) != 1)
    throw std::runtime_error("TLS: cannot set TLS 1.2 as the minimum: " + last_error("?"));
  SSL_CTX_set_options(ctx.get(), SSL_OP_NO_COMPRESSION | SSL_OP_NO_RENEGOTIATION);
  return ctx;
}

}  // namespace

CtxPtr server_context(const std::string& cert_file, const std::string& key_file) {
  CtxPtr ctx = new_context(TLS_server_method());
  if (SSL_CTX_set_cipher_list(ctx.get(), kServerCiphers12) != 1)
    throw std::runtime_error("TLS: cannot set the cipher list: " + last_error("?"));
  SSL_CTX_set_options(ctx.get(), SSL_OP_SINGLE_ECDH_USE);
  if (SSL_CTX_use_certificate_chain_file(ctx.get(), cert_file.c_str()) != 1)
    throw std::runtime_error("tls-cert " + cert_file + ": cannot load a PEM certificate: " + last_error("no certificate"));
  if (SSL_CTX_use_PrivateKey_file(ctx.get(), key_file.c_str(), SSL_FILETYPE_PEM) != 1) {
    // OpenSSL compares the key with the certificate as it loads it.
    const bool mismatch = ERR_GET_REASON(ERR_peek_last_error()) == X509_R_KEY_VALUES_MISMATCH;
    throw std::runtime_error("tls-key " + key_file +
                             (mismatch ? " does not belong to the certificate in " + cert_file + ": "
                                       : ": cannot load a PEM private key: ") +
                             last_error("no key"));
  }
  if (SSL_CTX_check_private_key(ctx.get()) != 1)
    throw std::runtime_error("tls-key " + key_file + " does not belong to the certificate in " + cert_file + ": " +
                             last_error("mismatch"));
  return ctx;
}

namespace {

CertInfo info_of(X509* cert) {
  CertInfo info;
  if (!cert) return info;
  if (BIO* bio = BIO_new(BIO_s_mem())) {
    if (X509_NAME_print_ex(bio, X509_get_subject_name(cert), 0, XN_FLAG_RFC2253) >= 0) {
      char* data = nullptr;
      const long n = BIO_get_mem_data(bio, &data);
      if (n > 0 && data) info.subject.assign(data, size_t(n));
    }
    BIO_free(bio);
  }
  std::tm tm{};
  if (ASN1_TIME_to_tm(X509_get0_notAfter(cert), &tm) == 1) {
    info.expires = int64_t(timegm(&tm));
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    info.not_after = buf;
  }
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  if (X509_digest(cert, EVP_sha256(), md, &n) == 1) {
    static const char* kHex = "0123456789ABCDEF";
    for (unsigned int i = 0; i < n; ++i) {
      if (i) info.sha256 += ':';
      info.sha256 += kHex[md[i] >> 4];
      info.sha256 += kHex[md[i] & 15];
    }
  }
  ERR_clear_error();
  return info;
}

}  // namespace

CertInfo peer_certificate_info(const void* ssl) {
  return info_of(ssl ? SSL_get0_peer_certificate(static_cast<const SSL*>(ssl)) : nullptr);
}

// A certificate, its chain and its key, as a loaded context holds them (references taken).
struct Identity {
  X509* cert = nullptr;
  EVP_PKEY* key = nullptr;
  STACK_OF(X509)* chain = nullptr;  // the certificates after the leaf; may be null
  CertInfo info;
  explicit Identity(SSL_CTX* ctx) {
    cert = SSL_CTX_get0_certificate(ctx);
    key = SSL_CTX_get0_privatekey(ctx);
    if (!cert || !key) throw std::runtime_error("TLS: the context holds no certificate and key");
    X509_up_ref(cert);
    EVP_PKEY_up_ref(key);
    STACK_OF(X509)* c = nullptr;
    if (SSL_CTX_get0_chain_certs(ctx, &c) == 1 && c) chain = X509_chain_up_ref(c);
    info = info_of(cert);
  }
  ~Identity() {
    X509_free(cert);
    EVP_PKEY_free(key);
    if (chain) sk_X509_pop_free(chain, X509_free);
  }
  Identity(const Identity&) = delete;
  Identity& operator=(const Identity&) = delete;
};

struct ServerContext::Installed {
  std::mutex mu;
  std::shared_ptr<const Identity> identity;
  std::shared_ptr<const Identity> get() {
    std::lock_guard<std::mutex> l(mu);
    return identity;
  }
};

namespace {

// The context's Installed, kept in its ex_data (a shared_ptr, freed with the context: the
// context may outlive its ServerContext in connections that still hold it).
int installed_index() {
  static const int index = SSL_CTX_get_ex_new_index(
      0, nullptr, nullptr, nullptr, [](void*, void* p, CRYPTO_EX_DATA*, int, long, void*) {
        delete static_cast<std::shared_ptr<ServerContext::Installed>*>(p);
      });
  return index;
}

// OpenSSL's certificate callback, on every handshake before the certificate is chosen: the
// connection presents what is installed now. Its certificates are cleared first, so that a
// reload from an ECDSA to an RSA certificate (or back) leaves no certificate of the other kind
// for OpenSSL to choose.
int present_installed(SSL* ssl, void*) {
  auto* installed =
      static_cast<std::shared_ptr<ServerContext::Installed>*>(SSL_CTX_get_ex_data(SSL_get_SSL_CTX(ssl), installed_index()));
  if (!installed || !*installed) return 0;
  const std::shared_ptr<const Identity> id = (*installed)->get();
  if (!id) return 0;
  SSL_certs_clear(ssl);
  return SSL_use_cert_and_key(ssl, id->cert, id->key, id->chain, 1) == 1 ? 1 : 0;
}

}  // namespace

ServerContext::ServerContext(const std::string& cert_file, const std::string& key_file)
    : ctx_(server_context(cert_file, key_file)), installed_(std::make_shared<Installed>()) {
  installed_->identity = std::make_shared<const Identity>(ctx_.get());
  auto* held = new std::shared_ptr<Installed>(installed_);
  if (SSL_CTX_set_ex_data(ctx_.get(), installed_index(), held) != 1) {
    delete held;
    throw std::runtime_error("TLS: cannot attach the certificate to the context: " + last_error("?"));
  }
  SSL_CTX_set_cert_cb(ctx_.get(), present_installed, nullptr);
}

CertInfo ServerContext::reload(const std::string& cert_file, const std::string& key_file) {
  CtxPtr fresh = server_context(cert_file, key_file);
  auto id = std::make_shared<const Identity>(fresh.get());
  // An expired certificate fails every browser's handshake; the installed one may still be valid.
  if (X509_cmp_current_time(X509_get0_notAfter(id->cert)) < 0)
    throw std::runtime_error("tls-cert " + cert_file + ": the certificate expired at " + id->info.not_after);
  std::lock_guard<std::mutex> l(installed_->mu);
  installed_->identity = id;
  return id->info;
}

CertInfo ServerContext::current() const { return installed_->get()->info; }

CtxPtr client_context(const std::string& ca_file) {
  CtxPtr ctx = new_context(TLS_client_method());
  if (ca_file.empty()) {
    SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_NONE, nullptr);
  } else if (ca_file == kSystemCas) {
    if (SSL_CTX_set_default_verify_paths(ctx.get()) != 1)
      throw std::runtime_error("the system's CA certificates: " + last_error("cannot load"));
    SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_PEER, nullptr);
  } else {
    if (SSL_CTX_load_verify_locations(ctx.get(), ca_file.c_str(), nullptr) != 1)
      throw std::runtime_error("TLS CA file " + ca_file + ": " + last_error("cannot load"));
    SSL_CTX_set_verify(ctx.get(), SSL_VERIFY_PEER, nullptr);
  }
  return ctx;
}

void expect_host(void* ssl, const std::string& host) {
  X509_VERIFY_PARAM* param = SSL_get0_param(static_cast<SSL*>(ssl));
  if (X509_VERIFY_PARAM_set1_ip_asc(param, host.c_str()) != 1) {  // not an IP address: a name
    ERR_clear_error();
    X509_VERIFY_PARAM_set1_host(param, host.c_str(), 0);
  }
}

std::string describe_session(const void* ssl) {
  auto* s = static_cast<SSL*>(const_cast<void*>(ssl));
  if (!s) return "";
  const char* version = SSL_get_version(s);
  const SSL_CIPHER* c = SSL_get_current_cipher(s);
  return std::string(version ? version : "?") + " " + (c ? SSL_CIPHER_get_name(c) : "?");
}

}  // namespace tessera::tls
