// Writes a corpus of valid protocol messages, one file per message, made with the encoders:
//   protocol_make_corpus <dir>
// The checked-in copy lives in tests/fuzz/corpus (regenerate after a protocol change).
#include <cstdio>
#include <fstream>
#include <string>

#include "codecs/jpeg.h"
#include "net/protocol.h"

using namespace tessera;
using namespace tessera::protocol;

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <dir>\n", argv[0]);
    return 2;
  }
  std::string dir = argv[1];
  int n = 0;
  auto put = [&](const std::string& name, const std::vector<uint8_t>& bytes) {
    std::ofstream(dir + "/" + name, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    ++n;
  };

  Handshake h;
  h.display = DisplayKind::s3tc;
  h.max_nodes = 4;
  put("handshake", encode(ClientRecord{h}));
  put("settings", encode(ClientRecord{Settings{4, 3}}));
  put("resolution", encode(ClientRecord{Resolution{1280, 720}}));
  SetCamera cam;
  cam.camera.to_world = Mat4::look_at({0, 1, 5}, {0, 0, 0}, {0, 1, 0});
  put("camera", encode(ClientRecord{cam}));
  SetEnvironment env;
  env.environment.ambient = {0.2f, 0.2f, 0.2f};
  put("environment", encode(ClientRecord{env}));

  SetBuffer pos;
  pos.id = 1;
  pos.buffer.components = 3;
  pos.buffer.f = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  SetBuffer idx;
  idx.id = 2;
  idx.buffer.type = Buffer::Type::u32;
  idx.buffer.u = {0, 1, 2, 2, 1, 3};
  SetBuffer nrm = pos;
  nrm.id = 3;
  nrm.buffer.f = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
  nrm.deflate = true;
  SetBuffer uv;
  uv.id = 4;
  uv.buffer.components = 2;
  uv.buffer.f = {0, 0, 1, 0, 0, 1, 1, 1};
  put("buffer_f32", encode(ClientRecord{pos}));
  put("buffer_u32", encode(ClientRecord{idx}));
  put("buffer_deflate", encode(ClientRecord{nrm}));

  SetTexture tex;
  tex.id = 5;
  tex.texture.width = 2;
  tex.texture.height = 2;
  tex.texture.rgba = {255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128};
  put("texture_rgba8", encode(ClientRecord{tex}));
  SetTexture jtex = tex;
  jtex.id = 6;
  jtex.format = TextureFormat::jpeg;
  Image img(8, 8);
  for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = uint8_t(i * 3);
  jtex.texture.width = 8;
  jtex.texture.height = 8;
  std::string err;
  JpegEncoder().encode(img, 80, jtex.encoded, err);
  put("texture_jpeg", encode(ClientRecord{jtex}));

  SetMaterial mat;
  mat.id = 7;
  mat.material.diffuse_texture = 5;
  mat.material.reflection = 0.3f;
  put("material", encode(ClientRecord{mat}));
  SetMesh mesh;
  mesh.id = 8;
  mesh.mesh.positions = 1;
  mesh.mesh.normals = 3;
  mesh.mesh.texcoords = 4;
  mesh.mesh.indices = 2;
  mesh.mesh.material = 7;
  put("mesh", encode(ClientRecord{mesh}));
  SetLight light;
  light.id = 9;
  light.light.type = Light::Type::point;
  put("light", encode(ClientRecord{light}));
  put("remove", encode(ClientRecord{Remove{RecordType::mesh, 8}}));
  put("render", encode(ClientRecord{RenderRequest{1}}));
  put("scene_batch", encode(std::vector<ClientRecord>{cam, env, pos, idx, nrm, uv, tex, mat, mesh, light,
                                                      Remove{RecordType::texture, 5}, RenderRequest{2}}));

  HandshakeReply reply;
  reply.server_version = "tessera 0.1.0";
  put("server_handshake_reply", encode(ServerRecord{reply}));
  Frame frame;
  frame.width = 8;
  frame.height = 8;
  frame.encoding = FrameEncoding::dxt1;
  frame.payload.assign(32, 0x55);
  put("server_frame", encode(ServerRecord{frame}));
  put("server_error", encode(ServerRecord{ErrorReply{ErrorCode::bad_mesh, false, 2, "mesh 8: bad"}}));
  put("server_stats", encode(ServerRecord{Stats{}}));
  std::printf("wrote %d messages to %s\n", n, dir.c_str());
  return 0;
}
