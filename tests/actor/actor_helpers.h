#pragma once
// Shared by the deterministic actor tests: a sink that records what a session sends its
// client, and a tiny scene that renders in well under a millisecond.
#include <atomic>
#include <mutex>
#include <string>
#include <vector>

#include <caf/all.hpp>
#include <caf/test/dsl.hpp>

#include "actors/node.h"
#include "protocol/protocol.h"

namespace tessera::test {

using namespace tessera::protocol;

struct TestConfig : caf::actor_system_config {
  TestConfig() { register_message_types(*this); }
};

// Records what the session sends to its client.
struct RecordingSink : ClientSink {
  std::mutex mu;
  std::vector<ServerRecord> records;
  int closes = 0;
  size_t mjpeg = 0;
  // What frames_unsent() says: a test sets it to hold the H.264 display back, as a connection
  // that has not yet written the last frame does.
  std::atomic<uint32_t> unsent{0};
  uint32_t frames_unsent() const override { return unsent; }
  std::function<void()> gone;  // on_frame_gone's callback: the test calls it after lowering `unsent`
  void on_frame_gone(std::function<void()> f) override { gone = std::move(f); }
  void send(std::vector<uint8_t> message) override {
    auto r = decode_server(message.data(), message.size(), Limits{});
    if (!r.ok()) CAF_FAIL("the session sent what a client cannot decode: " << r.error().message);
    std::lock_guard<std::mutex> l(mu);
    for (auto& x : r.value()) records.push_back(std::move(x));
  }
  void send_mjpeg(std::shared_ptr<const std::vector<uint8_t>>, uint32_t) override { ++mjpeg; }
  void close(const std::string&) override { ++closes; }
  std::string token() const override { return "testtoken"; }
  template <class T>
  std::vector<T> all() {
    std::vector<T> out;
    for (auto& r : records)
      if (auto* t = std::get_if<T>(&r)) out.push_back(*t);
    return out;
  }
};

// A quad in front of the camera, one light: 16x16 pixels render in well under a millisecond.
inline std::vector<ClientRecord> tiny_scene() {
  SetBuffer pos;
  pos.id = 1;
  pos.buffer.type = Buffer::Type::f32;
  pos.buffer.components = 3;
  pos.buffer.f = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
  SetBuffer idx;
  idx.id = 2;
  idx.buffer.type = Buffer::Type::u32;
  idx.buffer.components = 1;
  idx.buffer.u = {0, 1, 2, 0, 2, 3};
  SetMesh mesh;
  mesh.id = 3;
  mesh.mesh.positions = 1;
  mesh.mesh.indices = 2;
  SetLight light;
  light.id = 4;
  light.light.type = Light::Type::directional;
  light.light.direction = {0, 0, -1};
  return {pos, idx, mesh, light};
}

inline Camera camera_at(float z) {
  Camera c;
  c.to_world = Mat4::look_at({0, 0, z}, {0, 0, 0}, {0, 1, 0});
  return c;
}

}  // namespace tessera::test
