#pragma once
// The node's network endpoint: one port serving
//   /ws[?session=TOKEN]  the WebSocket carrying the client protocol (docs/protocol.md),
//                        one session actor per connection;
//   /mjpeg/TOKEN         the MJPEG stream of session TOKEN (multipart/x-mixed-replace);
//   everything else      static files from the web root (the web client and demo pages).
// websocketpp lives only in server.cpp (with the test/load-test client below).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <caf/fwd.hpp>

#include "actors/node.h"

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
};

class Server {
 public:
  Server(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds and starts the network thread; throws std::runtime_error when it cannot bind.
  void start();
  // Closes every connection, ends every session and joins the network thread.
  void stop();
  uint16_t port() const;
  size_t sessions() const;  // connected WebSocket clients (not counting those being closed)
  // Bytes waiting for slow WebSocket clients (websocketpp's send queues and the frames
  // waiting to replace), over all connections; counted in NodeSettings::budget.
  uint64_t queued_bytes() const;
  size_t mjpeg_viewers() const;  // open MJPEG streams

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

// A blocking WebSocket client (tests, `tessera loadtest`): a network thread and a queue of
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
