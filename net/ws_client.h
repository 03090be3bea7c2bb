#pragma once
// A blocking WebSocket client: what the tests, `tessera loadtest` and `tessera soak` use to talk
// to a node as a browser would. Not part of the node (net/server.h).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
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

  // ws://host:port + resource (e.g. "/ws"). False and *error (e.g. "HTTP 503") on failure.
  bool connect(const std::string& host, uint16_t port, const std::string& resource, std::string* error,
               int timeout_ms = 5000);
  bool send(const std::vector<uint8_t>& message);
  bool send_text(const std::string& text);
  // The next received message; nullopt on timeout, or when closed and nothing is left.
  std::optional<std::vector<uint8_t>> receive(int timeout_ms);
  bool closed() const;
  void close();   // close handshake
  void abort();   // drops the TCP connection without a close handshake (a crashed client)

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
