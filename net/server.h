#pragma once
// The node's network endpoint: one port serving
//   /ws[?session=NAME]   the WebSocket carrying the client protocol (docs/protocol.md),
//                        one session actor per connection;
//   /mjpeg/NAME          the MJPEG stream of session NAME (multipart/x-mixed-replace);
//   everything else      static files from the web root (the web client and demo pages).
// Over HTTPS and WSS when ServerOptions names a certificate (net/tls.h), else plain.
// websocketpp lives only in server.cpp (and in the client, net/ws_client.cpp).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <caf/fwd.hpp>

#include "actors/node.h"
#include "net/admission.h"

namespace tessera {

struct ServerOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 8080;        // 0: any free port (see Server::port())
  std::string web_root = "web";
  std::vector<std::string> web_public;  // further folders of the web root to serve (each "dir/sub/")
  std::string scenes_root = "../shared/scenes";  // served at /scenes/ (the demo pages' glTF files)
  size_t max_clients = 16;     // further WebSocket handshakes get HTTP 503
  size_t max_mjpeg_per_session = 4;  // MJPEG viewers of one session token; further ones get HTTP 503
  size_t max_mjpeg_viewers = 64;     // MJPEG viewers on the node
  // Session admission on /ws and /mjpeg/ (net/admission.h; docs/operations.md, "Admission").
  admission::TokenPolicy tokens;        // none configured: no access token asked for
  admission::OriginPolicy origins = admission::OriginPolicy::parse({"self", "loopback"});
  size_t max_connections_per_ip = 0;  // WebSocket connections per client address (0: no limit)
  // HTTPS and WSS on the port (net/tls.h): a PEM certificate (chain) and its key; both empty:
  // plain HTTP and WebSocket. With TLS the port speaks nothing else.
  std::string tls_cert, tls_key;
  bool tls() const { return !tls_cert.empty() || !tls_key.empty(); }
  // With TLS: every response on the port carries `Strict-Transport-Security: max-age=N` (0:
  // none). Never sent over plain HTTP.
  uint32_t hsts_max_age = 0;
  // With TLS: plain HTTP on this port of the same address answers GET and HEAD with a 308
  // redirect to https://HOST:port/... and serves nothing else (0: any free port, see
  // Server::redirect_port()); none: no such listener. Without TLS start() refuses it.
  std::optional<uint16_t> http_redirect_port;
  // TCP congestion control of every connection on the port (TCP_CONGESTION: "bbr", "cubic",
  // ...; docs/operations.md); empty: the system's default. start() refuses one the kernel lacks.
  std::string tcp_congestion;
};

class Server {
 public:
  Server(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds and starts the network thread; throws std::runtime_error when it cannot bind or
  // cannot load the TLS certificate or key.
  void start();
  // Closes every connection, ends every session and joins the network thread.
  void stop();
  uint16_t port() const;
  size_t sessions() const;  // connected WebSocket clients (not counting those being closed)
  // Bytes waiting for slow WebSocket clients (websocketpp's send queues and the frames
  // waiting to replace), over all connections; counted in NodeSettings::budget.
  uint64_t queued_bytes() const;
  size_t mjpeg_viewers() const;  // open MJPEG streams
  uint16_t redirect_port() const;  // the plain HTTP redirect's port (0: none)
  // With TLS: reads ServerOptions::tls_cert and tls_key again (SIGHUP in `tessera serve`).
  // Connections accepted from now on present the new certificate; established ones go on with
  // theirs. Logs a `tls_certificate` event: "reloaded" with the new certificate's subject,
  // expiry and SHA-256 fingerprint, or "reload_failed" with the reason (a file missing or
  // unreadable, not PEM, a key that does not belong to the certificate, an expired certificate)
  // while the node serves on with the certificate it had. False and *error when refused, and
  // on a server without TLS. Any thread.
  bool reload_tls(std::string* error = nullptr);

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace tessera
