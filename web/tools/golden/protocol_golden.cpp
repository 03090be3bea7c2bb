// Writes golden protocol messages (hex, one JSON object) encoded by protocol/protocol.cpp, for the
// web client's byte-for-byte tests (web/test/unit/net/golden.json). Not part of the CMake build:
//   g++ -std=c++17 -I../../.. protocol_golden.cpp ../../../build/net/libtessera_protocol.a \
//       ../../../build/codecs/libtessera_codecs.a ../../../build/renderer/libtessera_scene.a -lturbojpeg -lz -o /tmp/golden
//   /tmp/golden > ../../test/unit/net/golden.json
#include <cstdio>
#include <string>
#include "protocol/protocol.h"

using namespace tessera;
using namespace tessera::protocol;

static std::string hex(const std::vector<uint8_t>& v) {
  static const char* d = "0123456789abcdef";
  std::string s;
  for (uint8_t b : v) { s += d[b >> 4]; s += d[b & 15]; }
  return s;
}

int main() {
  std::vector<ClientRecord> c;
  Handshake h; h.renderer = RendererKind::raytracer; h.display = DisplayKind::s3tc; h.jpeg_quality = 80; h.max_nodes = 3; h.width = 320; h.height = 240;
  std::printf("{\n\"handshake\": \"%s\",\n", hex(encode(ClientRecord(h))).c_str());
  c.push_back(Settings{16, 5});
  c.push_back(Resolution{640, 360});
  SetCamera cam; cam.camera.to_world = Mat4::translate({1, 2, 3}); cam.camera.fov_y = 0.5f; c.push_back(cam);
  SetEnvironment env; env.environment.ambient = {0.1f, 0.2f, 0.3f}; env.environment.background = {0.5f, 0.5f, 0.5f}; env.environment.linear = false; c.push_back(env);
  SetBuffer b; b.id = 7; b.buffer.type = Buffer::Type::f32; b.buffer.components = 3; b.buffer.f = {0, 0, 0, 1, 0, 0, 0, 1, 0}; c.push_back(b);
  SetBuffer ib; ib.id = 8; ib.buffer.type = Buffer::Type::u32; ib.buffer.components = 1; ib.buffer.u = {0, 1, 2}; c.push_back(ib);
  SetTexture t; t.id = 9; t.format = TextureFormat::rgba8; t.texture.width = 1; t.texture.height = 2; t.texture.rgba = {255, 0, 0, 255, 0, 255, 0, 128};
  t.texture.sampler.wrap_s = Sampler::Wrap::clamp; t.texture.sampler.wrap_t = Sampler::Wrap::repeat; t.texture.sampler.filter = Sampler::Filter::nearest; t.texture.srgb = false; c.push_back(t);
  SetMaterial m; m.id = 10; m.material.model = Material::Model::phong; m.material.diffuse_color = {0.5f, 0.25f, 1}; m.material.specular_color = {1, 1, 1};
  m.material.shininess = 0.2f; m.material.emissive_color = {0, 0.1f, 0}; m.material.ambient_intensity = 0.3f; m.material.opacity = 0.75f;
  m.material.diffuse_texture = 9; m.material.reflection = 0.1f; m.material.refraction = 0.9f; m.material.ior = 1.5f; m.material.alpha_mask = true; m.material.double_sided = true; c.push_back(m);
  SetMesh me; me.id = 11; me.mesh.positions = 7; me.mesh.indices = 8; me.mesh.material = 10; me.mesh.transform = Mat4::scale({2, 3, 4}); me.mesh.visible = false; c.push_back(me);
  SetLight l; l.id = 12; l.light.type = Light::Type::spot; l.light.color = {1, 0.5f, 0.25f}; l.light.intensity = 1; l.light.position = {1, 2, 3};
  l.light.direction = {0, -1, 0}; l.light.attenuation = {1, 0, 0.1f}; l.light.cutoff = 0.4f; l.light.softness = 0.5f; l.light.on = true; c.push_back(l);
  c.push_back(Remove{RecordType::mesh, 5});
  c.push_back(RenderRequest{42});
  std::printf("\"client\": \"%s\",\n", hex(encode(c)).c_str());
  std::vector<ServerRecord> s;
  HandshakeReply r; r.display = DisplayKind::jpeg; r.jpeg_quality = 85; r.nodes = 2; r.width = 320; r.height = 240; r.max_message_bytes = 1000000; r.max_buffer_bytes = 5000000000ull; r.server_version = "tessera 0.1.0";
  s.push_back(r);
  Frame f; f.frame = 42; f.width = 4; f.height = 4; f.encoding = FrameEncoding::dxt1; f.timings = {1, 2, 3, 4, 5, 6}; f.payload = {1, 2, 3, 4, 5, 6, 7, 8}; s.push_back(f);
  ErrorReply e; e.code = ErrorCode::bad_mesh; e.fatal = false; e.record = 3; e.message = "mesh 11: bad"; s.push_back(e);
  Stats st; st.frames = 10; st.dropped = 1; st.bytes_sent = 12345; st.scene_bytes = 678; st.triangles = 1; st.nodes = 2; st.fps = 30; st.mean_pipeline_ms = 12.5f; s.push_back(st);
  std::printf("\"server\": \"%s\"\n}\n", hex(encode(s)).c_str());
  // A round trip through the C++ decoder of a message the JS encoder will also produce is in the JS test.
}
