// Writes the seed corpora of the fuzz targets, one directory per target, one file per input:
//   fuzz_make_corpus <dir>      (the checked-in copy: fuzz_make_corpus tests/fuzz/corpus)
// Regenerate after a protocol or message change. protocol/ and render/ hold messages made by
// the protocol's encoders, cluster/ CAF-serialised cluster messages, gltf/ small glTF files
// with data: URI buffers, camera_loop/ camera loops, http/ requests. render/ also holds the
// inputs of issue 16 that abort inside Embree (mesh transforms that are singular or nearly
// so, a camera scaled by 1e19, a glTF node scaled to zero): the render target must survive them.
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <caf/binary_serializer.hpp>

#include "actors/cluster_protocol.h"
#include "codecs/jpeg.h"
#include "protocol/protocol.h"
#include "protocol/scene_records.h"
#include "renderer/renderer.h"
#include "update/scene_update.h"
#include "lb/sat.h"

using namespace tessera;
using namespace tessera::protocol;

namespace {

std::string g_dir;
int g_count = 0;

void put(const std::string& target, const std::string& name, const std::string& bytes) {
  std::filesystem::create_directories(g_dir + "/" + target);
  std::ofstream(g_dir + "/" + target + "/" + name, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  ++g_count;
}
void put(const std::string& target, const std::string& name, const std::vector<uint8_t>& bytes) {
  put(target, name, std::string(bytes.begin(), bytes.end()));
}

std::string base64(const std::vector<uint8_t>& in) {
  static const char* abc = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < in.size(); i += 3) {
    uint32_t v = uint32_t(in[i]) << 16;
    if (i + 1 < in.size()) v |= uint32_t(in[i + 1]) << 8;
    if (i + 2 < in.size()) v |= in[i + 2];
    out += abc[(v >> 18) & 63];
    out += abc[(v >> 12) & 63];
    out += i + 1 < in.size() ? abc[(v >> 6) & 63] : '=';
    out += i + 2 < in.size() ? abc[v & 63] : '=';
  }
  return out;
}

template <class T>
void append(std::vector<uint8_t>& out, const T& v) {
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  out.insert(out.end(), p, p + sizeof v);
}

// --- client protocol ------------------------------------------------------------------------

struct Quad {
  SetBuffer pos, idx, nrm, uv;
  SetMaterial mat;
  SetMesh mesh;
};
Quad quad() {
  Quad q;
  q.pos.id = 1;
  q.pos.buffer.components = 3;
  q.pos.buffer.f = {-1, -1, 0, 1, -1, 0, -1, 1, 0, 1, 1, 0};
  q.idx.id = 2;
  q.idx.buffer.type = Buffer::Type::u32;
  q.idx.buffer.u = {0, 1, 2, 2, 1, 3};
  q.nrm = q.pos;
  q.nrm.id = 3;
  q.nrm.buffer.f = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
  q.nrm.deflate = true;
  q.uv.id = 4;
  q.uv.buffer.components = 2;
  q.uv.buffer.f = {0, 0, 1, 0, 0, 1, 1, 1};
  q.mat.id = 7;
  q.mat.material.reflection = 0.3f;
  q.mesh.id = 8;
  q.mesh.mesh.positions = 1;
  q.mesh.mesh.normals = 3;
  q.mesh.mesh.texcoords = 4;
  q.mesh.mesh.indices = 2;
  q.mesh.mesh.material = 7;
  return q;
}
SetCamera camera_at(Vec3 eye) {
  SetCamera c;
  c.camera.to_world = Mat4::look_at(eye, {0, 0, 0}, {0, 1, 0});
  return c;
}
SetLight point_light() {
  SetLight l;
  l.id = 9;
  l.light.type = Light::Type::point;
  l.light.position = {2, 3, 4};
  return l;
}
// A quad scene whose mesh has the given transform (and the camera given).
std::vector<ClientRecord> quad_scene(const Mat4& transform, const SetCamera& cam) {
  Quad q = quad();
  q.mesh.mesh.transform = transform;
  SetEnvironment env;
  env.environment.ambient = {0.2f, 0.2f, 0.2f};
  return {cam, env, q.pos, q.idx, q.nrm, q.uv, q.mat, q.mesh, point_light(), RenderRequest{1}};
}

void protocol_corpus() {
  Handshake h;
  h.display = DisplayKind::s3tc;
  h.max_nodes = 4;
  put("protocol", "handshake", encode(ClientRecord{h}));
  put("protocol", "settings", encode(ClientRecord{Settings{4, 3}}));
  put("protocol", "refine", encode(ClientRecord{Refine{64}}));
  put("protocol", "budget", encode(ClientRecord{Budget{33}}));
  put("protocol", "video", encode(ClientRecord{Video{4000, true}}));
  put("protocol", "resolution", encode(ClientRecord{Resolution{1280, 720}}));
  SetCamera cam = camera_at({0, 1, 5});
  put("protocol", "camera", encode(ClientRecord{cam}));
  SetEnvironment env;
  env.environment.ambient = {0.2f, 0.2f, 0.2f};
  put("protocol", "environment", encode(ClientRecord{env}));
  Quad q = quad();
  put("protocol", "buffer_f32", encode(ClientRecord{q.pos}));
  put("protocol", "buffer_u32", encode(ClientRecord{q.idx}));
  put("protocol", "buffer_deflate", encode(ClientRecord{q.nrm}));

  SetTexture tex;
  tex.id = 5;
  tex.texture.width = 2;
  tex.texture.height = 2;
  tex.texture.rgba = {255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128};
  put("protocol", "texture_rgba8", encode(ClientRecord{tex}));
  SetTexture jtex = tex;
  jtex.id = 6;
  jtex.format = TextureFormat::jpeg;
  Image img(8, 8);
  for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = uint8_t(i * 3);
  jtex.texture.width = 8;
  jtex.texture.height = 8;
  std::string err;
  JpegEncoder().encode(img, 80, jtex.encoded, err);
  put("protocol", "texture_jpeg", encode(ClientRecord{jtex}));

  SetMaterial mat = q.mat;
  mat.material.diffuse_texture = 5;
  put("protocol", "material", encode(ClientRecord{mat}));
  put("protocol", "mesh", encode(ClientRecord{q.mesh}));
  put("protocol", "light", encode(ClientRecord{point_light()}));
  put("protocol", "remove", encode(ClientRecord{Remove{RecordType::mesh, 8}}));
  put("protocol", "render", encode(ClientRecord{RenderRequest{1}}));
  put("protocol", "scene_batch", encode(std::vector<ClientRecord>{cam, env, q.pos, q.idx, q.nrm, q.uv, tex, mat, q.mesh,
                                                                  point_light(), Remove{RecordType::texture, 5},
                                                                  RenderRequest{2}}));

  HandshakeReply reply;
  reply.server_version = "tessera 0.1.0";
  put("protocol", "server_handshake_reply", encode(ServerRecord{reply}));
  Frame frame;
  frame.width = 8;
  frame.height = 8;
  frame.encoding = FrameEncoding::dxt1;
  frame.payload.assign(32, 0x55);
  put("protocol", "server_frame", encode(ServerRecord{frame}));
  frame.refined = true;
  frame.samples = 16;
  put("protocol", "server_frame_refined", encode(ServerRecord{frame}));
  put("protocol", "server_error", encode(ServerRecord{ErrorReply{ErrorCode::bad_mesh, false, 2, "mesh 8: bad"}}));
  put("protocol", "server_stats", encode(ServerRecord{Stats{}}));
  SetBufferRef bref;
  bref.id = 20;
  bref.type = Buffer::Type::u32;
  bref.source = SourceType::u16;
  bref.value_count = 6;
  bref.byte_stride = 2;
  bref.byte_offset = 96;
  bref.url = "http://127.0.0.1:8080/scenes/quad/quad.bin";
  SetTextureRef tref;
  tref.id = 21;
  tref.url = "http://127.0.0.1:8080/scenes/quad/quad.png";
  put("protocol", "refs", encode(std::vector<ClientRecord>{bref, tref}));
  put("protocol", "server_reference",
      encode(ServerRecord{Reference{RefKind::texture, false, 21, 0, "http://x is not in tessera.asset-origins"}}));
}

// --- glTF ----------------------------------------------------------------------------------

// A glTF file with one indexed quad (positions, normals, texcoords), a JPEG texture in a
// data: URI, and `nodes` / `extra` spliced in (nodes refer to mesh 0, camera 0, light 0).
std::string gltf(const std::string& nodes, const std::string& scene_nodes, bool texture = true) {
  std::vector<uint8_t> bin;
  for (float v : {-1.f, -1.f, 0.f, 1.f, -1.f, 0.f, -1.f, 1.f, 0.f, 1.f, 1.f, 0.f}) append(bin, v);     // 0: 48 B
  for (float v : {0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f}) append(bin, v);        // 48: 48 B
  for (float v : {0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 1.f}) append(bin, v);                            // 96: 32 B
  for (uint16_t v : {0, 1, 2, 2, 1, 3}) append(bin, v);                                              // 128: 12 B
  std::string s = R"({"asset": {"version": "2.0"},
  "buffers": [{"byteLength": 140, "uri": "data:application/octet-stream;base64,)" + base64(bin) + R"("}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 48},
                  {"buffer": 0, "byteOffset": 96, "byteLength": 32}, {"buffer": 0, "byteOffset": 128, "byteLength": 12}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, -1, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
                {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
                {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}],
)";
  if (texture) {
    Image img(4, 4);
    for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = uint8_t(i * 13);
    std::vector<uint8_t> jpeg;
    std::string err;
    JpegEncoder().encode(img, 80, jpeg, err);
    s += R"(  "images": [{"uri": "data:image/jpeg;base64,)" + base64(jpeg) + R"("}],
  "samplers": [{"magFilter": 9728, "wrapS": 33071}],
  "textures": [{"source": 0, "sampler": 0}],
  "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [1, 0.5, 0.5, 1]},
                 "alphaMode": "MASK", "alphaCutoff": 0.4, "doubleSided": true,
                 "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.5}, "KHR_materials_ior": {"ior": 1.5}}}],
)";
  } else {
    s += R"(  "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1]}}],
)";
  }
  s += R"(  "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1, "aspectRatio": 1.5}}],
  "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "color": [1, 1, 1], "intensity": 5},
                                                    {"type": "spot", "intensity": 3, "spot": {"outerConeAngle": 0.7}},
                                                    {"type": "directional", "intensity": 1}]}},
  "nodes": [)" + nodes + R"(],
  "scenes": [{"nodes": [)" + scene_nodes + R"(], "extras": {"environment": {"ambient": [0.1, 0.1, 0.2]}}}],
  "scene": 0}
)";
  return s;
}

// What real exporters write besides float triangle lists: quantized attributes
// (KHR_mesh_quantization), a sparse accessor, a strip and a fan, a second texture coordinate
// set under KHR_texture_transform, and an unlit material.
std::string gltf_conformance() {
  std::vector<uint8_t> bin;
  for (int16_t v : {-32767, -32767, 0, 0, 32767, -32767, 0, 0, -32767, 32767, 0, 0, 32767, 32767, 0, 0}) append(bin, v);  // 0: 32 B
  for (int8_t v : {0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0}) append(bin, v);                        // 32: 16 B
  for (uint16_t v : {0, 0, 65535, 0, 0, 65535, 65535, 65535}) append(bin, v);                                   // 48: 16 B
  for (float v : {0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 1.f}) append(bin, v);                                      // 64: 32 B
  for (uint8_t v : {3, 0, 0, 0}) append(bin, v);                                                                // 96: 4 B
  for (float v : {1.f, 1.f, 0.5f}) append(bin, v);                                                              // 100: 12 B
  Image img(4, 4);
  for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = uint8_t(i * 7);
  std::vector<uint8_t> jpeg;
  std::string err;
  JpegEncoder().encode(img, 80, jpeg, err);
  return R"({"asset": {"version": "2.0"},
  "extensionsUsed": ["KHR_mesh_quantization", "KHR_texture_transform", "KHR_materials_unlit"],
  "extensionsRequired": ["KHR_mesh_quantization"],
  "buffers": [{"byteLength": 112, "uri": "data:application/octet-stream;base64,)" + base64(bin) + R"("}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 32, "byteStride": 8},
                  {"buffer": 0, "byteOffset": 32, "byteLength": 16, "byteStride": 4},
                  {"buffer": 0, "byteOffset": 48, "byteLength": 16}, {"buffer": 0, "byteOffset": 64, "byteLength": 32},
                  {"buffer": 0, "byteOffset": 96, "byteLength": 1}, {"buffer": 0, "byteOffset": 100, "byteLength": 12}],
  "accessors": [{"bufferView": 0, "componentType": 5122, "normalized": true, "count": 4, "type": "VEC3"},
                {"bufferView": 1, "componentType": 5120, "normalized": true, "count": 4, "type": "VEC3"},
                {"bufferView": 2, "componentType": 5123, "normalized": true, "count": 4, "type": "VEC2"},
                {"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2"},
                {"bufferView": 0, "componentType": 5122, "normalized": true, "count": 4, "type": "VEC3",
                 "sparse": {"count": 1, "indices": {"bufferView": 4, "componentType": 5121}, "values": {"bufferView": 5}}}],
  "images": [{"uri": "data:image/jpeg;base64,)" + base64(jpeg) + R"("}],
  "textures": [{"source": 0}],
  "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "texCoord": 1,
                   "extensions": {"KHR_texture_transform": {"offset": [0.5, 0], "rotation": 0.3, "scale": [2, 2]}}}}},
                {"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.6, 0.2, 1]}, "extensions": {"KHR_materials_unlit": {}}}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "TEXCOORD_1": 3}, "mode": 5, "material": 0},
                             {"attributes": {"POSITION": 4}, "mode": 6, "material": 1}]}],
  "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}
)";
}

void gltf_corpus() {
  put("gltf", "conformance.gltf", gltf_conformance());
  put("gltf", "mesh.gltf", gltf(R"({"mesh": 0})", "0", false));
  put("gltf", "textured.gltf", gltf(R"({"mesh": 0})", "0"));
  put("gltf", "trs_matrix.gltf",
      gltf(R"({"mesh": 0, "translation": [1, 2, 3], "rotation": [0, 0.7071068, 0, 0.7071068], "scale": [2, 2, 2]},
            {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -3, 0, 0, 1]},
            {"children": [0, 1], "translation": [0, -1, 0]})",
           "2"));
  put("gltf", "camera_lights.gltf",
      gltf(R"({"mesh": 0}, {"camera": 0, "translation": [0, 0, 5]},
            {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [1, 2, 3]},
            {"extensions": {"KHR_lights_punctual": {"light": 1}}, "rotation": [0.3826834, 0, 0, 0.9238795]},
            {"extensions": {"KHR_lights_punctual": {"light": 2}}})",
           "0, 1, 2, 3, 4"));
}

// --- cluster messages ----------------------------------------------------------------------

template <class T>
std::string caf_bytes(uint8_t mode, T& x) {
  std::vector<char> buf;
  caf::binary_serializer sink{nullptr, buf};
  if (auto err = sink(x)) {
    std::fprintf(stderr, "cannot serialise a cluster message\n");
    std::exit(1);
  }
  return std::string(1, char(mode)) + std::string(buf.begin(), buf.end());
}

TileResult tile(const Rect& pixels, PacketLayout layout) {
  TileResult t;
  t.frame = 7;  // fuzz_cluster's frame (64x48, tasks [0,0,32,48] and [32,0,64,48])
  t.pixels = pixels;
  t.rgba.assign(size_t(pixels.area()) * 4, 128);
  CostMap cost;
  cost.packets = pixels_to_packets(pixels, layout);
  for (int32_t i = 0; i < cost.packets.area(); ++i) cost.cost.push_back(uint32_t(100 + i));
  t.sat = Sat::from_cost_map_serial(cost).serialize();
  // Depths for the balancer's reprojection: a wall, one sky packet, one unknown.
  std::vector<float> depth(cost.cost.size(), 20.0f);
  depth[0] = std::numeric_limits<float>::infinity();
  depth[1] = std::numeric_limits<float>::quiet_NaN();
  t.depth.resize(depth.size() * 4);
  std::memcpy(t.depth.data(), depth.data(), t.depth.size());
  t.kernel_ms = 1.5;
  t.rendering_ms = 2;
  t.sat_ms = 0.1;
  t.rays = 1536;
  return t;
}

void cluster_corpus() {
  RenderBatch b;
  b.frame = 7;
  b.width = 64;
  b.height = 48;
  b.ao_samples = 2;
  b.tasks = {{0, 0, 32, 48}, {32, 0, 64, 48}};
  put("cluster", "render_batch", caf_bytes(0, b));
  RenderBatch planned = b;  // an adaptive round: a plan of the frame's 16x12 blocks
  planned.radiance = true;
  planned.sample = 5;
  planned.plan_blocks = {0, 0, 16, 12};
  for (int i = 0; i < 16 * 12; ++i) planned.plan.push_back(i % 3 == 0 ? kSkipPacket : uint32_t(i % 6));
  put("cluster", "render_batch_plan", caf_bytes(0, planned));
  BatchReply r;
  r.tiles = {tile({0, 0, 32, 48}, {4, 4}), tile({32, 0, 64, 48}, {4, 4})};
  put("cluster", "batch_reply_4x4", caf_bytes(1, r));
  TileResult t = tile({0, 0, 32, 48}, {4, 2});
  put("cluster", "tile_result_4x2", caf_bytes(2 | 0x80, t));
  TileResult failed;
  failed.frame = 7;
  failed.code = protocol::ErrorCode::node_lost;
  failed.error = "node worker:4000 failed";
  put("cluster", "tile_result_error", caf_bytes(2, failed));
  OpenRequest o;
  o.session = 42;
  o.master = "master:4000";
  o.timeout_ms = 3000;
  put("cluster", "open_request", caf_bytes(3, o));
  std::vector<NodeInfo> nodes = {{"local", 8, 1.0}, {"10.0.0.3:4000", 16, 0.8}};
  put("cluster", "node_infos", caf_bytes(4, nodes));
  auto scene = std::make_shared<Scene>();
  std::vector<uint8_t> records = encode(quad_scene(Mat4::identity(), camera_at({0, 1, 5})));
  {
    auto lim = Limits{};
    auto msg = decode_client(records.data(), records.size(), lim);
    for (auto& rec : msg.value())
      if (!std::holds_alternative<RenderRequest>(rec)) (void)apply(*scene, std::move(rec), lim);
  }
  SceneSnapshot snap{scene};
  put("cluster", "scene_snapshot", caf_bytes(5, snap));
  put("cluster", "update", std::string(1, char(6)) + std::string(records.begin(), records.end()));
  Payload payload{records};
  put("cluster", "update_message", caf_bytes(7, payload));
}

// --- render ----------------------------------------------------------------------------------

void render_corpus() {
  SetCamera cam = camera_at({0, 1, 5});
  put("render", "quad", encode(quad_scene(Mat4::identity(), cam)));
  {
    Quad q = quad();
    SetTexture tex;
    tex.id = 5;
    tex.texture.width = 2;
    tex.texture.height = 2;
    tex.texture.rgba = {255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 100};
    q.mat.material.diffuse_texture = 5;
    q.mat.material.alpha_mask = true;
    q.mat.material.refraction = 0.5f;
    q.mat.material.ior = 1.5f;
    SetMesh second = q.mesh;
    second.id = 10;
    second.mesh.transform = Mat4::translate({0.5f, 0, -1});
    SetLight spot = point_light();
    spot.id = 11;
    spot.light.type = Light::Type::spot;
    spot.light.direction = {0, 0, -1};
    put("render", "textured_instances",
        encode(std::vector<ClientRecord>{cam, q.pos, q.idx, q.nrm, q.uv, tex, q.mat, q.mesh, second, point_light(), spot}));
  }
  {  // Vertex colours (XML3D's useVertexColor): a float3 colour per vertex, a material that uses them.
    Quad q = quad();
    SetBuffer colors = q.pos;
    colors.id = 12;
    colors.buffer.f = {1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
    q.mat.material.use_vertex_color = true;
    q.mesh.mesh.colors = 12;
    put("render", "vertex_colors",
        encode(std::vector<ClientRecord>{cam, q.pos, q.idx, q.nrm, q.uv, colors, q.mat, q.mesh, point_light()}));
  }
  // Issue 16: each of these aborts inside Embree today (an assertion on the ray or the bounds).
  Mat4 zero;
  zero.m.fill(0);
  zero.m[15] = 1;
  put("render", "abort_mesh_zero_transform", encode(quad_scene(zero, cam)));
  put("render", "abort_mesh_zero_z_scale", encode(quad_scene(Mat4::scale({1, 1, 0}), cam)));
  put("render", "abort_mesh_scale_1e-30", encode(quad_scene(Mat4::scale({1e-30f, 1e-30f, 1e-30f}), cam)));
  SetCamera huge = cam;
  for (int i : {0, 1, 2, 4, 5, 6, 8, 9, 10}) huge.camera.to_world.m[i] *= 1e19f;
  put("render", "abort_camera_scale_1e19", encode(quad_scene(Mat4::identity(), huge)));
  SetCamera huge_elem = cam;
  huge_elem.camera.to_world.m[0] = 3e38f;
  put("render", "abort_camera_element_3e38", encode(quad_scene(Mat4::identity(), huge_elem)));
  put("render", "abort_gltf_node_zero_scale.gltf", gltf(R"({"mesh": 0, "scale": [1, 1, 0]}, {"camera": 0, "translation": [0, 0, 5]})", "0, 1", false));
  put("render", "abort_gltf_node_zero_matrix.gltf",
      gltf(R"({"mesh": 0, "matrix": [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1]}, {"camera": 0, "translation": [0, 0, 5]})", "0, 1", false));
  put("render", "gltf_quad.gltf", gltf(R"({"mesh": 0}, {"camera": 0, "translation": [0, 0, 5]})", "0, 1"));
}

// --- camera loops and HTTP -------------------------------------------------------------------

void camera_loop_corpus() {
  put("camera_loop", "loop.json", std::string(R"({"fovY_deg": 45, "frames": [
  {"eye": [0, 1.6, 5], "target": [0, 1, 0], "up": [0, 1, 0]},
  {"eye": [3, 1.6, 4], "target": [0, 1, 0], "up": [0, 1, 0]},
  {"eye": [5, 2, 0], "target": [0, 1, 0], "up": [0, 1, 0]}]}
)"));
  put("camera_loop", "eye_1e39.json", std::string(R"({"fovY_deg": 60, "frames": [{"eye": [1e39, 0, 0], "target": [0, 0, 0], "up": [0, 1, 0]}]}
)"));
  put("camera_loop", "eye_is_target.json", std::string(R"({"fovY_deg": 179.9, "frames": [{"eye": [1, 1, 1], "target": [1, 1, 1], "up": [0, 0, 0]}]}
)"));
}

void http_corpus() {
  // The first byte says where fuzz_http splits the request into two reads.
  auto req = [](char split, const std::string& text) { return std::string(1, split) + text; };
  put("http", "get_root", req(7, "GET / HTTP/1.1\r\nHost: 127.0.0.1:8080\r\n\r\n"));
  put("http", "get_file_query", req(40, "GET /demo/a%20b.css?v=3#top HTTP/1.1\r\nHost: x\r\nAccept: */*\r\n\r\n"));
  put("http", "websocket_upgrade",
      req(20, "GET /ws?session=abcDEF12_- HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
              "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
              "Sec-WebSocket-Extensions: permessage-deflate; client_max_window_bits, x-webkit-deflate-frame\r\n\r\n"));
  put("http", "mjpeg", req(3, "GET /mjpeg/abcdefgh12345678 HTTP/1.1\r\nHost: x\r\n\r\n"));
  put("http", "scenes", req(9, "GET /scenes/room/scene.gltf HTTP/1.1\r\nHost: x\r\n\r\n"));
  put("http", "traversal", req(11, "GET /%2e%2e/secret.txt HTTP/1.1\r\nHost: x\r\n\r\n"));
  put("http", "symlinks", req(11, "GET /up/secret.txt HTTP/1.1\r\nHost: x\r\n\r\n"));
  put("http", "head_range", req(30, "HEAD /app.js HTTP/1.1\r\nHost: x\r\nRange: bytes=0-1\r\n\r\n"));
  put("http", "post_body", req(50, "POST /index.html HTTP/1.1\r\nHost: x\r\nContent-Length: 5\r\n\r\nhello"));
  // The redirect port's Location from a hostile Host header and a target to escape.
  put("http", "redirect_hostile_host",
      req(25, "GET /a\"b<c>%zz?q=1 HTTP/1.1\r\nHost: evil.example/@x\nX-Injected: 1\r\n\r\n"));
  put("http", "redirect_ipv6_host", req(18, "HEAD /demo/ HTTP/1.1\r\nHost: [::1]:8080\r\n\r\n"));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <dir>\n", argv[0]);
    return 2;
  }
  g_dir = argv[1];
  protocol_corpus();
  render_corpus();
  gltf_corpus();
  cluster_corpus();
  camera_loop_corpus();
  http_corpus();
  std::printf("wrote %d inputs under %s\n", g_count, g_dir.c_str());
  return 0;
}
