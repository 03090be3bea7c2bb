#pragma once
// A blocking WebSocket client: what the tests, `tessera loadtest` and `tessera soak` use to talk
// to a node as a browser would. Not part of the node (net/server.h).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace tessera {

// A blocking WebSocket client (tests, `tessera loadtest`, `tessera soak`): a network thread and a queue of
// received binary messages.
class WsClient {
 public:
  WsClient();
  ~WsClient();
  WsClient(const WsClient&) = delete;
  WsClient& operator=(const WsClient&) = delete;

  // Before connect: wss:// instead of ws://. ca_file "": any certificate is taken (a node with
  // a self-signed one); else the node's must chain to a certificate in ca_file and name the
  // host given to connect.
  void use_tls(const std::string& ca_file = "");
  // ws://host:port + resource (e.g. "/ws"). False and *error (e.g. "HTTP 503") on failure.
  // `headers` go with the upgrade request (e.g. {"Origin", "http://127.0.0.1:8080"}, as a
  // browser sends it; without one the client is no browser).
  bool connect(const std::string& host, uint16_t port, const std::string& resource, std::string* error,
               int timeout_ms = 5000, const std::vector<std::pair<std::string, std::string>>& headers = {});
  bool send(const std::vector<uint8_t>& message);
  bool send_text(const std::string& text);
  // The next received message; nullopt on timeout, or when closed and nothing is left.
  std::optional<std::vector<uint8_t>> receive(int timeout_ms);
  bool closed() const;
  // Once closed: the server's close code and reason (websocketpp's 1005 or 1006 when it sent
  // none; 0 before), and the HTTP status of a refused upgrade (0 when the upgrade got through).
  uint16_t close_code() const;
  std::string close_reason() const;
  int http_status() const;
  // The protocol and cipher of an open TLS connection ("TLSv1.3 TLS_AES_256_GCM_SHA384"); "" without TLS.
  std::string tls_session() const;
  void close();   // close handshake
  void abort();   // drops the TCP connection without a close handshake (a crashed client)

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
