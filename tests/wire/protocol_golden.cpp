// The C++ half of the protocol cross-check (CTest protocol_crosscheck, docs/testing.md): writes,
// as one JSON object, what protocol/protocol.cpp makes of a set of inputs, for
// web/test/wire/crosscheck.js to hold web/src/net/Protocol.js to:
//   - valid: messages of every record type with every field set, edge values included (the
//     ends of every range, the largest ids and counts, NaN and infinities where a field takes
//     any float, over-long strings that the encoders cut): the records as Protocol.js names
//     them, the bytes the C++ encoder wrote, and whether the C++ decoder accepted them and
//     re-encoded its records to the same bytes;
//   - invalid: one message per malformed-input class and place the C++ decoder tells apart
//     (framing, lengths, ids, enums, flags, reserved bits, finiteness, ranges, limits, deflate,
//     texture headers, handshake order, on the client and the server channel), each made by
//     changing one thing in a valid message at the offset protocol/wire.toml declares, with the
//     error class it was made to hit ("expect") and the one the C++ decoder reports ("code",
//     "record").
// The build runs it (tests/CMakeLists.txt) and writes build/tests/wire/protocol_golden.json.
//   protocol_golden [OUT.json]     (standard output without OUT.json)
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include <unistd.h>

#include "codecs/deflate.h"
#include "codecs/jpeg.h"
#include "core/image.h"
#include "protocol/protocol.h"

using namespace tessera;
using namespace tessera::protocol;

namespace {

constexpr size_t kB = kMessageHeaderSize + kRecordHeaderSize;  // body of record 0
const float kNaN = std::numeric_limits<float>::quiet_NaN();
const float kInf = std::numeric_limits<float>::infinity();
const float kDenorm = std::numeric_limits<float>::denorm_min();
const float kMaxF = std::numeric_limits<float>::max();
constexpr uint32_t kMaxU32 = 0xffffffffu;
constexpr uint64_t kMaxU64 = ~0ull;

// ---------------------------------------------------------------------------------------
// JSON, with tags for what JSON cannot hold: {"$f": "NaN"} (non-finite floats), {"$u64": "..."}
// (integers beyond 2^53), {"$hex": "..."} (bytes), {"$f32": [...]} and {"$u32": [...]} (typed arrays).

std::string hex(const uint8_t* p, size_t n) {
  static const char* d = "0123456789abcdef";
  std::string s;
  for (size_t i = 0; i < n; ++i) s += d[p[i] >> 4], s += d[p[i] & 15];
  return s;
}
std::string hex(const std::vector<uint8_t>& v) { return hex(v.data(), v.size()); }
std::string bytes(const uint8_t* p, size_t n) { return "{\"$hex\": \"" + hex(p, n) + "\"}"; }
std::string bytes(const std::vector<uint8_t>& v) { return bytes(v.data(), v.size()); }

std::string num(float v) {
  if (std::isnan(v)) return "{\"$f\": \"NaN\"}";
  if (std::isinf(v)) return v > 0 ? "{\"$f\": \"Infinity\"}" : "{\"$f\": \"-Infinity\"}";
  char b[32];
  std::snprintf(b, sizeof b, "%.9g", double(v));
  return b;
}
std::string num(uint64_t v) {
  if (v > (1ull << 53) - 1) return "{\"$u64\": \"" + std::to_string(v) + "\"}";
  return std::to_string(v);
}
std::string num(uint32_t v) { return std::to_string(v); }
std::string num(int32_t v) { return std::to_string(v); }
std::string boolean(bool b) { return b ? "true" : "false"; }
std::string str(const std::string& s) {
  std::string o = "\"";
  for (unsigned char c : s) {
    if (c == '"' || c == '\\') o += '\\', o += char(c);
    else if (c < 0x20) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", c);
      o += b;
    } else o += char(c);
  }
  return o + "\"";
}
std::string vec3(const Vec3& v) { return "[" + num(v.x) + ", " + num(v.y) + ", " + num(v.z) + "]"; }
std::string floats(const float* p, size_t n) {
  std::string s = "{\"$f32\": [";
  for (size_t i = 0; i < n; ++i) s += (i ? ", " : "") + num(p[i]);
  return s + "]}";
}
std::string mat4(const Mat4& m) { return floats(m.m.data(), 16); }

// A JSON object built field by field.
struct Obj {
  std::string s = "{";
  Obj& f(const char* k, const std::string& v) {
    s += (s.size() > 1 ? ", \"" : "\"") + std::string(k) + "\": " + v;
    return *this;
  }
  std::string str() const { return s + "}"; }
};

const char* name(RendererKind k) { return k == RendererKind::raytracer ? "raytracer" : "rasterizer"; }
const char* name(DisplayKind k) { return k == DisplayKind::jpeg ? "jpeg" : k == DisplayKind::s3tc ? "s3tc" : "mjpeg"; }
const char* name(TextureFormat f) { return f == TextureFormat::rgba8 ? "rgba8" : f == TextureFormat::png ? "png" : "jpeg"; }
const char* name(Sampler::Wrap w) { return w == Sampler::Wrap::clamp ? "clamp" : "repeat"; }
const char* name(Sampler::Filter f) { return f == Sampler::Filter::nearest ? "nearest" : "linear"; }
const char* name(Material::Model m) {
  return m == Material::Model::matte ? "matte" : m == Material::Model::diffuse ? "diffuse" : "phong";
}
const char* name(Light::Type t) {
  return t == Light::Type::point ? "point" : t == Light::Type::directional ? "directional" : "spot";
}
std::string q(const char* s) { return str(s); }

// A record as Protocol.js's encoders take it.
struct ClientJs {
  std::string operator()(const Handshake& h) {
    return Obj{}.f("type", q("handshake")).f("renderer", q(name(h.renderer))).f("display", q(name(h.display)))
        .f("jpegQuality", num(uint32_t(h.jpeg_quality))).f("maxNodes", num(h.max_nodes)).f("width", num(h.width))
        .f("height", num(h.height)).str();
  }
  std::string operator()(const Settings& s) {
    return Obj{}.f("type", q("settings")).f("aoSamples", num(s.ao_samples)).f("maxDepth", num(s.max_depth)).str();
  }
  std::string operator()(const Resolution& r) {
    return Obj{}.f("type", q("resolution")).f("width", num(r.width)).f("height", num(r.height)).str();
  }
  std::string operator()(const SetCamera& c) {
    return Obj{}.f("type", q("camera")).f("toWorld", mat4(c.camera.to_world)).f("fovY", num(c.camera.fov_y)).str();
  }
  std::string operator()(const SetEnvironment& e) {
    const Environment& v = e.environment;
    return Obj{}.f("type", q("environment")).f("ambient", vec3(v.ambient)).f("background", vec3(v.background))
        .f("exposure", num(v.exposure)).f("linear", boolean(v.linear)).str();
  }
  std::string operator()(const SetBuffer& b) {
    const Buffer& buf = b.buffer;
    Obj o;
    o.f("type", q("buffer")).f("id", num(b.id)).f("bufferType", q(buf.type == Buffer::Type::f32 ? "f32" : "u32"))
        .f("components", num(uint32_t(buf.components)));
    if (buf.type == Buffer::Type::f32) {
      o.f("data", floats(buf.f.data(), buf.f.size()));
    } else {
      std::string s = "{\"$u32\": [";
      for (size_t i = 0; i < buf.u.size(); ++i) s += (i ? ", " : "") + num(buf.u[i]);
      o.f("data", s + "]}");
    }
    if (b.deflate) {  // the bytes the C++ encoder writes: the same function, the same level
      const uint8_t* p = buf.type == Buffer::Type::f32 ? reinterpret_cast<const uint8_t*>(buf.f.data())
                                                       : reinterpret_cast<const uint8_t*>(buf.u.data());
      o.f("deflated", bytes(deflate_zlib(p, buf.bytes())));
    }
    return o.str();
  }
  std::string operator()(const SetTexture& t) {
    const Texture& x = t.texture;
    return Obj{}.f("type", q("texture")).f("id", num(t.id)).f("format", q(name(t.format)))
        .f("wrapS", q(name(x.sampler.wrap_s))).f("wrapT", q(name(x.sampler.wrap_t))).f("filter", q(name(x.sampler.filter)))
        .f("srgb", boolean(x.srgb)).f("width", num(x.width)).f("height", num(x.height))
        .f("bytes", t.format == TextureFormat::rgba8 ? bytes(x.rgba.data(), x.rgba.size()) : bytes(t.encoded)).str();
  }
  std::string operator()(const SetMaterial& s) {
    const Material& m = s.material;
    return Obj{}.f("type", q("material")).f("id", num(s.id)).f("model", q(name(m.model)))
        .f("alphaMask", boolean(m.alpha_mask)).f("doubleSided", boolean(m.double_sided))
        .f("useVertexColor", boolean(m.use_vertex_color))
        .f("diffuseColor", vec3(m.diffuse_color)).f("specularColor", vec3(m.specular_color))
        .f("shininess", num(m.shininess)).f("emissiveColor", vec3(m.emissive_color))
        .f("ambientIntensity", num(m.ambient_intensity)).f("opacity", num(m.opacity))
        .f("diffuseTexture", num(m.diffuse_texture)).f("specularTexture", num(m.specular_texture))
        .f("emissiveTexture", num(m.emissive_texture)).f("reflection", num(m.reflection))
        .f("refraction", num(m.refraction)).f("ior", num(m.ior)).f("alphaCutoff", num(m.alpha_cutoff)).str();
  }
  std::string operator()(const SetMesh& s) {
    const Mesh& m = s.mesh;
    return Obj{}.f("type", q("mesh")).f("id", num(s.id)).f("positions", num(m.positions)).f("normals", num(m.normals))
        .f("texcoords", num(m.texcoords)).f("colors", num(m.colors)).f("indices", num(m.indices))
        .f("material", num(m.material))
        .f("transform", mat4(m.transform)).f("visible", boolean(m.visible)).str();
  }
  std::string operator()(const SetLight& s) {
    const Light& l = s.light;
    return Obj{}.f("type", q("light")).f("id", num(s.id)).f("lightType", q(name(l.type))).f("on", boolean(l.on))
        .f("castShadow", boolean(l.cast_shadow)).f("color", vec3(l.color)).f("intensity", num(l.intensity)).f("position", vec3(l.position))
        .f("direction", vec3(l.direction)).f("attenuation", vec3(l.attenuation)).f("cutoff", num(l.cutoff))
        .f("softness", num(l.softness)).str();
  }
  std::string operator()(const Remove& r) {
    return Obj{}.f("type", q("remove")).f("what", q(to_string(r.what))).f("id", num(r.id)).str();
  }
  std::string operator()(const RenderRequest& r) { return Obj{}.f("type", q("render")).f("frame", num(r.frame)).str(); }
  std::string operator()(const Refine& r) { return Obj{}.f("type", q("refine")).f("samples", num(r.samples)).str(); }
  std::string operator()(const Budget& b) { return Obj{}.f("type", q("budget")).f("frameMs", num(b.frame_ms)).str(); }
  std::string operator()(const Video& v) {
    return Obj{}.f("type", q("video")).f("bitrateKbps", num(v.bitrate_kbps)).f("keyframe", v.keyframe ? "true" : "false").str();
  }
  std::string operator()(const SetBufferRef& b) {
    static const char* sources[] = {"f32", "u32", "u16", "u8"};
    return Obj{}.f("type", q("buffer_ref")).f("id", num(b.id)).f("bufferType", q(b.type == Buffer::Type::f32 ? "f32" : "u32"))
        .f("components", num(uint32_t(b.components))).f("source", q(sources[int(b.source)]))
        .f("values", num(b.value_count)).f("byteStride", num(b.byte_stride)).f("byteOffset", num(b.byte_offset))
        .f("url", str(b.url)).str();
  }
  std::string operator()(const SetTextureRef& t) {
    return Obj{}.f("type", q("texture_ref")).f("id", num(t.id)).f("wrapS", q(name(t.sampler.wrap_s)))
        .f("wrapT", q(name(t.sampler.wrap_t))).f("filter", q(name(t.sampler.filter))).f("srgb", boolean(t.srgb))
        .f("url", str(t.url)).str();
  }
};

struct ServerJs {
  std::string operator()(const HandshakeReply& h) {
    return Obj{}.f("type", q("handshake_reply")).f("renderer", q(name(h.renderer))).f("display", q(name(h.display)))
        .f("jpegQuality", num(uint32_t(h.jpeg_quality))).f("nodes", num(h.nodes)).f("width", num(h.width))
        .f("height", num(h.height)).f("maxMessageBytes", num(h.max_message_bytes))
        .f("maxBufferBytes", num(h.max_buffer_bytes)).f("serverVersion", str(h.server_version)).str();
  }
  std::string operator()(const Frame& f) {
    const FrameTimings& t = f.timings;
    std::string timings = Obj{}.f("kernel", num(t.kernel_ms)).f("rendering", num(t.rendering_ms)).f("sat", num(t.sat_ms))
                              .f("tiling", num(t.tiling_ms)).f("pipeline", num(t.pipeline_ms)).f("encode", num(t.encode_ms))
                              .str();
    return Obj{}.f("type", q("frame")).f("frame", num(f.frame)).f("width", num(f.width)).f("height", num(f.height))
        .f("encoding", q(f.encoding == FrameEncoding::jpeg ? "jpeg" : "dxt1")).f("refinement", q(f.refined ? (f.converged ? "converged" : "refined") : "requested"))
        .f("samples", num(uint32_t(f.samples))).f("timings", timings)
        .f("payload", bytes(f.payload)).str();
  }
  std::string operator()(const ErrorReply& e) {
    return Obj{}.f("type", q("error")).f("code", num(uint32_t(e.code))).f("fatal", boolean(e.fatal))
        .f("record", num(e.record)).f("message", str(e.message)).str();
  }
  std::string operator()(const Reference& r) {
    return Obj{}.f("type", q("reference")).f("what", q(r.what == RefKind::buffer ? "buffer" : "texture"))
        .f("ok", boolean(r.ok)).f("id", num(r.id)).f("bytes", num(r.bytes)).f("message", str(r.message)).str();
  }
  std::string operator()(const Stats& s) {
    return Obj{}.f("type", q("stats")).f("frames", num(s.frames)).f("dropped", num(s.dropped))
        .f("bytesSent", num(s.bytes_sent)).f("sceneBytes", num(s.scene_bytes)).f("triangles", num(s.triangles))
        .f("nodes", num(s.nodes)).f("fps", num(s.fps)).f("meanPipelineMs", num(s.mean_pipeline_ms)).str();
  }
};

// The limits that differ from Limits{}, under their C++ names.
std::string limits_json(const Limits& l) {
  const Limits d;
  Obj o;
#define TESSERA_LIMIT(x) \
  if (l.x != d.x) o.f(#x, num(l.x));
  TESSERA_LIMIT(max_message_bytes) TESSERA_LIMIT(max_records) TESSERA_LIMIT(max_width) TESSERA_LIMIT(max_height)
  TESSERA_LIMIT(max_message_payload_bytes) TESSERA_LIMIT(max_buffer_bytes) TESSERA_LIMIT(max_client_bytes)
  TESSERA_LIMIT(max_triangles) TESSERA_LIMIT(max_vertices) TESSERA_LIMIT(max_texture_size) TESSERA_LIMIT(max_nodes)
  TESSERA_LIMIT(max_ao_samples) TESSERA_LIMIT(max_depth) TESSERA_LIMIT(max_refine_samples)
  TESSERA_LIMIT(max_frame_budget_ms)
#undef TESSERA_LIMIT
  return o.str();
}
std::string all_limits() {
  const Limits l;
  return Obj{}.f("max_message_bytes", num(l.max_message_bytes)).f("max_records", num(l.max_records))
      .f("max_width", num(l.max_width)).f("max_height", num(l.max_height))
      .f("max_message_payload_bytes", num(l.max_message_payload_bytes)).f("max_buffer_bytes", num(l.max_buffer_bytes))
      .f("max_client_bytes", num(l.max_client_bytes)).f("max_triangles", num(l.max_triangles))
      .f("max_vertices", num(l.max_vertices)).f("max_texture_size", num(l.max_texture_size))
      .f("max_nodes", num(l.max_nodes)).f("max_ao_samples", num(l.max_ao_samples)).f("max_depth", num(l.max_depth))
      .f("max_refine_samples", num(l.max_refine_samples)).f("max_frame_budget_ms", num(l.max_frame_budget_ms)).str();
}

// ---------------------------------------------------------------------------------------
// Valid messages.

std::vector<std::string> valid;

template <class Record, class Js>
void add_valid(const std::string& what, const std::vector<Record>& records, Js js, bool lossy = false) {
  const auto m = encode(records);
  std::string recs = "[";
  for (size_t i = 0; i < records.size(); ++i) recs += (i ? ", " : "") + std::visit(js, records[i]);
  recs += "]";
  std::string cpp = "ok", roundtrip = "null";
  constexpr bool client = std::is_same_v<Record, ClientRecord>;
  auto check = [&](auto r) {
    if (!r) {
      cpp = r.error().message;
      return;
    }
    bool files = false;  // a PNG/JPEG texture decodes to pixels: it cannot re-encode to its file
    if constexpr (client)
      for (const auto& x : r.value())
        if (const auto* t = std::get_if<SetTexture>(&x)) files |= t->format != TextureFormat::rgba8;
    if (!files) roundtrip = boolean(encode(r.value()) == m);
  };
  if constexpr (client) check(decode_client(m.data(), m.size(), Limits{}));
  else check(decode_server(m.data(), m.size(), Limits{}));
  valid.push_back(Obj{}.f("name", str(what)).f("channel", q(client ? "client" : "server")).f("records", recs)
                      .f("hex", str(hex(m))).f("cpp", str(cpp)).f("cpp_roundtrip", roundtrip).f("lossy", boolean(lossy))
                      .str());
}
void client(const std::string& what, std::vector<ClientRecord> r) { add_valid(what, r, ClientJs{}); }
void server(const std::string& what, std::vector<ServerRecord> r, bool lossy = false) {
  add_valid(what, r, ServerJs{}, lossy);
}

// Sample records (each field a distinct value, so a swapped pair shows).
Handshake handshake() {
  Handshake h;
  h.renderer = RendererKind::rasterizer;
  h.display = DisplayKind::s3tc;
  h.jpeg_quality = 80;
  h.max_nodes = 3;
  h.width = 320;
  h.height = 240;
  return h;
}
SetCamera camera() {
  SetCamera c;
  c.camera.to_world = Mat4::look_at({1, 2, 3}, {0, 0.5f, 0}, {0, 1, 0});
  c.camera.fov_y = 0.8f;
  return c;
}
SetEnvironment environment() {
  SetEnvironment e;
  e.environment.ambient = {0.1f, 0.2f, 0.3f};
  e.environment.background = {0.5f, 0.25f, 0.125f};
  e.environment.exposure = 1.5f;
  e.environment.linear = false;
  return e;
}
SetBuffer f32_buffer(Id id, std::vector<float> v, uint8_t comps, bool deflate = false) {
  SetBuffer b;
  b.id = id;
  b.buffer.type = Buffer::Type::f32;
  b.buffer.components = comps;
  b.buffer.f = std::move(v);
  b.deflate = deflate;
  return b;
}
SetBuffer u32_buffer(Id id, std::vector<uint32_t> v, uint8_t comps) {
  SetBuffer b;
  b.id = id;
  b.buffer.type = Buffer::Type::u32;
  b.buffer.components = comps;
  b.buffer.u = std::move(v);
  return b;
}
SetTexture rgba_texture(Id id, int w, int h) {
  SetTexture t;
  t.id = id;
  t.format = TextureFormat::rgba8;
  t.texture.width = w;
  t.texture.height = h;
  t.texture.rgba.resize(size_t(w) * size_t(h) * 4);
  for (size_t i = 0; i < t.texture.rgba.size(); ++i) t.texture.rgba[i] = uint8_t(i * 37 + 11);
  t.texture.sampler.wrap_s = Sampler::Wrap::clamp;
  t.texture.sampler.wrap_t = Sampler::Wrap::repeat;
  t.texture.sampler.filter = Sampler::Filter::nearest;
  t.texture.srgb = false;
  return t;
}
Image test_image(int w, int h) {
  Image img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t* p = &img.rgba[(size_t(y) * size_t(w) + size_t(x)) * 4];
      p[0] = uint8_t(x * 15), p[1] = uint8_t(y * 25), p[2] = uint8_t((x + y) * 7), p[3] = 255;
    }
  return img;
}
std::vector<uint8_t> png_file(int w, int h) {
  const auto path = std::filesystem::temp_directory_path() / ("tessera_golden_" + std::to_string(::getpid()) + ".png");
  write_png(path.string(), test_image(w, h));
  std::ifstream f(path, std::ios::binary);
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), {});
  std::filesystem::remove(path);
  return b;
}
std::vector<uint8_t> jpeg_file(int w, int h) {
  JpegEncoder enc;
  std::vector<uint8_t> out;
  std::string err;
  if (!enc.encode(test_image(w, h), 90, out, err)) throw std::runtime_error(err);
  return out;
}
SetTexture file_texture(Id id, TextureFormat f, int w, int h) {
  SetTexture t = rgba_texture(id, w, h);
  t.texture.rgba.clear();
  t.format = f;
  t.encoded = f == TextureFormat::png ? png_file(w, h) : jpeg_file(w, h);
  return t;
}
SetMaterial material() {
  SetMaterial s;
  s.id = 10;
  Material& m = s.material;
  m.model = Material::Model::diffuse;
  m.alpha_mask = true;
  m.double_sided = false;
  m.diffuse_color = {0.5f, 0.25f, 1};
  m.specular_color = {1, 0.75f, 0.625f};
  m.shininess = 0.2f;
  m.emissive_color = {0, 0.1f, 0.05f};
  m.ambient_intensity = 0.3f;
  m.opacity = 0.75f;
  m.diffuse_texture = 9;
  m.specular_texture = 8;
  m.emissive_texture = 7;
  m.reflection = 0.1f;
  m.refraction = 0.9f;
  m.ior = 1.5f;
  m.alpha_cutoff = 0.4f;
  return s;
}
SetMesh mesh() {
  SetMesh s;
  s.id = 11;
  s.mesh.positions = 7;
  s.mesh.normals = 6;
  s.mesh.texcoords = 5;
  s.mesh.colors = 4;
  s.mesh.indices = 8;
  s.mesh.material = 10;
  s.mesh.transform = Mat4::translate({1, -2, 3}) * Mat4::scale({2, 3, 4});
  s.mesh.visible = false;
  return s;
}
SetLight light(Light::Type type) {
  SetLight s;
  s.id = 12;
  Light& l = s.light;
  l.type = type;
  l.color = {1, 0.5f, 0.25f};
  l.intensity = 2;
  l.position = {1, 2, 3};
  l.direction = {0, -1, 0.5f};
  l.attenuation = {1, 0.5f, 0.1f};
  l.cutoff = 0.4f;
  l.softness = 0.5f;
  l.on = true;
  return s;
}
SetBufferRef buffer_ref() {
  SetBufferRef b;
  b.id = 13;
  b.type = Buffer::Type::f32;
  b.components = 3;
  b.source = SourceType::f32;
  b.value_count = 300;
  b.byte_stride = 24;
  b.byte_offset = 5000000000ull;
  b.url = "http://127.0.0.1:8080/scenes/kitchen/scene_0.bin";
  return b;
}
SetTextureRef texture_ref() {
  SetTextureRef t;
  t.id = 14;
  t.sampler.wrap_s = Sampler::Wrap::clamp;
  t.sampler.wrap_t = Sampler::Wrap::repeat;
  t.sampler.filter = Sampler::Filter::nearest;
  t.srgb = false;
  t.url = "https://assets.example/textures/a%20b.png?v=2";
  return t;
}
Reference reference() {
  Reference r;
  r.what = RefKind::texture;
  r.ok = false;
  r.id = 14;
  r.bytes = 0;
  r.message = "https://assets.example is not in tessera.asset-origins";
  return r;
}
HandshakeReply handshake_reply() {
  HandshakeReply r;
  r.renderer = RendererKind::rasterizer;
  r.display = DisplayKind::mjpeg;
  r.jpeg_quality = 85;
  r.nodes = 2;
  r.width = 320;
  r.height = 240;
  r.max_message_bytes = 1000000;
  r.max_buffer_bytes = 5000000000ull;
  r.server_version = "tessera 0.1.0";
  return r;
}
Frame frame(FrameEncoding e, int32_t w, int32_t h) {
  Frame f;
  f.frame = 42;
  f.width = w;
  f.height = h;
  f.encoding = e;
  f.timings = {1, 2, 3, 4, 5, 6};
  f.payload.resize(e == FrameEncoding::dxt1 ? size_t((w + 3) / 4) * size_t((h + 3) / 4) * 8 : 13);
  for (size_t i = 0; i < f.payload.size(); ++i) f.payload[i] = uint8_t(i * 29 + 3);
  return f;
}
ErrorReply error_reply() {
  ErrorReply e;
  e.code = ErrorCode::bad_mesh;
  e.fatal = false;
  e.record = 3;
  e.message = "mesh 11: bad";
  return e;
}
Stats stats() {
  Stats s;
  s.frames = 10;
  s.dropped = 1;
  s.bytes_sent = 12345;
  s.scene_bytes = 678;
  s.triangles = 91011;
  s.nodes = 2;
  s.fps = 30;
  s.mean_pipeline_ms = 12.5f;
  return s;
}

void valid_messages() {
  // Client channel.
  client("handshake", {handshake()});
  {
    Handshake lo = handshake(), hi = handshake();
    lo.renderer = RendererKind::raytracer, lo.display = DisplayKind::jpeg, lo.jpeg_quality = 1, lo.max_nodes = 0;
    lo.width = lo.height = 1;
    hi.display = DisplayKind::mjpeg, hi.jpeg_quality = 100, hi.max_nodes = Limits{}.max_nodes;
    hi.width = Limits{}.max_width, hi.height = Limits{}.max_height;
    client("handshake, lowest values", {lo});
    client("handshake, highest values", {hi});
  }
  client("settings and resolution at both ends",
         {Settings{0, 0}, Settings{Limits{}.max_ao_samples, Limits{}.max_depth}, Settings{16, 5}, Resolution{1, 1},
          Resolution{Limits{}.max_width, Limits{}.max_height}, Resolution{640, 360}});
  {
    SetCamera wide = camera(), narrow = camera(), far = camera();
    wide.camera.fov_y = std::nextafter(kPi, 0.0f);
    narrow.camera.fov_y = kDenorm;
    far.camera.to_world = Mat4::translate({4294967296.0f, -4294967296.0f, 0}) * Mat4::scale({65536, 65536, 65536});
    client("cameras: fov at both ends, the largest translation and scale", {camera(), wide, narrow, far});
  }
  {
    SetEnvironment zero, big = environment();
    zero.environment.ambient = zero.environment.background = {0, -0.0f, 0};
    zero.environment.exposure = kDenorm;
    zero.environment.linear = true;
    big.environment.ambient = {kMaxF, kMaxF, kMaxF};
    big.environment.exposure = kMaxF;
    client("environments: zero and largest values", {environment(), zero, big});
  }
  client("buffers: floats of every kind, u32 ends, 1..4 components, empty",
         {f32_buffer(7, {0, -0.0f, 1, kNaN, kInf, -kInf, kDenorm, kMaxF, -1.5f}, 3), u32_buffer(8, {0, 1, 2, kMaxU32}, 1),
          f32_buffer(kMaxU32, {1, 2, 3, 4, 5, 6, 7, 8}, 4), u32_buffer(1, {5, 6}, 2), f32_buffer(2, {}, 1)});
  {
    std::vector<float> v(300);
    for (size_t i = 0; i < v.size(); ++i) v[i] = float(i % 17) * 0.25f;
    client("deflated buffer", {f32_buffer(3, v, 3, true)});
  }
  {
    SetTexture wide = rgba_texture(4, Limits{}.max_texture_size, 1), srgb = rgba_texture(kMaxU32, 1, 1);
    srgb.texture.srgb = true;
    srgb.texture.sampler.wrap_s = Sampler::Wrap::repeat, srgb.texture.sampler.wrap_t = Sampler::Wrap::clamp;
    srgb.texture.sampler.filter = Sampler::Filter::linear;
    client("textures: RGBA8, the widest, every sampler field", {rgba_texture(9, 1, 2), wide, srgb});
  }
  client("textures: PNG and JPEG files",
         {file_texture(20, TextureFormat::png, 3, 2), file_texture(21, TextureFormat::jpeg, 16, 9)});
  {
    SetMaterial lo = material(), hi = material(), matte = material(), flags = material();
    Material& l = lo.material;
    l.model = Material::Model::phong;
    l.diffuse_color = l.specular_color = l.emissive_color = {0, 0, -0.0f};
    l.shininess = l.ambient_intensity = l.opacity = l.reflection = l.refraction = l.alpha_cutoff = 0;
    l.ior = wire::material::ior.lo;
    l.diffuse_texture = l.specular_texture = l.emissive_texture = 0;
    l.alpha_mask = false;
    Material& h = hi.material;
    h.diffuse_color = h.specular_color = h.emissive_color = {kMaxF, kMaxF, kMaxF};
    h.shininess = wire::material::shininess.hi, h.ambient_intensity = wire::material::ambient_intensity.hi;
    h.opacity = h.reflection = h.refraction = h.alpha_cutoff = 1;
    h.ior = wire::material::ior.hi;
    h.diffuse_texture = h.specular_texture = h.emissive_texture = kMaxU32;
    h.double_sided = true;
    matte.material.model = Material::Model::matte;
    matte.id = kMaxU32;
    flags.material.alpha_mask = flags.material.double_sided = flags.material.use_vertex_color = true;
    SetMaterial vertex_color = material();
    vertex_color.material.alpha_mask = false;
    vertex_color.material.use_vertex_color = true;
    client("materials: every model and flag, ranges at both ends", {material(), lo, hi, matte, flags, vertex_color});
  }
  {
    SetMesh bare, big = mesh(), shown = mesh();
    bare.id = 1, bare.mesh.positions = 2;
    big.id = big.mesh.positions = big.mesh.normals = big.mesh.texcoords = big.mesh.colors = big.mesh.indices =
        big.mesh.material = kMaxU32;
    big.mesh.transform = Mat4::translate({-4294967296.0f, 0, 4294967296.0f}) * Mat4::scale({1024, 1024, 1024});
    shown.mesh.visible = true;
    client("meshes: bare, largest ids and transform, visible", {mesh(), bare, big, shown});
  }
  {
    SetLight point = light(Light::Type::point), off = light(Light::Type::directional), lo = light(Light::Type::spot);
    SetLight hi = light(Light::Type::spot);
    point.light.direction = {0, 0, 0};  // unused by point lights
    point.light.position = {4294967296.0f, -4294967296.0f, 0};
    off.light.on = false;
    off.light.cast_shadow = false;
    off.light.attenuation = {0, 0, 0};  // unused by directional lights
    off.light.position = {kMaxF, -kMaxF, 0};
    lo.light.color = {0, 0, 0}, lo.light.intensity = 0, lo.light.softness = 0, lo.light.cutoff = kDenorm;
    hi.light.intensity = wire::light::intensity.hi, hi.light.cutoff = wire::light::cutoff.hi, hi.light.softness = 1;
    hi.light.direction = {1e18f, 0, 0};
    hi.id = kMaxU32;
    client("lights: every type, on and off, casting shadows or not, ranges at both ends", {light(Light::Type::spot), point, off, lo, hi});
  }
  client("removes of every kind", {Remove{RecordType::buffer, 1}, Remove{RecordType::texture, 2},
                                   Remove{RecordType::material, 3}, Remove{RecordType::mesh, 4},
                                   Remove{RecordType::light, kMaxU32}});
  client("render requests", {RenderRequest{0}, RenderRequest{42}, RenderRequest{kMaxU32}});
  client("refine: off, one sample, a target, the limit", {Refine{0}, Refine{1}, Refine{64}, Refine{Limits{}.max_refine_samples}});
  client("budget: off, 1 ms, 33 ms, the limit", {Budget{0}, Budget{1}, Budget{33}, Budget{Limits{}.max_frame_budget_ms}});
  client("video: unchanged, a keyframe alone, both ends of the bitrate",
         {Video{0, false}, Video{0, true}, Video{kMinVideoKbps, false}, Video{wire::video::bitrate_kbps.hi, true}});
  {
    SetBufferRef packed = buffer_ref(), u16 = buffer_ref(), u8 = buffer_ref(), u32 = buffer_ref();
    packed.byte_stride = 0, packed.byte_offset = 0, packed.components = 4, packed.value_count = 0;
    packed.url = std::string(wire::buffer_ref::url_max_length, 'u');
    u16.type = Buffer::Type::u32, u16.source = SourceType::u16, u16.components = 1, u16.byte_stride = 2;
    u16.id = kMaxU32, u16.byte_offset = kMaxU64;
    u8.type = Buffer::Type::u32, u8.source = SourceType::u8, u8.components = 2, u8.byte_stride = 252;
    u8.url = "http://h/\xc3\xa9.bin";
    u32.type = Buffer::Type::u32, u32.source = SourceType::u32, u32.components = 1, u32.byte_stride = 0;
    u32.value_count = Limits{}.max_vertices;
    client("buffer references: every source, stride and offset at both ends, the longest url", {buffer_ref(), packed, u16, u8, u32});
    SetTextureRef srgb = texture_ref();
    srgb.srgb = true, srgb.sampler.filter = Sampler::Filter::linear, srgb.sampler.wrap_s = Sampler::Wrap::repeat;
    srgb.id = kMaxU32, srgb.url = "x";
    client("texture references: every sampler field", {texture_ref(), srgb});
  }
  client("every client record in one message",
         {Settings{16, 5}, Refine{32}, Budget{33}, Video{4000, true}, Resolution{640, 360}, camera(), environment(),
          f32_buffer(7, {0, 0, 0, 1, 0, 0, 0, 1, 0}, 3), u32_buffer(8, {0, 1, 2}, 1), rgba_texture(9, 1, 2), material(),
          mesh(), light(Light::Type::spot), Remove{RecordType::mesh, 5}, RenderRequest{42}, buffer_ref(), texture_ref()});

  // Server channel.
  server("handshake reply", {handshake_reply()});
  {
    HandshakeReply lo = handshake_reply(), hi = handshake_reply(), cut = handshake_reply(), utf = handshake_reply();
    lo.renderer = RendererKind::raytracer, lo.display = DisplayKind::jpeg, lo.jpeg_quality = 1, lo.nodes = 0;
    lo.width = lo.height = 1, lo.max_message_bytes = 0, lo.max_buffer_bytes = 0, lo.server_version.clear();
    hi.display = DisplayKind::s3tc, hi.jpeg_quality = 100, hi.nodes = kMaxU32, hi.width = Limits{}.max_width;
    hi.height = Limits{}.max_height, hi.max_message_bytes = kMaxU32, hi.max_buffer_bytes = kMaxU64;
    hi.server_version = std::string(wire::handshake_reply::server_version_max_length, 'v');
    utf.server_version = "tessera \xc3\xa9\xe2\x82\xac \xf0\x9f\x9a\x80";
    server("handshake replies: lowest and highest values, UTF-8", {lo, hi, utf});
    cut.server_version = std::string(300, 'w');
    server("handshake reply: a version beyond 255 bytes is cut", {cut}, true);
  }
  {
    Frame odd = frame(FrameEncoding::jpeg, 7, 5), big = frame(FrameEncoding::jpeg, Limits{}.max_width, Limits{}.max_height);
    odd.frame = kMaxU32;
    odd.timings = {kNaN, kInf, -kInf, -0.0f, kDenorm, kMaxF};
    big.frame = 0;
    big.payload.clear();
    server("frames: DXT1 and JPEG, odd sizes, every kind of float",
           {frame(FrameEncoding::dxt1, 5, 3), frame(FrameEncoding::dxt1, 1, 1), odd, big});
    Frame refined = frame(FrameEncoding::jpeg, 7, 5), top = frame(FrameEncoding::dxt1, 5, 3), two = refined;
    refined.refined = true, refined.samples = 17;
    top.refined = true, top.samples = 0xffff, top.converged = true;
    two.samples = 2;
    server("frames: refined, the most samples, a requested frame of 2 samples", {refined, top, two});
    Frame none = frame(FrameEncoding::jpeg, 7, 5);
    none.samples = 0;
    server("frame: 0 samples are written as 1", {none}, true);
  }
  {
    std::vector<ServerRecord> every;
    for (uint16_t c = 0; c <= kMaxErrorCode; ++c) {
      ErrorReply e = error_reply();
      e.code = ErrorCode(c);
      e.fatal = is_fatal(e.code);
      e.record = c % 2 ? kNoRecord : c;
      e.message = std::string(to_string(e.code)) + " \"quoted\" \\ \xc3\xa9";
      every.push_back(e);
    }
    server("errors: every code on the wire", every);
    ErrorReply empty = error_reply(), cut = error_reply();
    empty.message.clear();
    empty.fatal = true;
    cut.message = std::string(wire::error::message_max_length + 100, 'm');
    server("error: empty message", {empty});
    server("error: a message beyond 65535 bytes is cut", {cut}, true);
  }
  {
    Stats zero, top = stats();
    zero.nodes = 0;
    top.frames = top.dropped = top.nodes = kMaxU32;
    top.bytes_sent = top.scene_bytes = top.triangles = kMaxU64;
    top.fps = kNaN, top.mean_pipeline_ms = kInf;
    server("stats: zero, largest and non-finite values", {stats(), zero, top});
  }
  {
    Reference loaded = reference(), cut = reference();
    loaded.what = RefKind::buffer, loaded.ok = true, loaded.id = kMaxU32, loaded.bytes = kMaxU64, loaded.message.clear();
    server("references: refused and loaded", {reference(), loaded});
    cut.message = std::string(wire::reference::message_max_length + 10, 'r');
    server("reference: a message beyond 65535 bytes is cut", {cut}, true);
  }
  server("every server record in one message",
         {handshake_reply(), frame(FrameEncoding::dxt1, 4, 4), error_reply(), stats(), reference()});
}

// ---------------------------------------------------------------------------------------
// Malformed messages: a valid one changed in one place.

std::vector<std::string> invalid;
using Bytes = std::vector<uint8_t>;

template <class T>
Bytes put(Bytes m, size_t at, T v) {
  if (at + sizeof(T) > m.size()) throw std::runtime_error("put beyond the message");
  std::memcpy(m.data() + at, &v, sizeof(T));
  return m;
}
// Record 0's body set to n bytes (cut, or padded with zeros), its length field too.
Bytes body_length(Bytes m, size_t n) {
  m.resize(kB + n);
  return put<uint32_t>(m, kMessageHeaderSize + 4, uint32_t(n));
}
Bytes one(const ClientRecord& r) { return encode(r); }
Bytes one(const ServerRecord& r) { return encode(r); }
Bytes mat3_at(Bytes m, size_t at, float sx, float sy, float sz) {  // a diagonal upper 3x3 (column-major)
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m = put(m, at + size_t(j * 4 + i) * 4, i != j ? 0.0f : i == 0 ? sx : i == 1 ? sy : sz);
  return m;
}

void bad(const std::string& what, Channel ch, const Bytes& m, ErrorCode expect, const Limits& lim = {}) {
  std::string code = "ok";
  uint32_t record = kNoRecord;
  auto note = [&](const auto& r) {
    if (!r) code = to_string(r.error().code), record = r.error().record;
  };
  if (ch == Channel::client) note(decode_client(m.data(), m.size(), lim));
  else note(decode_server(m.data(), m.size(), lim));
  invalid.push_back(Obj{}.f("name", str(what)).f("channel", q(ch == Channel::client ? "client" : "server"))
                        .f("hex", str(hex(m))).f("limits", limits_json(lim)).f("expect", q(to_string(expect)))
                        .f("code", str(code)).f("record", num(record)).str());
}
void bad_client(const std::string& what, const Bytes& m, ErrorCode expect, const Limits& lim = {}) {
  bad(what, Channel::client, m, expect, lim);
}
void bad_server(const std::string& what, const Bytes& m, ErrorCode expect, const Limits& lim = {}) {
  bad(what, Channel::server, m, expect, lim);
}

void framing(Channel ch, const Bytes& good) {
  const std::string side = ch == Channel::client ? "client: " : "server: ";
  auto b = [&](const std::string& w, const Bytes& m, ErrorCode e, const Limits& lim = {}) { bad(side + w, ch, m, e, lim); };
  Limits small;
  small.max_message_bytes = uint32_t(good.size() - 1);
  b("message beyond max_message_bytes", good, ErrorCode::too_large, small);
  b("empty message", {}, ErrorCode::truncated);
  b("message shorter than its header", Bytes(good.begin(), good.begin() + 7), ErrorCode::truncated);
  b("bad magic", put<uint8_t>(good, 0, 'X'), ErrorCode::bad_magic);
  b("bad magic, second byte", put<uint8_t>(good, 1, 's'), ErrorCode::bad_magic);
  b("version 1 (before vertex colours)", put<uint8_t>(good, 2, 1), ErrorCode::bad_version);
  b("version 2 (before references)", put<uint8_t>(good, 2, 2), ErrorCode::bad_version);
  b("the next version", put<uint8_t>(good, 2, kVersion + 1), ErrorCode::bad_version);
  b("version 0", put<uint8_t>(good, 2, 0), ErrorCode::bad_version);
  b("the other channel", put<uint8_t>(good, 3, ch == Channel::client ? 1 : 0), ErrorCode::bad_channel);
  b("channel 2", put<uint8_t>(good, 3, 2), ErrorCode::bad_channel);
  b("no records", put<uint32_t>(Bytes(good.begin(), good.begin() + 8), 4, 0), ErrorCode::bad_length);
  b("record count beyond max_records", put<uint32_t>(good, 4, Limits{}.max_records + 1), ErrorCode::too_large);
  b("record count that cannot fit", put<uint32_t>(good, 4, uint32_t(good.size())), ErrorCode::truncated);
  {
    Bytes two = good;
    two.resize(good.size() + 7);
    b("second record's header cut", put<uint32_t>(two, 4, 2), ErrorCode::truncated);
  }
  b("body longer than the message", put<uint32_t>(good, 12, uint32_t(good.size())), ErrorCode::truncated);
  b("record type 0", put<uint8_t>(good, 8, 0), ErrorCode::unknown_record);
  b("record type 0x30", put<uint8_t>(good, 8, 0x30), ErrorCode::unknown_record);
  b("record type 0xff", put<uint8_t>(good, 8, 0xff), ErrorCode::unknown_record);
  b("a record of the other channel",
    put<uint8_t>(good, 8, uint8_t(ch == Channel::client ? RecordType::stats : RecordType::settings)),
    ErrorCode::unknown_record);
  b("op 2", put<uint8_t>(good, 9, 2), ErrorCode::bad_op);
  b("reserved header field", put<uint16_t>(good, 10, 1), ErrorCode::bad_reserved);
  b("reserved header field, high byte", put<uint16_t>(good, 10, 0x100), ErrorCode::bad_reserved);
  {
    Bytes extra = good;
    extra.push_back(0);
    b("a byte after the last record", extra, ErrorCode::bad_length);
  }
}

void client_records() {
  const Limits d;
  // Lengths: one byte short and one long, for every fixed-size record.
  const std::vector<std::pair<std::string, ClientRecord>> fixed = {
      {"handshake", handshake()}, {"settings", Settings{16, 5}}, {"resolution", Resolution{640, 360}},
      {"camera", camera()},       {"environment", environment()}, {"material", material()},
      {"mesh", mesh()},           {"light", light(Light::Type::spot)}, {"render", RenderRequest{1}},
      {"remove", Remove{RecordType::mesh, 5}}, {"refine", Refine{64}}, {"budget", Budget{33}},
      {"video", Video{4000, false}}};
  for (const auto& [n, r] : fixed) {
    const Bytes m = one(r);
    const size_t len = m.size() - kB;
    bad_client(n + ": body one byte short", body_length(m, len - 1), ErrorCode::bad_length);
    bad_client(n + ": body one byte long", body_length(m, len + 1), ErrorCode::bad_length);
  }
  // Op remove where it is not defined.
  for (const auto& [n, r] : std::vector<std::pair<std::string, ClientRecord>>{
           {"handshake", handshake()}, {"settings", Settings{}}, {"resolution", Resolution{}}, {"camera", camera()},
           {"environment", environment()}, {"render", RenderRequest{1}}, {"refine", Refine{64}},
           {"budget", Budget{33}}, {"video", Video{4000, false}}})
    bad_client(n + ": op remove", put<uint8_t>(one(r), 9, 1), ErrorCode::bad_op);
  for (auto t : {RecordType::buffer, RecordType::texture, RecordType::material, RecordType::mesh, RecordType::light})
    bad_client(std::string("remove ") + to_string(t) + ": id 0", one(Remove{t, 0}), ErrorCode::bad_id);

  // Handshake.
  {
    const Bytes h = one(handshake());
    using namespace wire::handshake;
    bad_client("handshake: renderer 2", put<uint8_t>(h, kB + at::renderer, 2), ErrorCode::bad_enum);
    bad_client("handshake: display 4", put<uint8_t>(h, kB + at::display, 4), ErrorCode::bad_enum);
    bad_client("handshake: display 255", put<uint8_t>(h, kB + at::display, 255), ErrorCode::bad_enum);
    bad_client("handshake: reserved", put<uint8_t>(h, kB + at::reserved, 1), ErrorCode::bad_reserved);
    bad_client("handshake: jpeg_quality 0", put<uint8_t>(h, kB + at::jpeg_quality, 0), ErrorCode::out_of_range);
    bad_client("handshake: jpeg_quality 101", put<uint8_t>(h, kB + at::jpeg_quality, 101), ErrorCode::out_of_range);
    bad_client("handshake: max_nodes beyond the limit", put<uint32_t>(h, kB + at::max_nodes, d.max_nodes + 1),
               ErrorCode::limit_exceeded);
    bad_client("handshake: width 0", put<uint32_t>(h, kB + at::width, 0), ErrorCode::out_of_range);
    bad_client("handshake: height 0", put<uint32_t>(h, kB + at::height, 0), ErrorCode::out_of_range);
    bad_client("handshake: width 0 and height beyond the limit",
               put<uint32_t>(put<uint32_t>(h, kB + at::width, 0), kB + at::height, kMaxU32), ErrorCode::out_of_range);
    bad_client("handshake: width beyond the limit", put<uint32_t>(h, kB + at::width, uint32_t(d.max_width) + 1),
               ErrorCode::limit_exceeded);
    bad_client("handshake: height beyond the limit", put<uint32_t>(h, kB + at::height, uint32_t(d.max_height) + 1),
               ErrorCode::limit_exceeded);
    Bytes two = encode(std::vector<ClientRecord>{handshake(), Settings{}});
    bad_client("handshake not alone in its message", two, ErrorCode::bad_handshake);
    bad_client("handshake after another record", encode(std::vector<ClientRecord>{Settings{}, handshake()}),
               ErrorCode::bad_handshake);
  }
  // Settings and resolution.
  {
    const Bytes s = one(Settings{16, 5}), r = one(Resolution{640, 360});
    bad_client("settings: ao_samples beyond the limit",
               put<uint32_t>(s, kB + wire::settings::at::ao_samples, d.max_ao_samples + 1), ErrorCode::limit_exceeded);
    bad_client("settings: max_depth beyond the limit",
               put<uint32_t>(s, kB + wire::settings::at::max_depth, d.max_depth + 1), ErrorCode::limit_exceeded);
    const Bytes f = one(Refine{64});
    bad_client("refine: samples beyond the limit",
               put<uint32_t>(f, kB + wire::refine::at::samples, d.max_refine_samples + 1), ErrorCode::limit_exceeded);
    bad_client("refine: samples 0xffffffff", put<uint32_t>(f, kB + wire::refine::at::samples, kMaxU32),
               ErrorCode::limit_exceeded);
    Limits few;
    few.max_refine_samples = 63;
    bad_client("refine: samples beyond a node's lower limit", f, ErrorCode::limit_exceeded, few);
    const Bytes b = one(Budget{33});
    bad_client("budget: frame_ms beyond the limit",
               put<uint32_t>(b, kB + wire::budget::at::frame_ms, d.max_frame_budget_ms + 1), ErrorCode::limit_exceeded);
    bad_client("budget: frame_ms 0xffffffff", put<uint32_t>(b, kB + wire::budget::at::frame_ms, kMaxU32),
               ErrorCode::limit_exceeded);
    Limits quick;
    quick.max_frame_budget_ms = 32;
    bad_client("budget: frame_ms beyond a node's lower limit", b, ErrorCode::limit_exceeded, quick);
    const Bytes v = one(Video{4000, false});
    bad_client("video: bitrate_kbps 1 (below 100, not 0)", put<uint32_t>(v, kB + wire::video::at::bitrate_kbps, 1),
               ErrorCode::out_of_range);
    bad_client("video: bitrate_kbps 99", put<uint32_t>(v, kB + wire::video::at::bitrate_kbps, kMinVideoKbps - 1),
               ErrorCode::out_of_range);
    bad_client("video: bitrate_kbps beyond 200000",
               put<uint32_t>(v, kB + wire::video::at::bitrate_kbps, wire::video::bitrate_kbps.hi + 1), ErrorCode::out_of_range);
    bad_client("video: keyframe 2", put<uint8_t>(v, kB + wire::video::at::keyframe, 2), ErrorCode::bad_enum);
    bad_client("video: reserved byte set", put<uint8_t>(v, kB + wire::video::at::keyframe + 2, 1), ErrorCode::bad_reserved);
    bad_client("resolution: width 0", put<uint32_t>(r, kB + wire::resolution::at::width, 0), ErrorCode::out_of_range);
    bad_client("resolution: height 0", put<uint32_t>(r, kB + wire::resolution::at::height, 0), ErrorCode::out_of_range);
    bad_client("resolution: width beyond the limit", put<uint32_t>(r, kB + wire::resolution::at::width, kMaxU32),
               ErrorCode::limit_exceeded);
    bad_client("resolution: height beyond the limit",
               put<uint32_t>(r, kB + wire::resolution::at::height, uint32_t(d.max_height) + 1), ErrorCode::limit_exceeded);
  }
  // Camera.
  {
    const Bytes c = one(camera());
    using namespace wire::camera;
    const size_t m = kB + at::to_world;
    bad_client("camera: NaN in to_world", put(c, m, kNaN), ErrorCode::not_finite);
    bad_client("camera: infinity in to_world's bottom row", put(c, m + 15 * 4, kInf), ErrorCode::not_finite);
    bad_client("camera: fov_y infinite", put(c, kB + at::fov_y, kInf), ErrorCode::not_finite);
    bad_client("camera: fov_y NaN", put(c, kB + at::fov_y, kNaN), ErrorCode::not_finite);
    bad_client("camera: fov_y 0", put(c, kB + at::fov_y, 0.0f), ErrorCode::out_of_range);
    bad_client("camera: fov_y -0", put(c, kB + at::fov_y, -0.0f), ErrorCode::out_of_range);
    bad_client("camera: fov_y pi", put(c, kB + at::fov_y, kPi), ErrorCode::out_of_range);
    bad_client("camera: fov_y negative", put(c, kB + at::fov_y, -0.5f), ErrorCode::out_of_range);
    bad_client("camera: singular to_world", mat3_at(c, m, 1, 1, 0), ErrorCode::out_of_range);
    SetCamera big = camera(), tiny = camera(), skew = camera(), far = camera();
    big.camera.to_world = Mat4::scale({70000, 1, 1});
    tiny.camera.to_world = Mat4::scale({1e-5f, 1e-5f, 1e-5f});
    skew.camera.to_world = Mat4::scale({1000, 0.0005f, 1});
    far.camera.to_world = Mat4::translate({0, 0, 1e10f});
    bad_client("camera: scale beyond the camera limit", one(big), ErrorCode::out_of_range);
    bad_client("camera: nearly singular", one(tiny), ErrorCode::out_of_range);
    bad_client("camera: ill-conditioned", one(skew), ErrorCode::out_of_range);
    bad_client("camera: translation beyond the limit", one(far), ErrorCode::out_of_range);
  }
  // Environment.
  {
    const Bytes e = one(environment());
    using namespace wire::environment;
    bad_client("environment: ambient NaN", put(e, kB + at::ambient + 4, kNaN), ErrorCode::not_finite);
    bad_client("environment: ambient negative", put(e, kB + at::ambient, -0.5f), ErrorCode::out_of_range);
    bad_client("environment: background negative", put(e, kB + at::background + 8, -kDenorm), ErrorCode::out_of_range);
    bad_client("environment: background infinite", put(e, kB + at::background, kInf), ErrorCode::not_finite);
    bad_client("environment: exposure infinite", put(e, kB + at::exposure, kInf), ErrorCode::not_finite);
    bad_client("environment: exposure 0", put(e, kB + at::exposure, 0.0f), ErrorCode::out_of_range);
    bad_client("environment: exposure negative", put(e, kB + at::exposure, -1.0f), ErrorCode::out_of_range);
    bad_client("environment: linear 2", put<uint8_t>(e, kB + at::linear, 2), ErrorCode::bad_enum);
    bad_client("environment: reserved", put<uint8_t>(e, kB + at::reserved + 2, 1), ErrorCode::bad_reserved);
  }
  // Buffers.
  {
    const Bytes b = one(f32_buffer(7, {0, 0, 0, 1, 0, 0, 0, 1, 0}, 3));
    using namespace wire::buffer;
    bad_client("buffer: body shorter than its fixed part", body_length(b, kFixed - 1), ErrorCode::bad_length);
    bad_client("buffer: id 0", put<uint32_t>(b, kB + at::id, 0), ErrorCode::bad_id);
    bad_client("buffer: type 2", put<uint8_t>(b, kB + at::type, 2), ErrorCode::bad_enum);
    bad_client("buffer: reserved", put<uint8_t>(b, kB + at::reserved, 1), ErrorCode::bad_reserved);
    bad_client("buffer: unknown flag", put<uint8_t>(b, kB + at::flags, 2), ErrorCode::bad_reserved);
    bad_client("buffer: 0 components", put<uint8_t>(b, kB + at::components, 0), ErrorCode::bad_components);
    bad_client("buffer: 5 components", put<uint8_t>(b, kB + at::components, 5), ErrorCode::bad_components);
    bad_client("buffer: values not a multiple of components", put<uint8_t>(b, kB + at::components, 2),
               ErrorCode::bad_components);
    Limits lim;
    lim.max_buffer_bytes = 32;
    bad_client("buffer: beyond max_buffer_bytes", b, ErrorCode::limit_exceeded, lim);
    lim = {};
    lim.max_vertices = 2;
    bad_client("buffer: elements beyond max_vertices", b, ErrorCode::limit_exceeded, lim);
    bad_client("buffer: value_count beyond the default limit", put<uint32_t>(b, kB + at::value_count, 0xfffffff0u),
               ErrorCode::limit_exceeded);
    bad_client("buffer: payload shorter than value_count x 4", body_length(b, b.size() - kB - 4), ErrorCode::bad_length);
    bad_client("buffer: payload longer than value_count x 4", body_length(b, b.size() - kB + 4), ErrorCode::bad_length);
    lim = {};
    lim.max_message_payload_bytes = 40;
    bad_client("buffers: the message's payload beyond its limit",
               encode(std::vector<ClientRecord>{f32_buffer(1, {1, 2, 3, 4, 5, 6}, 3), f32_buffer(2, {1, 2, 3, 4, 5, 6}, 3)}),
               ErrorCode::limit_exceeded, lim);
    // Deflated payloads.
    std::vector<float> v(64, 0.5f);
    const Bytes z = one(f32_buffer(3, v, 1, true));
    bad_client("deflated buffer: declares more than it inflates to", put<uint32_t>(z, kB + at::value_count, 65),
               ErrorCode::bad_payload);
    bad_client("deflated buffer: declares less than it inflates to", put<uint32_t>(z, kB + at::value_count, 63),
               ErrorCode::bad_payload);
    bad_client("deflated buffer: declares 0 values", put<uint32_t>(z, kB + at::value_count, 0), ErrorCode::bad_payload);
    bad_client("deflated buffer: stream cut", body_length(z, z.size() - kB - 3), ErrorCode::bad_payload);
    Bytes trailing = body_length(z, z.size() - kB + 2);
    bad_client("deflated buffer: bytes after the stream", trailing, ErrorCode::bad_payload);
    bad_client("deflated buffer: corrupt stream", put<uint8_t>(z, kB + kFixed + 2, 0xff), ErrorCode::bad_payload);
    bad_client("deflated buffer: not zlib", put<uint16_t>(z, kB + kFixed, 0x1234), ErrorCode::bad_payload);
  }
  // Textures.
  {
    const Bytes t = one(rgba_texture(9, 2, 2));
    using namespace wire::texture;
    bad_client("texture: body shorter than its fixed part", body_length(t, kFixed - 1), ErrorCode::bad_length);
    bad_client("texture: id 0", put<uint32_t>(t, kB + at::id, 0), ErrorCode::bad_id);
    bad_client("texture: format 3", put<uint8_t>(t, kB + at::format, 3), ErrorCode::bad_enum);
    bad_client("texture: wrap_s 2", put<uint8_t>(t, kB + at::wrap_s, 2), ErrorCode::bad_enum);
    bad_client("texture: wrap_t 2", put<uint8_t>(t, kB + at::wrap_t, 2), ErrorCode::bad_enum);
    bad_client("texture: filter 2", put<uint8_t>(t, kB + at::filter, 2), ErrorCode::bad_enum);
    bad_client("texture: srgb 2", put<uint8_t>(t, kB + at::srgb, 2), ErrorCode::bad_enum);
    bad_client("texture: reserved", put<uint8_t>(t, kB + at::reserved, 1), ErrorCode::bad_reserved);
    bad_client("texture: width 0", put<uint32_t>(t, kB + at::width, 0), ErrorCode::out_of_range);
    bad_client("texture: height 0", put<uint32_t>(t, kB + at::height, 0), ErrorCode::out_of_range);
    bad_client("texture: width beyond the limit", put<uint32_t>(t, kB + at::width, uint32_t(d.max_texture_size) + 1),
               ErrorCode::limit_exceeded);
    bad_client("texture: height beyond the limit", put<uint32_t>(t, kB + at::height, kMaxU32), ErrorCode::limit_exceeded);
    bad_client("texture: RGBA8 payload short", body_length(t, t.size() - kB - 1), ErrorCode::bad_length);
    bad_client("texture: RGBA8 payload long", body_length(t, t.size() - kB + 4), ErrorCode::bad_length);
    Limits lim;
    lim.max_message_payload_bytes = 15;
    bad_client("texture: the message's payload beyond its limit", t, ErrorCode::limit_exceeded, lim);
    const Bytes png = one(file_texture(20, TextureFormat::png, 3, 2)), jpeg = one(file_texture(21, TextureFormat::jpeg, 16, 9));
    bad_client("PNG texture: not a PNG", put<uint8_t>(png, kB + kFixed + 1, 'Q'), ErrorCode::bad_texture);
    bad_client("PNG texture: no IHDR first", put<uint8_t>(png, kB + kFixed + 12, 'X'), ErrorCode::bad_texture);
    bad_client("PNG texture: cut before its size", body_length(png, kFixed + 20), ErrorCode::bad_texture);
    bad_client("PNG texture: declared width differs", put<uint32_t>(png, kB + at::width, 4), ErrorCode::bad_texture);
    bad_client("PNG texture: declared height differs", put<uint32_t>(png, kB + at::height, 1), ErrorCode::bad_texture);
    bad_client("PNG texture: RGBA8 format", put<uint8_t>(png, kB + at::format, 0), ErrorCode::bad_length);
    bad_client("JPEG texture: not a JPEG", put<uint8_t>(jpeg, kB + kFixed + 1, 0), ErrorCode::bad_texture);
    bad_client("JPEG texture: a PNG", put<uint8_t>(png, kB + at::format, uint8_t(TextureFormat::jpeg)),
               ErrorCode::bad_texture);
    bad_client("JPEG texture: declared width differs", put<uint32_t>(jpeg, kB + at::width, 17), ErrorCode::bad_texture);
    bad_client("JPEG texture: declared height differs", put<uint32_t>(jpeg, kB + at::height, 8), ErrorCode::bad_texture);
  }
  // Materials.
  {
    const Bytes m = one(material());
    using namespace wire::material;
    bad_client("material: id 0", put<uint32_t>(m, kB + at::id, 0), ErrorCode::bad_id);
    bad_client("material: model 3", put<uint8_t>(m, kB + at::model, 3), ErrorCode::bad_enum);
    bad_client("material: reserved", put<uint16_t>(m, kB + at::reserved, 0x100), ErrorCode::bad_reserved);
    bad_client("material: unknown flag", put<uint8_t>(m, kB + at::flags, 8), ErrorCode::bad_reserved);
    bad_client("material: unknown flag beside the known ones", put<uint8_t>(m, kB + at::flags, 0x87),
               ErrorCode::bad_reserved);
    for (auto [field, off] : {std::pair{"diffuse_color", at::diffuse_color}, {"specular_color", at::specular_color},
                              {"emissive_color", at::emissive_color}}) {
      bad_client(std::string("material: ") + field + " negative", put(m, kB + off + 8, -1.0f), ErrorCode::out_of_range);
      bad_client(std::string("material: ") + field + " NaN", put(m, kB + off + 4, kNaN), ErrorCode::not_finite);
    }
    for (auto [field, off, r] : {std::tuple{"shininess", at::shininess, shininess},
                                {"ambient_intensity", at::ambient_intensity, ambient_intensity},
                                {"opacity", at::opacity, opacity}, {"reflection", at::reflection, reflection},
                                {"refraction", at::refraction, refraction}, {"ior", at::ior, ior},
                                {"alpha_cutoff", at::alpha_cutoff, alpha_cutoff}}) {
      const std::string f = std::string("material: ") + field;
      bad_client(f + " just below its range", put(m, kB + off, std::nextafter(r.lo, -kInf)), ErrorCode::out_of_range);
      bad_client(f + " just above its range", put(m, kB + off, std::nextafter(r.hi, kInf)), ErrorCode::out_of_range);
      bad_client(f + " infinite", put(m, kB + off, -kInf), ErrorCode::not_finite);
    }
  }
  // Meshes.
  {
    const Bytes m = one(mesh());
    using namespace wire::mesh;
    bad_client("mesh: id 0", put<uint32_t>(m, kB + at::id, 0), ErrorCode::bad_id);
    bad_client("mesh: positions 0", put<uint32_t>(m, kB + at::positions, 0), ErrorCode::bad_id);
    bad_client("mesh: transform NaN", put(m, kB + at::transform + 13 * 4, kNaN), ErrorCode::not_finite);
    bad_client("mesh: visible 2", put<uint8_t>(m, kB + at::visible, 2), ErrorCode::bad_enum);
    bad_client("mesh: reserved", put<uint8_t>(m, kB + at::reserved + 1, 1), ErrorCode::bad_reserved);
    SetMesh flat = mesh(), big = mesh(), tiny = mesh(), skew = mesh(), far = mesh();
    flat.mesh.transform = Mat4::scale({1, 0, 1});
    big.mesh.transform = Mat4::scale({5e9f, 1, 1});
    tiny.mesh.transform = Mat4::scale({1e-8f, 1e-8f, 1e-8f});
    skew.mesh.transform = Mat4::scale({1e4f, 1e-3f, 1});
    far.mesh.transform = Mat4::translate({0, -1e10f, 0});
    bad_client("mesh: singular transform", one(flat), ErrorCode::out_of_range);
    bad_client("mesh: scale beyond the mesh limit", one(big), ErrorCode::out_of_range);
    bad_client("mesh: nearly singular transform", one(tiny), ErrorCode::out_of_range);
    bad_client("mesh: ill-conditioned transform", one(skew), ErrorCode::out_of_range);
    bad_client("mesh: translation beyond the limit", one(far), ErrorCode::out_of_range);
  }
  // Lights.
  {
    const Bytes l = one(light(Light::Type::spot));
    using namespace wire::light;
    bad_client("light: id 0", put<uint32_t>(l, kB + at::id, 0), ErrorCode::bad_id);
    bad_client("light: type 3", put<uint8_t>(l, kB + at::type, 3), ErrorCode::bad_enum);
    bad_client("light: on 2", put<uint8_t>(l, kB + at::on, 2), ErrorCode::bad_enum);
    bad_client("light: cast_shadow 2", put<uint8_t>(l, kB + at::cast_shadow, 2), ErrorCode::bad_enum);
    bad_client("light: reserved", put<uint8_t>(l, kB + at::reserved, 1), ErrorCode::bad_reserved);
    bad_client("light: color negative", put(l, kB + at::color + 4, -0.1f), ErrorCode::out_of_range);
    bad_client("light: intensity negative", put(l, kB + at::intensity, -1.0f), ErrorCode::out_of_range);
    bad_client("light: intensity beyond its range", put(l, kB + at::intensity, std::nextafter(intensity.hi, kInf)),
               ErrorCode::out_of_range);
    bad_client("light: intensity NaN", put(l, kB + at::intensity, kNaN), ErrorCode::not_finite);
    bad_client("light: position infinite", put(l, kB + at::position + 8, -kInf), ErrorCode::not_finite);
    bad_client("light: direction NaN", put(l, kB + at::direction, kNaN), ErrorCode::not_finite);
    bad_client("light: attenuation negative", put(l, kB + at::attenuation, -1.0f), ErrorCode::out_of_range);
    bad_client("light: cutoff beyond pi", put(l, kB + at::cutoff, std::nextafter(kPi, 4.0f)), ErrorCode::out_of_range);
    bad_client("light: cutoff negative", put(l, kB + at::cutoff, -0.1f), ErrorCode::out_of_range);
    bad_client("light: softness beyond 1", put(l, kB + at::softness, 1.5f), ErrorCode::out_of_range);
    SetLight dir = light(Light::Type::directional), tiny = light(Light::Type::spot), huge = light(Light::Type::directional);
    SetLight point = light(Light::Type::point), spot = light(Light::Type::spot), flat = light(Light::Type::point);
    dir.light.direction = {0, 0, 0};
    tiny.light.direction = {1e-30f, 0, 0};
    huge.light.direction = {3e38f, 3e38f, 3e38f};
    point.light.position = {0, 8589934592.0f, 0};
    spot.light.cutoff = 0;
    flat.light.attenuation = {0, -0.0f, 0};
    bad_client("light: directional with a zero direction", one(dir), ErrorCode::out_of_range);
    bad_client("light: spot with a direction that underflows", one(tiny), ErrorCode::out_of_range);
    bad_client("light: directional with a direction that overflows", one(huge), ErrorCode::out_of_range);
    bad_client("light: point beyond the world limit", one(point), ErrorCode::out_of_range);
    bad_client("light: spot with cutoff 0", one(spot), ErrorCode::out_of_range);
    bad_client("light: point with no attenuation", one(flat), ErrorCode::out_of_range);
  }
  // References.
  {
    const Bytes b = one(buffer_ref());
    using namespace wire::buffer_ref;
    bad_client("buffer_ref: body shorter than its fixed part", body_length(b, kFixed - 1), ErrorCode::bad_length);
    bad_client("buffer_ref: no url", body_length(b, kFixed), ErrorCode::bad_length);
    {
      SetBufferRef big = buffer_ref();
      big.url = std::string(url_max_length, 'u');
      bad_client("buffer_ref: url of 4097 bytes", body_length(one(big), kFixed + url_max_length + 1), ErrorCode::bad_length);
    }
    bad_client("buffer_ref: id 0", put<uint32_t>(b, kB + at::id, 0), ErrorCode::bad_id);
    bad_client("buffer_ref: type 2", put<uint8_t>(b, kB + at::type, 2), ErrorCode::bad_enum);
    bad_client("buffer_ref: source 4", put<uint8_t>(b, kB + at::source, 4), ErrorCode::bad_enum);
    bad_client("buffer_ref: an integer source for a f32 buffer", put<uint8_t>(b, kB + at::source, 2), ErrorCode::bad_enum);
    bad_client("buffer_ref: a f32 source for a u32 buffer", put<uint8_t>(b, kB + at::type, 1), ErrorCode::bad_enum);
    bad_client("buffer_ref: reserved", put<uint8_t>(b, kB + at::reserved, 1), ErrorCode::bad_reserved);
    bad_client("buffer_ref: components 0", put<uint8_t>(b, kB + at::components, 0), ErrorCode::bad_components);
    bad_client("buffer_ref: components 5", put<uint8_t>(b, kB + at::components, 5), ErrorCode::bad_components);
    bad_client("buffer_ref: values not a multiple of components", put<uint32_t>(b, kB + at::value_count, 301),
               ErrorCode::bad_components);
    bad_client("buffer_ref: beyond max_buffer_bytes", put<uint32_t>(b, kB + at::value_count, 3000),
               ErrorCode::limit_exceeded, [] { Limits l; l.max_buffer_bytes = 11996; return l; }());
    bad_client("buffer_ref: beyond max_vertices", b, ErrorCode::limit_exceeded, [] { Limits l; l.max_vertices = 99; return l; }());
    bad_client("buffer_ref: stride 253", put<uint32_t>(b, kB + at::byte_stride, 253), ErrorCode::out_of_range);
    bad_client("buffer_ref: stride shorter than an element", put<uint32_t>(b, kB + at::byte_stride, 8), ErrorCode::out_of_range);
    bad_client("buffer_ref: stride not a multiple of the source's size", put<uint32_t>(b, kB + at::byte_stride, 14),
               ErrorCode::out_of_range);
    bad_client("buffer_ref: op remove", put<uint8_t>(b, 9, 1), ErrorCode::bad_op);
    const Bytes t = one(texture_ref());
    bad_client("texture_ref: body shorter than its fixed part", body_length(t, wire::texture_ref::kFixed - 1),
               ErrorCode::bad_length);
    bad_client("texture_ref: no url", body_length(t, wire::texture_ref::kFixed), ErrorCode::bad_length);
    bad_client("texture_ref: id 0", put<uint32_t>(t, kB + wire::texture_ref::at::id, 0), ErrorCode::bad_id);
    bad_client("texture_ref: wrap_s 2", put<uint8_t>(t, kB + wire::texture_ref::at::wrap_s, 2), ErrorCode::bad_enum);
    bad_client("texture_ref: wrap_t 2", put<uint8_t>(t, kB + wire::texture_ref::at::wrap_t, 2), ErrorCode::bad_enum);
    bad_client("texture_ref: filter 2", put<uint8_t>(t, kB + wire::texture_ref::at::filter, 2), ErrorCode::bad_enum);
    bad_client("texture_ref: srgb 2", put<uint8_t>(t, kB + wire::texture_ref::at::srgb, 2), ErrorCode::bad_enum);
    bad_client("texture_ref: op remove", put<uint8_t>(t, 9, 1), ErrorCode::bad_op);
  }
  // A failure names its record: the third record of a message.
  const size_t third = kMessageHeaderSize + (kRecordHeaderSize + wire::settings::kFixed) +
                       (kRecordHeaderSize + wire::render::kFixed) + kRecordHeaderSize;
  bad_client("the third record fails",
             put<uint8_t>(encode(std::vector<ClientRecord>{Settings{}, RenderRequest{1}, material()}),
                          third + wire::material::at::model, 9),
             ErrorCode::bad_enum);
}

void server_records() {
  const Limits d;
  {
    const Bytes h = one(handshake_reply());
    using namespace wire::handshake_reply;
    bad_server("handshake reply: body shorter than its fixed part", body_length(h, kFixed - 1), ErrorCode::bad_length);
    bad_server("handshake reply: version length too long", put<uint8_t>(h, kB + at::version_length, 14),
               ErrorCode::bad_length);
    bad_server("handshake reply: version length too short", put<uint8_t>(h, kB + at::version_length, 12),
               ErrorCode::bad_length);
    bad_server("handshake reply: renderer 2", put<uint8_t>(h, kB + at::renderer, 2), ErrorCode::bad_enum);
    bad_server("handshake reply: display 4", put<uint8_t>(h, kB + at::display, 4), ErrorCode::bad_enum);
    bad_server("handshake reply: jpeg_quality 0", put<uint8_t>(h, kB + at::jpeg_quality, 0), ErrorCode::out_of_range);
    bad_server("handshake reply: jpeg_quality 200", put<uint8_t>(h, kB + at::jpeg_quality, 200), ErrorCode::out_of_range);
    bad_server("handshake reply: width 0", put<uint32_t>(h, kB + at::width, 0), ErrorCode::out_of_range);
    bad_server("handshake reply: height beyond the limit",
               put<uint32_t>(h, kB + at::height, uint32_t(d.max_height) + 1), ErrorCode::limit_exceeded);
    bad_server("handshake reply: op 1", put<uint8_t>(h, 9, 1), ErrorCode::bad_op);
  }
  {
    const Bytes f = one(frame(FrameEncoding::dxt1, 5, 3)), j = one(frame(FrameEncoding::jpeg, 5, 3));
    using namespace wire::frame;
    bad_server("frame: body shorter than its fixed part", body_length(j, kFixed - 1), ErrorCode::bad_length);
    bad_server("frame: encoding 3", put<uint8_t>(f, kB + at::encoding, 3), ErrorCode::bad_enum);
    bad_server("frame: refined 3", put<uint8_t>(f, kB + at::refined, 3), ErrorCode::bad_enum);
    bad_server("frame: refined 255", put<uint8_t>(j, kB + at::refined, 255), ErrorCode::bad_enum);
    bad_server("frame: refined 3 and width 0 (the enum first)",
               put<uint32_t>(put<uint8_t>(j, kB + at::refined, 3), kB + at::width, 0), ErrorCode::bad_enum);
    bad_server("frame: width 0", put<uint32_t>(j, kB + at::width, 0), ErrorCode::out_of_range);
    bad_server("frame: height 0", put<uint32_t>(j, kB + at::height, 0), ErrorCode::out_of_range);
    bad_server("frame: width beyond the limit", put<uint32_t>(j, kB + at::width, uint32_t(d.max_width) + 1),
               ErrorCode::limit_exceeded);
    bad_server("frame: DXT1 payload one block short", body_length(f, f.size() - kB - 8), ErrorCode::bad_length);
    bad_server("frame: DXT1 payload a byte long", body_length(f, f.size() - kB + 1), ErrorCode::bad_length);
    bad_server("frame: DXT1 size changed", put<uint32_t>(f, kB + at::width, 9), ErrorCode::bad_length);
  }
  {
    const Bytes e = one(error_reply());
    using namespace wire::error;
    bad_server("error: body shorter than its fixed part", body_length(e, kFixed - 1), ErrorCode::bad_length);
    bad_server("error: code beyond kMaxErrorCode", put<uint16_t>(e, kB + at::code, kMaxErrorCode + 1), ErrorCode::bad_enum);
    bad_server("error: a node's own code (64)", put<uint16_t>(e, kB + at::code, 64), ErrorCode::bad_enum);
    bad_server("error: code 0xffff", put<uint16_t>(e, kB + at::code, 0xffff), ErrorCode::bad_enum);
    bad_server("error: fatal 2", put<uint8_t>(e, kB + at::fatal, 2), ErrorCode::bad_enum);
    bad_server("error: reserved", put<uint8_t>(e, kB + at::reserved, 1), ErrorCode::bad_reserved);
  }
  {
    const Bytes r = one(reference());
    using namespace wire::reference;
    bad_server("reference: body shorter than its fixed part", body_length(r, kFixed - 1), ErrorCode::bad_length);
    bad_server("reference: what 2", put<uint8_t>(r, kB + at::what, 2), ErrorCode::bad_enum);
    bad_server("reference: ok 2", put<uint8_t>(r, kB + at::ok, 2), ErrorCode::bad_enum);
    bad_server("reference: reserved", put<uint16_t>(r, kB + at::reserved, 1), ErrorCode::bad_reserved);
    bad_server("reference: id 0", put<uint32_t>(r, kB + at::id, 0), ErrorCode::bad_id);
  }
  {
    const Bytes s = one(stats());
    bad_server("stats: body one byte short", body_length(s, wire::stats::kFixed - 1), ErrorCode::bad_length);
    bad_server("stats: body one byte long", body_length(s, wire::stats::kFixed + 1), ErrorCode::bad_length);
  }
  bad_server("the second record fails",
             put<uint8_t>(encode(std::vector<ServerRecord>{stats(), error_reply()}),
                          kMessageHeaderSize + kRecordHeaderSize + wire::stats::kFixed + kRecordHeaderSize + wire::error::at::fatal, 7),
             ErrorCode::bad_enum);
}

}  // namespace

int main(int argc, char** argv) {
  std::FILE* out = stdout;
  try {
    valid_messages();
    framing(Channel::client, one(Settings{16, 5}));
    framing(Channel::server, one(stats()));
    client_records();
    server_records();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "protocol_golden: %s\n", e.what());
    return 1;
  }
  if (argc > 1 && !(out = std::fopen(argv[1], "w"))) {
    std::fprintf(stderr, "protocol_golden: cannot write %s\n", argv[1]);
    return 1;
  }
  std::string codes = "[";
  for (uint16_t c = 0; c <= kMaxErrorCode; ++c) codes += (c ? ", " : "") + str(to_string(ErrorCode(c)));
  std::fprintf(out, "{\n\"generated_by\": \"tests/wire/protocol_golden.cpp (protocol/protocol.cpp's encoder and decoder)\",\n");
  std::fprintf(out, "\"error_codes\": %s],\n\"limits\": %s,\n\"valid\": [\n", codes.c_str(), all_limits().c_str());
  for (size_t i = 0; i < valid.size(); ++i) std::fprintf(out, "%s%s\n", valid[i].c_str(), i + 1 < valid.size() ? "," : "");
  std::fprintf(out, "],\n\"invalid\": [\n");
  for (size_t i = 0; i < invalid.size(); ++i)
    std::fprintf(out, "%s%s\n", invalid[i].c_str(), i + 1 < invalid.size() ? "," : "");
  std::fprintf(out, "]\n}\n");
  return out == stdout || std::fclose(out) == 0 ? 0 : 1;
}
