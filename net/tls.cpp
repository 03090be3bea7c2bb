#include "net/tls.h"

#include <stdexcept>

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
