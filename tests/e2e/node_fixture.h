#pragma once
// An in-process node on a free localhost port, and a protocol client for the e2e tests.
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <catch2/catch.hpp>

#include <caf/all.hpp>

#include "actors/node.h"
#include "protocol/protocol.h"
#include "protocol/scene_records.h"
#include "update/scene_update.h"
#include "net/server.h"
#include "net/ws_client.h"
#include "codecs/jpeg.h"
#include "core/gltf_loader.h"
#include "renderer/raytracer.h"
#include "tests/e2e/time_scale.h"

namespace tessera::test {

struct TestConfig : caf::actor_system_config {
  TestConfig() {
    register_message_types(*this);
    set("scheduler.max-threads", size_t{2});
    set("logger.verbosity", caf::atom("quiet"));
  }
};

struct TestNode {
  TestConfig cfg;
  caf::actor_system sys{cfg};
  logger_actor logger;  // the node's logger; ends before the actor system
  std::shared_ptr<NodeSettings> settings = std::make_shared<NodeSettings>();
  std::unique_ptr<Server> server;
  // The node's log lines. Shared with the log callback rather than a member the callback
  // reaches through `this`: a session's attach_functor logs `"closed": true` from CAF's
  // cleanup, which runs after the actor left the registry's running count, so it can still
  // run after await_all_actors_done() returned and ~TestNode freed the members (TSan:
  // heap-use-after-free in the log callback, found in the TSan build). The callback's copy
  // keeps the buffer alive until CAF drops the last NodeSettings.
  struct Log {
    std::mutex mu;
    std::vector<Event> events;
  };
  std::shared_ptr<Log> log = std::make_shared<Log>();

  // `configure` may change the settings and options before the server starts.
  explicit TestNode(size_t max_clients = 8,
                    const std::function<void(NodeSettings&, ServerOptions&)>& configure = nullptr) {
    settings->log = [log = log](const Event& e) {
      std::lock_guard<std::mutex> l(log->mu);
      log->events.push_back(e);
    };
    logger = spawn_logger(sys, settings->log);
    settings->logger = caf::actor_cast<caf::weak_actor_ptr>(logger);
    ServerOptions o;
    o.host = "127.0.0.1";
    o.port = 0;
    o.web_root = "web";
    o.max_clients = max_clients;
    if (configure) configure(*settings, o);
    server = std::make_unique<Server>(sys, settings, o);
    server->start();
  }
  // The sessions log into `log` until they have exited: wait for them before the members go.
  ~TestNode() {
    server->stop();
    sys.await_all_actors_done();
    flush_logger(sys, logger);
    stop_logger(sys, logger);
  }
  uint16_t port() const { return server->port(); }
  // The events the node reported so far (every event sent to the logger before the call).
  std::vector<Event> events(Ev kind) {
    flush_logger(sys, logger);
    std::lock_guard<std::mutex> l(log->mu);
    std::vector<Event> out;
    for (auto& e : log->events)
      if (e.kind == kind) out.push_back(e);
    return out;
  }
  // The node's last `n` events, one JSON line each: what a failing case prints to say where the
  // node was (a frame that never came, a hang).
  std::string last_events(size_t n = 40) {
    flush_logger(sys, logger);
    std::lock_guard<std::mutex> l(log->mu);
    std::string out;
    for (size_t i = log->events.size() > n ? log->events.size() - n : 0; i < log->events.size(); ++i)
      out += to_json_line(log->events[i]) + "\n";
    return out;
  }
  // How many events of `kind` (and for which `pred` holds) the node reported so far.
  size_t count(Ev kind, const std::function<bool(const Event&)>& pred = nullptr) {
    size_t n = 0;
    for (auto& e : events(kind)) n += !pred || pred(e);
    return n;
  }
};

// A protocol client over WsClient.
struct ProtoClient {
  WsClient ws;
  protocol::Limits limits;

  bool connect(uint16_t port, const std::string& resource = "/ws", std::string* error = nullptr) {
    return ws.connect("127.0.0.1", port, resource, error);
  }
  bool send(const std::vector<protocol::ClientRecord>& recs) { return ws.send(protocol::encode(recs)); }
  // Next server record of type T, skipping others (Stats); nullopt on timeout or close.
  template <class T>
  // The timeout is scaled for sanitizer builds (time_scale.h).
  std::optional<T> next(int timeout_ms = 20000, std::vector<protocol::ErrorReply>* errors = nullptr) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms) * time_scale();
    while (true) {
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      auto msg = ws.receive(int(left.count()));
      if (!msg) return std::nullopt;
      auto recs = protocol::decode_server(msg->data(), msg->size(), limits);
      if (!recs) return std::nullopt;
      for (auto& r : recs.value()) {
        if (auto* t = std::get_if<T>(&r)) return std::move(*t);
        if (errors)
          if (auto* e = std::get_if<protocol::ErrorReply>(&r)) errors->push_back(*e);
      }
    }
  }
  std::optional<protocol::HandshakeReply> handshake(protocol::DisplayKind display, int w, int h, uint8_t quality = 90,
                                                     protocol::RendererKind renderer = protocol::RendererKind::raytracer) {
    protocol::Handshake hs;
    hs.renderer = renderer;
    hs.display = display;
    hs.jpeg_quality = quality;
    hs.width = w;
    hs.height = h;
    if (!send({hs})) return std::nullopt;
    return next<protocol::HandshakeReply>();
  }
  bool upload(const Scene& scene) {
    protocol::SceneRecordOptions o;
    o.resolution = false;  // the handshake chose it
    for (auto& m : protocol::pack_messages(protocol::scene_to_records(scene, o), 8u << 20))
      if (!ws.send(m)) return false;
    return true;
  }
  std::optional<protocol::Frame> render(const Camera& cam, uint32_t frame, int timeout_ms = 20000) {
    if (!send({protocol::SetCamera{cam}, protocol::RenderRequest{frame}})) return std::nullopt;
    return next<protocol::Frame>(timeout_ms);
  }
  // The same while a still refines: the frames of earlier numbers still on their way (its
  // refinements) are skipped, and the first frame numbered `frame` is returned.
  std::optional<protocol::Frame> render_past_still(const Camera& cam, uint32_t frame, int timeout_ms = 20000) {
    if (!send({protocol::SetCamera{cam}, protocol::RenderRequest{frame}})) return std::nullopt;
    for (;;) {
      auto f = next<protocol::Frame>(timeout_ms);
      if (!f || f->frame == frame) return f;
    }
  }
};

inline const LoadedScene& pavilion() {
  static LoadedScene s = load_gltf("../shared/scenes/pavilion/scene.gltf");
  return s;
}
inline const CameraLoop& pavilion_loop() {
  static CameraLoop l = load_camera_loop("../shared/scenes/pavilion/camera-loop.json");
  return l;
}

// The ray tracer's direct render of a scene from a camera (AO seeded as a session seeds its
// frame `seq`): what a node's frame must show.
inline Image render_direct(const Scene& original, const Camera& cam, int w, int h, int ao, uint32_t seq) {
  Scene scene = original;
  scene.set_resolution(w, h);
  scene.set_camera(cam);
  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  RenderSettings s;
  s.ao_samples = ao;
  s.frame = seq;
  TaskResult r;
  rt.render({0, 0, w, h}, s, r);
  return std::move(r.image);
}

inline Image decode_jpeg(const std::vector<uint8_t>& bytes) {
  Image img;
  std::string err;
  REQUIRE(jpeg_decode(bytes.data(), bytes.size(), img, err));
  return img;
}

// Whether the event's field `key` is a string containing `part`.
inline bool has(const Event& e, const std::string& key, const std::string& part) {
  const Json* v = e.field(key);
  return v && v->type() == Json::Type::string && v->as_string().find(part) != std::string::npos;
}

inline bool wait_for(const std::function<bool()>& pred, int timeout_ms = 5000) {
  auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return pred();
}

}  // namespace tessera::test
