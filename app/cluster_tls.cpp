#include "app/cluster_tls.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <stdexcept>

#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <unistd.h>

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include "net/tls.h"

namespace tessera::app {

namespace {

[[noreturn]] void fail(const char* setting, const std::string& path, const std::string& what) {
  throw std::invalid_argument(std::string("tessera.") + setting + ": " + path + ": " + what);
}

void require_readable(const char* setting, const std::string& path) {
  if (path.empty()) fail(setting, "(empty)", "no file named");
  std::FILE* f = std::fopen(path.c_str(), "r");
  if (!f) fail(setting, path, std::string("cannot read it: ") + std::strerror(errno));
  std::fclose(f);
  struct stat st;
  if (stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) fail(setting, path, "is not a regular file");
}

// A certificate's subject as one line ("CN=w1, O=Tessera cluster").
std::string subject_of(X509* cert) {
  std::unique_ptr<BIO, decltype(&BIO_free)> bio(BIO_new(BIO_s_mem()), BIO_free);
  if (!bio || X509_NAME_print_ex(bio.get(), X509_get_subject_name(cert), 0, XN_FLAG_ONELINE & ~ASN1_STRFLGS_ESC_MSB) < 0)
    return "?";
  char* data = nullptr;
  long n = BIO_get_mem_data(bio.get(), &data);
  return std::string(data, size_t(n));
}

// Verifies `cert` (with the chain file's further certificates) against the context's trusted
// CA store for one TLS purpose ("ssl_server" or "ssl_client"): X509_V_OK or the error code.
int verify_for(SSL_CTX* ctx, X509* cert, const char* purpose) {
  STACK_OF(X509)* chain = nullptr;
  SSL_CTX_get0_chain_certs(ctx, &chain);
  std::unique_ptr<X509_STORE_CTX, decltype(&X509_STORE_CTX_free)> v(X509_STORE_CTX_new(), X509_STORE_CTX_free);
  if (!v || X509_STORE_CTX_init(v.get(), SSL_CTX_get_cert_store(ctx), cert, chain) != 1)
    throw std::runtime_error("cannot make an OpenSSL verification context: " + tls::last_error(""));
  X509_STORE_CTX_set_default(v.get(), purpose);
  const int ok = X509_verify_cert(v.get());
  const int err = X509_STORE_CTX_get_error(v.get());
  ERR_clear_error();
  return ok == 1 ? X509_V_OK : (err != X509_V_OK ? err : X509_V_ERR_UNSPECIFIED);
}

// A verification callback that keeps the subject of the peer's own certificate in the
// std::string of the SSL's app data, and changes no verdict.
int note_peer(int ok, X509_STORE_CTX* store) {
  auto* ssl = static_cast<SSL*>(X509_STORE_CTX_get_ex_data(store, SSL_get_ex_data_X509_STORE_CTX_idx()));
  X509* cert = X509_STORE_CTX_get0_cert(store);
  if (ssl && cert)
    if (auto* out = static_cast<std::string*>(SSL_get_app_data(ssl))) *out = subject_of(cert);
  return ok;
}

// The key file's content is never read into a message: no passphrase prompt on the terminal
// either (an encrypted key fails to load instead).
int no_passphrase(char*, int, int, void*) { return 0; }

}  // namespace

std::vector<std::string> check_cluster_tls(const ClusterTlsFiles& f) {
  std::vector<std::string> warnings;
  require_readable("cluster-tls-cert", f.cert);
  require_readable("cluster-tls-key", f.key);
  require_readable("cluster-tls-ca", f.ca);
  ERR_clear_error();
  // The same calls as CAF's OpenSSL session (libcaf_openssl, session::create_ssl_context).
  tls::CtxPtr ctx(SSL_CTX_new(TLS_method()));
  if (!ctx) throw std::runtime_error("cannot make an OpenSSL context: " + tls::last_error(""));
  SSL_CTX_set_default_passwd_cb(ctx.get(), no_passphrase);
  if (SSL_CTX_use_certificate_chain_file(ctx.get(), f.cert.c_str()) != 1)
    fail("cluster-tls-cert", f.cert, "holds no PEM certificate OpenSSL accepts (" + tls::last_error("") + ")");
  if (SSL_CTX_use_PrivateKey_file(ctx.get(), f.key.c_str(), SSL_FILETYPE_PEM) != 1) {
    const unsigned long e = ERR_peek_last_error();
    if (ERR_GET_LIB(e) == ERR_LIB_X509 && ERR_GET_REASON(e) == X509_R_KEY_VALUES_MISMATCH)
      fail("cluster-tls-key", f.key, "is not the key of the certificate " + f.cert + " (" + tls::last_error("") + ")");
    fail("cluster-tls-key", f.key,
         "holds no unencrypted PEM private key OpenSSL accepts (encrypted keys are not supported; " + tls::last_error("") +
             ")");
  }
  if (SSL_CTX_check_private_key(ctx.get()) != 1)
    fail("cluster-tls-key", f.key, "is not the key of the certificate " + f.cert + " (" + tls::last_error("") + ")");
  if (SSL_CTX_load_verify_locations(ctx.get(), f.ca.c_str(), nullptr) != 1)
    fail("cluster-tls-ca", f.ca, "holds no PEM certificate OpenSSL accepts (" + tls::last_error("") + ")");

  // The CA must have signed this node's certificate for both ends of a connection: a node
  // accepts its parents (TLS server) and connects to its children (TLS client).
  X509* cert = SSL_CTX_get0_certificate(ctx.get());
  for (const char* purpose : {"ssl_server", "ssl_client"}) {
    const int err = verify_for(ctx.get(), cert, purpose);
    if (err == X509_V_OK) continue;
    std::string why = X509_verify_cert_error_string(err);
    std::string what;
    switch (err) {
      case X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT_LOCALLY:
      case X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT:
      case X509_V_ERR_DEPTH_ZERO_SELF_SIGNED_CERT:
      case X509_V_ERR_SELF_SIGNED_CERT_IN_CHAIN:
      case X509_V_ERR_CERT_SIGNATURE_FAILURE:
        what = "was not signed by the CA of tessera.cluster-tls-ca " + f.ca;
        break;
      case X509_V_ERR_CERT_HAS_EXPIRED: what = "has expired"; break;
      case X509_V_ERR_CERT_NOT_YET_VALID: what = "is not valid yet"; break;
      case X509_V_ERR_INVALID_PURPOSE:
        what = std::string("is not for TLS ") + (std::strcmp(purpose, "ssl_server") == 0 ? "server" : "client") +
               " use (a node needs extendedKeyUsage serverAuth and clientAuth, as scripts/cluster-certs.sh makes)";
        break;
      default: what = "does not verify with the CA of tessera.cluster-tls-ca " + f.ca; break;
    }
    fail("cluster-tls-cert", f.cert, "the certificate (" + subject_of(cert) + ") " + what + " (OpenSSL: " + why + ")");
  }

  // Warnings: a key others may read, a certificate that expires soon.
  struct stat st;
  if (stat(f.key.c_str(), &st) == 0 && (st.st_mode & (S_IRWXG | S_IRWXO)) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", unsigned(st.st_mode & 07777));
    warnings.push_back("tessera.cluster-tls-key: " + f.key + " may be read by other users (mode " + mode +
                       "): chmod 600 it");
  }
  int days = 0, secs = 0;
  if (ASN1_TIME_diff(&days, &secs, nullptr, X509_get0_notAfter(cert)) == 1 && days < 30)
    warnings.push_back("tessera.cluster-tls-cert: " + f.cert + " (" + subject_of(cert) + ") expires in " +
                       std::to_string(days) + " days: make a new one (scripts/cluster-certs.sh)");
  ERR_clear_error();
  return warnings;
}

namespace {

// A blocking TCP connection to host:port within timeout_ms, its reads and writes bounded by the
// same time; -1 when there is none.
int connect_tcp(const std::string& host, uint16_t port, int timeout_ms) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found) != 0) return -1;
  int fd = -1;
  for (addrinfo* a = found; a && fd < 0; a = a->ai_next) {
    fd = socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, a->ai_protocol);
    if (fd < 0) continue;
    int err = 0;
    socklen_t len = sizeof err;
    pollfd p{fd, POLLOUT, 0};
    const bool ok = (connect(fd, a->ai_addr, a->ai_addrlen) == 0 || errno == EINPROGRESS) && poll(&p, 1, timeout_ms) == 1 &&
                    getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) == 0 && err == 0;
    if (!ok) {
      close(fd);
      fd = -1;
    }
  }
  freeaddrinfo(found);
  if (fd < 0) return -1;
  fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  return fd;
}

// SIGPIPE blocked on this thread while it lives (OpenSSL writes to a socket the peer may have
// closed), and a SIGPIPE raised meanwhile taken before the old mask comes back.
class SigpipeBlock {
 public:
  SigpipeBlock() {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipe_, &old_);
  }
  ~SigpipeBlock() {
    const timespec zero{0, 0};
    while (sigtimedwait(&pipe_, nullptr, &zero) > 0) {
    }
    pthread_sigmask(SIG_SETMASK, &old_, nullptr);
  }

 private:
  sigset_t pipe_, old_;
};

}  // namespace

std::string diagnose_cluster_link(const std::string& host, uint16_t port, const ClusterTlsFiles& files, int timeout_ms) {
  SigpipeBlock no_sigpipe;
  const int fd = connect_tcp(host, port, timeout_ms);
  if (fd < 0) return {};  // not a question of TLS
  tls::CtxPtr ctx(SSL_CTX_new(TLS_client_method()));
  std::unique_ptr<SSL, decltype(&SSL_free)> ssl(ctx ? SSL_new(ctx.get()) : nullptr, SSL_free);
  const bool tls = !files.cert.empty();
  std::string peer;  // the child's certificate's subject, as the verification saw it
  ERR_clear_error();
  if (!ssl) {
    close(fd);
    return {};
  }
  if (tls) {
    // As this node's CAF connects (check_cluster_tls checked the files at start).
    SSL_CTX_set_default_passwd_cb(ctx.get(), no_passphrase);
    if (SSL_use_certificate_chain_file(ssl.get(), files.cert.c_str()) != 1 ||
        SSL_use_PrivateKey_file(ssl.get(), files.key.c_str(), SSL_FILETYPE_PEM) != 1 ||
        SSL_CTX_load_verify_locations(ctx.get(), files.ca.c_str(), nullptr) != 1) {
      close(fd);
      return "this node's own certificate files cannot be read now (" + tls::last_error("") + ")";
    }
    SSL_set_app_data(ssl.get(), &peer);
    SSL_set_verify(ssl.get(), SSL_VERIFY_PEER, note_peer);
  } else {
    SSL_set_verify(ssl.get(), SSL_VERIFY_NONE, nullptr);  // only: does the child ask for TLS?
  }
  SSL_set_fd(ssl.get(), fd);
  int r = SSL_connect(ssl.get());
  // Over TLS 1.3 the server judges the client's certificate after the client's side of the
  // handshake is done: its verdict (an alert, or CAF's first bytes) comes with the first read.
  char first[16];
  if (r == 1) r = SSL_read(ssl.get(), first, sizeof first);
  const unsigned long err = ERR_peek_last_error();
  const long verify = SSL_get_verify_result(ssl.get());
  const char* err_text = err ? ERR_reason_error_string(err) : nullptr;
  const std::string detail = err_text ? std::string(" (OpenSSL: ") + err_text + ")" : std::string();
  ERR_clear_error();
  SSL_shutdown(ssl.get());
  ssl.reset();
  close(fd);

  const int reason = err && ERR_GET_LIB(err) == ERR_LIB_SSL ? ERR_GET_REASON(err) : 0;
  if (r > 0) return tls ? std::string() : "the child answers in TLS without asking this node for a certificate";
  if (tls && reason == SSL_R_CERTIFICATE_VERIFY_FAILED && verify != X509_V_OK)
    return "this node refused the child's certificate" + (peer.empty() ? "" : " (" + peer + ")") + ": " +
           X509_verify_cert_error_string(verify) + " with the CA of tessera.cluster-tls-ca " + files.ca +
           " (the child's certificate comes from another CA?)";
  if (reason > SSL_AD_REASON_OFFSET) {  // the child sent a TLS alert: it speaks TLS
    const int alert = reason - SSL_AD_REASON_OFFSET;
    const std::string what = err_text ? std::string(err_text) : "TLS alert " + std::to_string(alert);
    if (!tls)
      return "the child asks for mutual TLS (" + what +
             ") and this node has no cluster certificate (tessera.cluster-tls-cert, cluster-tls-key, cluster-tls-ca)";
    switch (alert) {
      case SSL_AD_BAD_CERTIFICATE:
      case SSL_AD_UNSUPPORTED_CERTIFICATE:
      case SSL_AD_CERTIFICATE_REVOKED:
      case SSL_AD_CERTIFICATE_EXPIRED:
      case SSL_AD_CERTIFICATE_UNKNOWN:
      case SSL_AD_UNKNOWN_CA:
      case SSL_AD_ACCESS_DENIED:
      case SSL_AD_DECRYPT_ERROR:
        return "the child refused this node's certificate " + files.cert + " (" + what +
               "): the child trusts another cluster CA";
      default: return "the child ended the TLS handshake (" + what + ")";
    }
  }
  if (!tls) return {};  // the child does not speak TLS either: something else cut CAF's handshake
  return "the child does not answer in TLS" + detail +
         ": it runs without mutual TLS (no tessera.cluster-tls-* settings), or is not a tessera node";
}

}  // namespace tessera::app
