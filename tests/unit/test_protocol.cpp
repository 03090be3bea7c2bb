// Client protocol: round trips of every record type, one test per validation rule, and
// truncation at every byte offset.
#include <random>
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>

#include "codecs/deflate.h"
#include "codecs/dxt1.h"
#include "codecs/jpeg.h"
#include "protocol/protocol.h"
#include "update/scene_update.h"
#include "core/image.h"

using namespace tessera;
using namespace tessera::protocol;

namespace {

constexpr size_t kBody = kMessageHeaderSize + kRecordHeaderSize;  // body offset of record 0
const float kNaN = std::numeric_limits<float>::quiet_NaN();
const float kInf = std::numeric_limits<float>::infinity();

template <class T>
void patch(std::vector<uint8_t>& m, size_t at, T v) {
  REQUIRE(at + sizeof(T) <= m.size());
  std::memcpy(m.data() + at, &v, sizeof(T));
}

Result<std::vector<ClientRecord>> dec(const std::vector<uint8_t>& m, const Limits& lim = {}) {
  return decode_client(m.data(), m.size(), lim);
}

// Decodes and requires failure with `code`; returns the message.
std::string fails(const std::vector<uint8_t>& m, ErrorCode code, const Limits& lim = {}) {
  auto r = dec(m, lim);
  REQUIRE_FALSE(r.ok());
  INFO(r.error().message);
  CHECK(r.error().code == code);
  CHECK_FALSE(r.error().message.empty());
  return r.error().message;
}

bool mentions(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

template <class T>
T one(const std::vector<uint8_t>& m, const Limits& lim = {}) {
  auto r = dec(m, lim);
  INFO((r.ok() ? std::string() : r.error().message));
  REQUIRE(r.ok());
  REQUIRE(r.value().size() == 1);
  REQUIRE(std::holds_alternative<T>(r.value()[0]));
  return std::get<T>(r.value()[0]);
}

Handshake sample_handshake() {
  Handshake h;
  h.renderer = RendererKind::rasterizer;
  h.display = DisplayKind::s3tc;
  h.jpeg_quality = 77;
  h.max_nodes = 5;
  h.width = 1280;
  h.height = 720;
  return h;
}

SetCamera sample_camera() {
  SetCamera c;
  c.camera.to_world = Mat4::look_at({1, 2, 3}, {0, 0, 0}, {0, 1, 0});
  c.camera.fov_y = 0.8f;
  return c;
}

SetEnvironment sample_environment() {
  SetEnvironment e;
  e.environment.ambient = {0.1f, 0.2f, 0.3f};
  e.environment.background = {0.5f, 0.5f, 1};
  e.environment.exposure = 1.5f;
  e.environment.linear = false;
  return e;
}

SetBuffer positions_buffer(Id id, int triangles, bool deflate = false) {
  SetBuffer b;
  b.id = id;
  b.buffer.type = Buffer::Type::f32;
  b.buffer.components = 3;
  for (int i = 0; i < triangles * 9; ++i) b.buffer.f.push_back(float(i % 7) * 0.5f);
  b.deflate = deflate;
  return b;
}

SetBuffer index_buffer(Id id, std::vector<uint32_t> idx, bool deflate = false) {
  SetBuffer b;
  b.id = id;
  b.buffer.type = Buffer::Type::u32;
  b.buffer.components = 1;
  b.buffer.u = std::move(idx);
  b.deflate = deflate;
  return b;
}

SetTexture sample_texture(Id id, int w = 3, int h = 2) {
  SetTexture t;
  t.id = id;
  t.texture.width = w;
  t.texture.height = h;
  for (int i = 0; i < w * h * 4; ++i) t.texture.rgba.push_back(uint8_t(i * 11));
  t.texture.sampler.wrap_s = Sampler::Wrap::clamp;
  t.texture.sampler.wrap_t = Sampler::Wrap::repeat;
  t.texture.sampler.filter = Sampler::Filter::nearest;
  t.texture.srgb = false;
  return t;
}

SetMaterial sample_material(Id id) {
  SetMaterial s;
  s.id = id;
  Material& m = s.material;
  m.model = Material::Model::diffuse;
  m.diffuse_color = {0.8f, 0.1f, 0.1f};
  m.specular_color = {0.2f, 0.2f, 0.2f};
  m.shininess = 0.4f;
  m.emissive_color = {0, 0.1f, 0};
  m.ambient_intensity = 0.3f;
  m.opacity = 0.9f;
  m.diffuse_texture = 7;
  m.specular_texture = 8;
  m.emissive_texture = 9;
  m.reflection = 0.25f;
  m.refraction = 0.5f;
  m.ior = 1.33f;
  m.alpha_mask = true;
  m.alpha_cutoff = 0.3f;
  m.double_sided = false;
  m.use_vertex_color = true;
  return s;
}

SetMesh sample_mesh(Id id, Id positions, Id indices = kNoId) {
  SetMesh s;
  s.id = id;
  s.mesh.positions = positions;
  s.mesh.indices = indices;
  s.mesh.material = 4;
  s.mesh.transform = Mat4::translate({1, 2, 3});
  s.mesh.visible = true;
  return s;
}

SetLight sample_light(Id id) {
  SetLight s;
  s.id = id;
  Light& l = s.light;
  l.type = Light::Type::spot;
  l.color = {1, 0.5f, 0.25f};
  l.intensity = 3;
  l.position = {1, 2, 3};
  l.direction = {0, -1, 0};
  l.attenuation = {1, 0.1f, 0.01f};
  l.cutoff = 0.6f;
  l.softness = 0.2f;
  l.on = false;
  return s;
}

std::vector<ClientRecord> every_client_record() {
  std::vector<ClientRecord> v;
  v.push_back(Settings{8, 3});
  v.push_back(Resolution{800, 600});
  v.push_back(sample_camera());
  v.push_back(sample_environment());
  v.push_back(positions_buffer(1, 2));
  v.push_back(positions_buffer(2, 3, true));
  v.push_back(index_buffer(3, {0, 1, 2, 2, 1, 0}, true));
  v.push_back(sample_texture(5));
  v.push_back(sample_material(4));
  v.push_back(sample_mesh(10, 1));
  std::get<SetMesh>(v.back()).mesh.texcoords = 12;
  std::get<SetMesh>(v.back()).mesh.colors = 13;
  v.push_back(sample_light(20));
  v.push_back(Remove{RecordType::light, 21});
  v.push_back(RenderRequest{42});
  v.push_back(Refine{256});
  v.push_back(Budget{40});
  return v;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Round trips.

TEST_CASE("Every client record survives an encode/decode round trip", "[protocol]") {
  SECTION("handshake") {
    auto h = one<Handshake>(encode(ClientRecord{sample_handshake()}));
    CHECK(h.renderer == RendererKind::rasterizer);
    CHECK(h.display == DisplayKind::s3tc);
    CHECK(h.jpeg_quality == 77);
    CHECK(h.max_nodes == 5);
    CHECK(h.width == 1280);
    CHECK(h.height == 720);
  }
  SECTION("batch of every other record, byte-identical after re-encoding") {
    auto recs = every_client_record();
    auto bytes = encode(recs);
    auto r = decode_client(bytes.data(), bytes.size(), Limits{});
    REQUIRE(r.ok());
    REQUIRE(r.value().size() == recs.size());
    CHECK(encode(r.value()) == bytes);
    auto& v = r.value();
    CHECK(std::get<Settings>(v[0]).ao_samples == 8);
    CHECK(std::get<Settings>(v[0]).max_depth == 3);
    CHECK(std::get<Resolution>(v[1]).width == 800);
    CHECK(std::get<SetCamera>(v[2]).camera.to_world == sample_camera().camera.to_world);
    CHECK(std::get<SetCamera>(v[2]).camera.fov_y == 0.8f);
    CHECK(std::get<SetEnvironment>(v[3]).environment.ambient == Vec3(0.1f, 0.2f, 0.3f));
    CHECK(std::get<SetEnvironment>(v[3]).environment.exposure == 1.5f);
    CHECK_FALSE(std::get<SetEnvironment>(v[3]).environment.linear);
    CHECK(std::get<SetBuffer>(v[4]).buffer.f == positions_buffer(1, 2).buffer.f);
    CHECK_FALSE(std::get<SetBuffer>(v[4]).deflate);
    CHECK(std::get<SetBuffer>(v[5]).deflate);
    CHECK(std::get<SetBuffer>(v[5]).buffer.f == positions_buffer(2, 3).buffer.f);
    CHECK(std::get<SetBuffer>(v[6]).buffer.u == std::vector<uint32_t>{0, 1, 2, 2, 1, 0});
    auto& t = std::get<SetTexture>(v[7]);
    CHECK(t.texture.rgba == sample_texture(5).texture.rgba);
    CHECK(t.texture.sampler.wrap_s == Sampler::Wrap::clamp);
    CHECK(t.texture.sampler.filter == Sampler::Filter::nearest);
    CHECK_FALSE(t.texture.srgb);
    auto& m = std::get<SetMaterial>(v[8]).material;
    CHECK(m.model == Material::Model::diffuse);
    CHECK(m.ior == 1.33f);
    CHECK(m.alpha_mask);
    CHECK_FALSE(m.double_sided);
    CHECK(m.use_vertex_color);
    CHECK(m.emissive_texture == 9);
    CHECK(std::get<SetMesh>(v[9]).mesh.transform == Mat4::translate({1, 2, 3}));
    CHECK(std::get<SetMesh>(v[9]).mesh.material == 4);
    CHECK(std::get<SetMesh>(v[9]).mesh.texcoords == 12);
    CHECK(std::get<SetMesh>(v[9]).mesh.colors == 13);
    CHECK(std::get<SetLight>(v[10]).light.type == Light::Type::spot);
    CHECK(std::get<SetLight>(v[10]).light.attenuation == Vec3(1, 0.1f, 0.01f));
    CHECK_FALSE(std::get<SetLight>(v[10]).light.on);
    CHECK(std::get<Remove>(v[11]).what == RecordType::light);
    CHECK(std::get<Remove>(v[11]).id == 21);
    CHECK(std::get<RenderRequest>(v[12]).frame == 42);
    CHECK(std::get<Refine>(v[13]).samples == 256);
    CHECK(std::get<Budget>(v[14]).frame_ms == 40);
  }
  SECTION("removes of every entry kind") {
    for (RecordType t : {RecordType::buffer, RecordType::texture, RecordType::material, RecordType::mesh,
                         RecordType::light}) {
      auto r = one<Remove>(encode(ClientRecord{Remove{t, 99}}));
      CHECK(r.what == t);
      CHECK(r.id == 99);
    }
  }
}

TEST_CASE("Textures round trip as PNG and JPEG bytes", "[protocol]") {
  Image img(17, 9);
  for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = uint8_t(i % 4 == 3 ? 255 : (i * 5) % 256);
  SECTION("png") {
    std::string path = "test_protocol_texture.png";
    write_png(path, img);
    std::ifstream f(path, std::ios::binary);
    std::vector<uint8_t> png((std::istreambuf_iterator<char>(f)), {});
    std::remove(path.c_str());
    SetTexture t = sample_texture(3, 17, 9);
    t.format = TextureFormat::png;
    t.encoded = png;
    auto back = one<SetTexture>(encode(ClientRecord{t}));
    CHECK(back.texture.width == 17);
    CHECK(back.texture.rgba == img.rgba);
    CHECK(back.format == TextureFormat::png);
    // PNG whose header disagrees with the declared size.
    t.texture.width = 16;
    CHECK(mentions(fails(encode(ClientRecord{t}), ErrorCode::bad_texture), "declared 16x9"));
    // Corrupt PNG data after a valid header.
    t.texture.width = 17;
    for (size_t i = 40; i < t.encoded.size(); ++i) t.encoded[i] ^= 0x5a;
    fails(encode(ClientRecord{t}), ErrorCode::bad_texture);
  }
  SECTION("jpeg") {
    JpegEncoder enc;
    std::string err;
    SetTexture t = sample_texture(3, 17, 9);
    t.format = TextureFormat::jpeg;
    REQUIRE(enc.encode(img, 95, t.encoded, err));
    auto back = one<SetTexture>(encode(ClientRecord{t}));
    CHECK(back.texture.width == 17);
    CHECK(back.texture.height == 9);
    CHECK(compare(img, Image{17, 9}).psnr < compare(img, [&] {
            Image i(17, 9);
            i.rgba.assign(back.texture.rgba.begin(), back.texture.rgba.end());
            return i;
          }()).psnr);
    t.texture.height = 10;
    fails(encode(ClientRecord{t}), ErrorCode::bad_texture);
    t.texture.height = 9;
    t.encoded.resize(10);
    fails(encode(ClientRecord{t}), ErrorCode::bad_texture);
  }
}

TEST_CASE("Every server record survives an encode/decode round trip", "[protocol]") {
  HandshakeReply h;
  h.renderer = RendererKind::raytracer;
  h.display = DisplayKind::mjpeg;
  h.jpeg_quality = 90;
  h.nodes = 3;
  h.width = 1024;
  h.height = 768;
  h.max_message_bytes = 1 << 20;
  h.max_buffer_bytes = 1ull << 33;
  h.server_version = "tessera 0.1.0";
  Frame f;
  f.frame = 7;
  f.width = 5;
  f.height = 3;
  f.encoding = FrameEncoding::dxt1;
  f.refined = true;
  f.samples = 300;
  f.timings = {1, 2, 3, 4, 5, 6};
  f.payload.assign(dxt1_size(5, 3), 0xab);
  ErrorReply e{ErrorCode::bad_mesh, false, 3, "mesh 4: index 9 out of range"};
  Stats s{100, 2, 1ull << 40, 12345, 1000000, 4, 29.5f, 12.25f};
  Frame plain;  // a requested frame: not refined, 1 sample
  plain.frame = 8;
  plain.width = plain.height = 1;
  plain.payload = {1, 2};
  std::vector<ServerRecord> recs{h, f, e, s, plain};
  auto bytes = encode(recs);
  auto r = decode_server(bytes.data(), bytes.size(), Limits{});
  REQUIRE(r.ok());
  REQUIRE(r.value().size() == 5);
  CHECK(encode(r.value()) == bytes);
  auto& h2 = std::get<HandshakeReply>(r.value()[0]);
  CHECK(h2.display == DisplayKind::mjpeg);
  CHECK(h2.server_version == "tessera 0.1.0");
  CHECK(h2.max_buffer_bytes == 1ull << 33);
  auto& f2 = std::get<Frame>(r.value()[1]);
  CHECK(f2.payload == f.payload);
  CHECK(f2.timings.encode_ms == 6);
  CHECK(f2.encoding == FrameEncoding::dxt1);
  CHECK(f2.refined);
  CHECK(f2.samples == 300);
  auto& p2 = std::get<Frame>(r.value()[4]);
  CHECK_FALSE(p2.refined);
  CHECK(p2.samples == 1);
  CHECK(p2.payload == plain.payload);
  auto& e2 = std::get<ErrorReply>(r.value()[2]);
  CHECK(e2.code == ErrorCode::bad_mesh);
  CHECK(e2.record == 3);
  CHECK(e2.message == e.message);
  auto& s2 = std::get<Stats>(r.value()[3]);
  CHECK(s2.bytes_sent == 1ull << 40);
  CHECK(s2.fps == 29.5f);
}

TEST_CASE("A frame header written before a JPEG matches encode(Frame)", "[protocol]") {
  Image img(64, 32);
  for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = uint8_t(i);
  Frame f;
  f.frame = 3;
  f.width = 64;
  f.height = 32;
  f.timings.encode_ms = 0.5f;
  JpegEncoder enc;
  std::string err;
  REQUIRE(enc.encode(img, 80, f.payload, err));
  std::vector<uint8_t> out;
  encode_frame_header(f, f.payload.size(), out);
  size_t header = out.size();
  REQUIRE(enc.encode(img, 80, out, err, header));
  CHECK(out == encode(ServerRecord{f}));
  // A refined frame's fields are in the header too; 0 samples are written as 1.
  f.refined = true;
  f.samples = 65535;
  out.clear();
  encode_frame_header(f, f.payload.size(), out);
  REQUIRE(enc.encode(img, 80, out, err, out.size()));
  CHECK(out == encode(ServerRecord{f}));
  auto back = decode_server(out.data(), out.size(), Limits{});
  REQUIRE(back.ok());
  CHECK(std::get<Frame>(back.value()[0]).refined);
  CHECK(std::get<Frame>(back.value()[0]).samples == 65535);
  f.samples = 0;
  out.clear();
  encode_frame_header(f, 0, out);
  CHECK(out[kBody + wire::frame::at::samples] == 1);
  CHECK(out[kBody + wire::frame::at::samples + 1] == 0);
}

// ---------------------------------------------------------------------------------------
// Framing rules.

TEST_CASE("Framing violations are rejected with their error codes", "[protocol]") {
  auto good = encode(ClientRecord{RenderRequest{1}});
  REQUIRE(dec(good).ok());
  SECTION("message larger than max_message_bytes") {
    Limits lim;
    lim.max_message_bytes = uint32_t(good.size() - 1);
    CHECK(mentions(fails(good, ErrorCode::too_large, lim), "exceeds the limit"));
  }
  SECTION("shorter than the header") {
    CHECK(mentions(fails({'T', 'S', 1}, ErrorCode::truncated), "header"));
  }
  SECTION("bad magic") {
    auto m = good;
    m[0] = 'X';
    fails(m, ErrorCode::bad_magic);
  }
  SECTION("unsupported version is fatal") {
    auto m = good;
    m[2] = kVersion + 1;
    CHECK(mentions(fails(m, ErrorCode::bad_version), "version " + std::to_string(kVersion + 1)));
    m[2] = 1;  // version 1 (before vertex colours): its mesh records are 4 bytes shorter
    CHECK(mentions(fails(m, ErrorCode::bad_version), "version 1 not supported"));
    CHECK(is_fatal(ErrorCode::bad_version));
  }
  SECTION("server message on the client decoder and vice versa") {
    auto m = good;
    m[3] = 1;
    fails(m, ErrorCode::bad_channel);
    auto r = decode_server(good.data(), good.size(), Limits{});
    REQUIRE_FALSE(r.ok());
    CHECK(r.error().code == ErrorCode::bad_channel);
  }
  SECTION("zero records") {
    auto m = good;
    patch<uint32_t>(m, 4, 0);
    fails(m, ErrorCode::bad_length);
  }
  SECTION("more records than max_records") {
    auto m = encode(std::vector<ClientRecord>{RenderRequest{1}, RenderRequest{2}, RenderRequest{3}});
    Limits lim;
    lim.max_records = 2;
    fails(m, ErrorCode::too_large, lim);
  }
  SECTION("record count that cannot fit in the message") {
    auto m = good;
    patch<uint32_t>(m, 4, 0xffffffffu);
    fails(m, ErrorCode::too_large);
    patch<uint32_t>(m, 4, 100);
    CHECK(mentions(fails(m, ErrorCode::truncated), "cannot fit"));
    patch<uint32_t>(m, 4, 2);
    fails(m, ErrorCode::truncated);
  }
  SECTION("body length beyond the message") {
    auto m = good;
    patch<uint32_t>(m, 12, 5);
    CHECK(mentions(fails(m, ErrorCode::truncated), "only 4 left"));
    patch<uint32_t>(m, 12, 0xffffffffu);
    fails(m, ErrorCode::truncated);
  }
  SECTION("unknown record type, and a server record type from a client") {
    auto m = good;
    m[8] = 0x30;
    CHECK(mentions(fails(m, ErrorCode::unknown_record), "48"));
    m[8] = uint8_t(RecordType::frame);
    fails(m, ErrorCode::unknown_record);
  }
  SECTION("unknown op, and remove on a record without ids") {
    auto m = good;
    m[9] = 2;
    fails(m, ErrorCode::bad_op);
    m[9] = uint8_t(Op::remove);
    CHECK(mentions(fails(m, ErrorCode::bad_op), "remove"));
  }
  SECTION("reserved record header field") {
    auto m = good;
    m[10] = 1;
    fails(m, ErrorCode::bad_reserved);
  }
  SECTION("trailing bytes after the last record") {
    auto m = good;
    m.push_back(0);
    CHECK(mentions(fails(m, ErrorCode::bad_length), "after the last record"));
  }
  SECTION("fixed-size body of the wrong length") {
    auto m = good;
    m.push_back(0);
    patch<uint32_t>(m, 12, 5);
    CHECK(mentions(fails(m, ErrorCode::bad_length), "expected 4"));
  }
  SECTION("the error names the offending record") {
    auto m = encode(std::vector<ClientRecord>{RenderRequest{1}, Resolution{0, 5}});
    auto r = dec(m);
    REQUIRE_FALSE(r.ok());
    CHECK(r.error().record == 1);
    CHECK(mentions(r.error().message, "record 1 (resolution)"));
    CHECK(to_reply(r.error()).record == 1);
    CHECK_FALSE(to_reply(r.error()).fatal);
  }
}

// ---------------------------------------------------------------------------------------
// Per-record rules.

TEST_CASE("Handshake rules", "[protocol]") {
  auto good = encode(ClientRecord{sample_handshake()});
  SECTION("renderer and display enums") {
    auto m = good;
    m[kBody] = 2;
    CHECK(mentions(fails(m, ErrorCode::bad_enum), "renderer"));
    m = good;
    m[kBody + 1] = 4;
    CHECK(mentions(fails(m, ErrorCode::bad_enum), "display"));
  }
  SECTION("jpeg quality 1..100") {
    auto m = good;
    m[kBody + 2] = 0;
    fails(m, ErrorCode::out_of_range);
    m[kBody + 2] = 101;
    CHECK(mentions(fails(m, ErrorCode::out_of_range), "jpeg_quality"));
  }
  SECTION("reserved byte") {
    auto m = good;
    m[kBody + 3] = 1;
    fails(m, ErrorCode::bad_reserved);
  }
  SECTION("max_nodes within the limit") {
    Limits lim;
    lim.max_nodes = 4;
    CHECK(mentions(fails(good, ErrorCode::limit_exceeded, lim), "max_nodes"));
  }
  SECTION("resolution non-empty and within the limit") {
    auto m = good;
    patch<uint32_t>(m, kBody + 8, 0);
    fails(m, ErrorCode::out_of_range);
    patch<uint32_t>(m, kBody + 8, 7681);
    fails(m, ErrorCode::limit_exceeded);
  }
  SECTION("a handshake must be alone in its message, and first in the session") {
    std::vector<ClientRecord> recs{sample_handshake(), RenderRequest{1}};
    fails(encode(recs), ErrorCode::bad_handshake);
    CHECK(is_fatal(ErrorCode::bad_handshake));
    auto r = dec(good);
    REQUIRE(r.ok());
    CHECK(check_session_order(false, r.value()).ok());
    CHECK(check_session_order(true, r.value()).code() == ErrorCode::bad_handshake);
    std::vector<ClientRecord> render{RenderRequest{1}};
    CHECK(check_session_order(false, render).code() == ErrorCode::bad_handshake);
    CHECK(check_session_order(true, render).ok());
  }
}

TEST_CASE("Settings and resolution rules", "[protocol]") {
  Limits lim;
  lim.max_ao_samples = 16;
  lim.max_depth = 8;
  CHECK(one<Settings>(encode(ClientRecord{Settings{16, 8}}), lim).ao_samples == 16);
  CHECK(mentions(fails(encode(ClientRecord{Settings{17, 8}}), ErrorCode::limit_exceeded, lim), "ao_samples"));
  CHECK(mentions(fails(encode(ClientRecord{Settings{1, 9}}), ErrorCode::limit_exceeded, lim), "max_depth"));
  fails(encode(ClientRecord{Resolution{0, 10}}), ErrorCode::out_of_range);
  // Refine: samples up to max_refine_samples (4096 by default); 0 and 1 mean no refinement.
  for (uint32_t n : {0u, 1u, 64u, Limits{}.max_refine_samples})
    CHECK(one<Refine>(encode(ClientRecord{Refine{n}})).samples == n);
  CHECK(mentions(fails(encode(ClientRecord{Refine{Limits{}.max_refine_samples + 1}}), ErrorCode::limit_exceeded),
                 "refine samples 4097"));
  lim.max_refine_samples = 16;
  CHECK(one<Refine>(encode(ClientRecord{Refine{16}}), lim).samples == 16);
  fails(encode(ClientRecord{Refine{17}}), ErrorCode::limit_exceeded, lim);
  fails(encode(ClientRecord{Refine{0xffffffffu}}), ErrorCode::limit_exceeded);
  {
    auto m = encode(ClientRecord{Refine{8}});
    CHECK(m.size() == kBody + 4);
    CHECK(m[8] == 0x06);
    m.push_back(0);
    patch<uint32_t>(m, 12, 5);
    fails(m, ErrorCode::bad_length);
    m = encode(ClientRecord{Refine{8}});
    m.pop_back();
    patch<uint32_t>(m, 12, 3);
    fails(m, ErrorCode::bad_length);
    m = encode(ClientRecord{Refine{8}});
    m[9] = 1;  // remove is not defined for refine
    fails(m, ErrorCode::bad_op);
    Scene scene;  // a session record, not a scene update
    CHECK_FALSE(is_scene_update(ClientRecord{Refine{8}}));
    CHECK(apply(scene, Refine{8}, Limits{}).code() == ErrorCode::not_scene_update);
  }
  // Budget: frame_ms up to max_frame_budget_ms (60000 by default); 0 means no budget.
  for (uint32_t ms : {0u, 1u, 33u, Limits{}.max_frame_budget_ms})
    CHECK(one<Budget>(encode(ClientRecord{Budget{ms}})).frame_ms == ms);
  CHECK(mentions(fails(encode(ClientRecord{Budget{Limits{}.max_frame_budget_ms + 1}}), ErrorCode::limit_exceeded),
                 "budget frame_ms 60001"));
  lim.max_frame_budget_ms = 100;
  CHECK(one<Budget>(encode(ClientRecord{Budget{100}}), lim).frame_ms == 100);
  fails(encode(ClientRecord{Budget{101}}), ErrorCode::limit_exceeded, lim);
  fails(encode(ClientRecord{Budget{0xffffffffu}}), ErrorCode::limit_exceeded);
  {
    auto m = encode(ClientRecord{Budget{33}});
    CHECK(m.size() == kBody + 4);
    CHECK(m[8] == 0x07);
    CHECK(m[kBody] == 33);
    m.push_back(0);
    patch<uint32_t>(m, 12, 5);
    fails(m, ErrorCode::bad_length);
    m = encode(ClientRecord{Budget{33}});
    m.pop_back();
    patch<uint32_t>(m, 12, 3);
    fails(m, ErrorCode::bad_length);
    m = encode(ClientRecord{Budget{33}});
    m[9] = 1;  // remove is not defined for budget
    fails(m, ErrorCode::bad_op);
    Scene scene;  // a session record, not a scene update
    CHECK_FALSE(is_scene_update(ClientRecord{Budget{33}}));
    CHECK(apply(scene, Budget{33}, Limits{}).code() == ErrorCode::not_scene_update);
    CHECK(std::string(to_string(RecordType::budget)) == "budget");
  }
  fails(encode(ClientRecord{Resolution{10, 0}}), ErrorCode::out_of_range);
  fails(encode(ClientRecord{Resolution{-1, 10}}), ErrorCode::limit_exceeded);  // 0xffffffff on the wire
  fails(encode(ClientRecord{Resolution{7680, 4321}}), ErrorCode::limit_exceeded);
  CHECK(one<Resolution>(encode(ClientRecord{Resolution{7680, 4320}})).height == 4320);
}

TEST_CASE("Camera rules: finite matrix, fov in (0, pi), not singular", "[protocol]") {
  SetCamera c = sample_camera();
  c.camera.to_world.m[5] = kNaN;
  CHECK(mentions(fails(encode(ClientRecord{c}), ErrorCode::not_finite), "to_world"));
  c = sample_camera();
  c.camera.fov_y = kInf;
  CHECK(mentions(fails(encode(ClientRecord{c}), ErrorCode::not_finite), "fov_y"));
  c.camera.fov_y = 0;
  fails(encode(ClientRecord{c}), ErrorCode::out_of_range);
  c.camera.fov_y = kPi;
  fails(encode(ClientRecord{c}), ErrorCode::out_of_range);
  c = sample_camera();
  c.camera.to_world = Mat4::scale({1, 0, 1});
  CHECK(mentions(fails(encode(ClientRecord{c}), ErrorCode::out_of_range), "singular"));
}

TEST_CASE("Environment rules", "[protocol]") {
  SetEnvironment e = sample_environment();
  e.environment.ambient.y = -0.1f;
  CHECK(mentions(fails(encode(ClientRecord{e}), ErrorCode::out_of_range), "ambient"));
  e = sample_environment();
  e.environment.background.z = kNaN;
  fails(encode(ClientRecord{e}), ErrorCode::not_finite);
  e = sample_environment();
  e.environment.exposure = 0;
  CHECK(mentions(fails(encode(ClientRecord{e}), ErrorCode::out_of_range), "exposure"));
  auto m = encode(ClientRecord{sample_environment()});
  m[kBody + 28] = 2;
  CHECK(mentions(fails(m, ErrorCode::bad_enum), "linear"));
  m[kBody + 28] = 1;
  m[kBody + 30] = 1;
  fails(m, ErrorCode::bad_reserved);
}

TEST_CASE("Buffer rules", "[protocol]") {
  auto good = encode(ClientRecord{positions_buffer(1, 1)});  // 9 floats
  SECTION("id 0 is reserved") {
    fails(encode(ClientRecord{positions_buffer(0, 1)}), ErrorCode::bad_id);
  }
  SECTION("type enum, flags, reserved") {
    auto m = good;
    m[kBody + 4] = 2;
    fails(m, ErrorCode::bad_enum);
    m = good;
    m[kBody + 6] = 2;
    fails(m, ErrorCode::bad_reserved);
    m = good;
    m[kBody + 7] = 1;
    fails(m, ErrorCode::bad_reserved);
  }
  SECTION("components 1..4 and values a multiple of them") {
    auto m = good;
    m[kBody + 5] = 0;
    fails(m, ErrorCode::bad_components);
    m[kBody + 5] = 5;
    fails(m, ErrorCode::bad_components);
    m[kBody + 5] = 2;  // 9 values are not float2s
    CHECK(mentions(fails(m, ErrorCode::bad_components), "multiple of 2"));
  }
  SECTION("payload length must match the declared value count") {
    auto m = good;
    patch<uint32_t>(m, kBody + 8, 6);
    fails(m, ErrorCode::bad_length);
  }
  SECTION("a huge declared size is rejected before allocating") {
    auto m = good;
    patch<uint32_t>(m, kBody + 8, 0xfffffffcu);  // 16 GiB declared
    CHECK(mentions(fails(m, ErrorCode::limit_exceeded), "exceeds the limit"));
    m[kBody + 6] = kBufferDeflate;
    fails(m, ErrorCode::limit_exceeded);
  }
  SECTION("max_buffer_bytes and max_vertices") {
    Limits lim;
    lim.max_buffer_bytes = 32;
    fails(good, ErrorCode::limit_exceeded, lim);
    lim = Limits{};
    lim.max_vertices = 2;
    CHECK(mentions(fails(good, ErrorCode::limit_exceeded, lim), "elements"));
  }
  SECTION("per-message payload total") {
    Limits lim;
    lim.max_message_payload_bytes = 60;
    std::vector<ClientRecord> two{positions_buffer(1, 1), positions_buffer(2, 1)};
    CHECK(dec(encode(ClientRecord{positions_buffer(1, 1)}), lim).ok());
    CHECK(fails(encode(two), ErrorCode::limit_exceeded, lim).find("record 1") == 0);
  }
  SECTION("deflate payloads: corrupt, short, long, bomb") {
    auto z = encode(ClientRecord{positions_buffer(1, 100, true)});
    REQUIRE(dec(z).ok());
    auto m = z;
    m[kBody + 12] = 0x00;  // zlib header
    fails(m, ErrorCode::bad_payload);
    m = z;
    patch<uint32_t>(m, kBody + 8, 903);  // declares more than the stream holds
    CHECK(mentions(fails(m, ErrorCode::bad_payload), "declared"));
    patch<uint32_t>(m, kBody + 8, 897);  // declares less
    CHECK(mentions(fails(m, ErrorCode::bad_payload), "exceeds the declared"));
    // A bomb: 64 MiB of zeros declared as 9 floats.
    std::vector<uint8_t> zeros(64 << 20);
    auto bomb = deflate_zlib(zeros.data(), zeros.size(), 9);
    zeros = {};
    m = encode(ClientRecord{positions_buffer(1, 1)});
    m.resize(kBody + 12);
    m[kBody + 6] = kBufferDeflate;
    m.insert(m.end(), bomb.begin(), bomb.end());
    patch<uint32_t>(m, 12, uint32_t(12 + bomb.size()));
    fails(m, ErrorCode::bad_payload);
  }
}

TEST_CASE("Texture rules", "[protocol]") {
  auto good = encode(ClientRecord{sample_texture(5)});
  REQUIRE(dec(good).ok());
  SECTION("id 0 is reserved") {
    fails(encode(ClientRecord{sample_texture(0)}), ErrorCode::bad_id);
  }
  SECTION("format, wrap, filter, srgb enums and reserved bytes") {
    const char* fields[] = {"format", "wrap_s", "wrap_t", "filter", "srgb"};
    for (int i = 0; i < 5; ++i) {
      auto m = good;
      m[kBody + 4 + i] = 3;
      CHECK(mentions(fails(m, ErrorCode::bad_enum), fields[i]));
    }
    auto m = good;
    m[kBody + 10] = 1;
    fails(m, ErrorCode::bad_reserved);
  }
  SECTION("dimensions non-empty and within max_texture_size") {
    auto m = good;
    patch<uint32_t>(m, kBody + 12, 0);
    fails(m, ErrorCode::out_of_range);
    Limits lim;
    lim.max_texture_size = 2;
    CHECK(mentions(fails(good, ErrorCode::limit_exceeded, lim), "texture size 3x2"));
    m = good;
    patch<uint32_t>(m, kBody + 12, 100000);
    patch<uint32_t>(m, kBody + 16, 100000);
    fails(m, ErrorCode::limit_exceeded);
  }
  SECTION("raw texel bytes must match width x height x 4") {
    auto m = good;
    patch<uint32_t>(m, kBody + 16, 1);
    fails(m, ErrorCode::bad_length);
  }
  SECTION("encoded bytes that are not an image") {
    auto m = good;
    m[kBody + 4] = uint8_t(TextureFormat::png);
    CHECK(mentions(fails(m, ErrorCode::bad_texture), "not a PNG"));
    m[kBody + 4] = uint8_t(TextureFormat::jpeg);
    fails(m, ErrorCode::bad_texture);
  }
  SECTION("decoded texture bytes count against the message payload limit") {
    Limits lim;
    lim.max_message_payload_bytes = 23;
    fails(good, ErrorCode::limit_exceeded, lim);
  }
}

TEST_CASE("Material rules", "[protocol]") {
  auto bad = [](auto change, ErrorCode code, const char* field) {
    SetMaterial m = sample_material(4);
    change(m.material);
    CHECK(mentions(fails(encode(ClientRecord{m}), code), field));
  };
  fails(encode(ClientRecord{sample_material(0)}), ErrorCode::bad_id);
  auto good = encode(ClientRecord{sample_material(4)});
  auto m = good;
  m[kBody + 4] = 3;
  CHECK(mentions(fails(m, ErrorCode::bad_enum), "model"));
  m = good;
  m[kBody + 5] = 8;  // bits 0..2 are alpha_mask, double_sided, use_vertex_color
  fails(m, ErrorCode::bad_reserved);
  m = good;
  m[kBody + 5] = 4;  // use_vertex_color alone
  {
    auto r = decode_client(m.data(), m.size(), Limits{});
    REQUIRE(r.ok());
    const Material& x = std::get<SetMaterial>(r.value()[0]).material;
    CHECK(x.use_vertex_color);
    CHECK_FALSE(x.alpha_mask);
    CHECK_FALSE(x.double_sided);
  }
  m = good;
  m[kBody + 6] = 1;
  fails(m, ErrorCode::bad_reserved);
  bad([](Material& x) { x.diffuse_color.x = kNaN; }, ErrorCode::not_finite, "diffuse_color");
  bad([](Material& x) { x.specular_color.y = -1; }, ErrorCode::out_of_range, "specular_color");
  bad([](Material& x) { x.emissive_color.z = kInf; }, ErrorCode::not_finite, "emissive_color");
  bad([](Material& x) { x.shininess = -1; }, ErrorCode::out_of_range, "shininess");
  bad([](Material& x) { x.ambient_intensity = kNaN; }, ErrorCode::not_finite, "ambient_intensity");
  bad([](Material& x) { x.opacity = 1.5f; }, ErrorCode::out_of_range, "opacity");
  bad([](Material& x) { x.reflection = 2; }, ErrorCode::out_of_range, "reflection");
  bad([](Material& x) { x.refraction = -0.5f; }, ErrorCode::out_of_range, "refraction");
  bad([](Material& x) { x.ior = 0; }, ErrorCode::out_of_range, "ior");
  bad([](Material& x) { x.alpha_cutoff = 1.1f; }, ErrorCode::out_of_range, "alpha_cutoff");
}

TEST_CASE("Mesh rules at decode time", "[protocol]") {
  fails(encode(ClientRecord{sample_mesh(0, 1)}), ErrorCode::bad_id);
  CHECK(mentions(fails(encode(ClientRecord{sample_mesh(1, 0)}), ErrorCode::bad_id), "positions"));
  SetMesh s = sample_mesh(1, 2);
  s.mesh.transform.m[12] = kInf;
  CHECK(mentions(fails(encode(ClientRecord{s}), ErrorCode::not_finite), "transform"));
  auto m = encode(ClientRecord{sample_mesh(1, 2)});
  m[kBody + wire::mesh::at::visible] = 2;
  CHECK(mentions(fails(m, ErrorCode::bad_enum), "visible"));
  m[kBody + wire::mesh::at::visible] = 0;
  m[kBody + wire::mesh::at::reserved + 2] = 1;
  fails(m, ErrorCode::bad_reserved);
  // The colour buffer id sits between texcoords and indices; 0 is "none", any other id decodes.
  SetMesh c = sample_mesh(1, 2, 3);
  c.mesh.colors = 7;
  auto cm = encode(ClientRecord{c});
  CHECK(cm.size() == kBody + wire::mesh::kFixed);
  CHECK(cm[kBody + wire::mesh::at::colors] == 7);
  auto r = decode_client(cm.data(), cm.size(), Limits{});
  REQUIRE(r.ok());
  CHECK(std::get<SetMesh>(r.value()[0]).mesh.colors == 7);
  CHECK(std::get<SetMesh>(r.value()[0]).mesh.indices == 3);
}

TEST_CASE("Light rules", "[protocol]") {
  auto bad = [](auto change, ErrorCode code, const char* field) {
    SetLight l = sample_light(3);
    change(l.light);
    CHECK(mentions(fails(encode(ClientRecord{l}), code), field));
  };
  fails(encode(ClientRecord{sample_light(0)}), ErrorCode::bad_id);
  auto good = encode(ClientRecord{sample_light(3)});
  auto m = good;
  m[kBody + 4] = 3;
  CHECK(mentions(fails(m, ErrorCode::bad_enum), "type"));
  m = good;
  m[kBody + 5] = 2;
  CHECK(mentions(fails(m, ErrorCode::bad_enum), "on"));
  m = good;
  m[kBody + 7] = 2;
  fails(m, ErrorCode::bad_reserved);
  bad([](Light& l) { l.color.x = -1; }, ErrorCode::out_of_range, "color");
  bad([](Light& l) { l.intensity = kNaN; }, ErrorCode::not_finite, "intensity");
  bad([](Light& l) { l.intensity = -2; }, ErrorCode::out_of_range, "intensity");
  bad([](Light& l) { l.position.z = kInf; }, ErrorCode::not_finite, "position");
  bad([](Light& l) { l.direction.x = kNaN; }, ErrorCode::not_finite, "direction");
  bad([](Light& l) { l.direction = {0, 0, 0}; }, ErrorCode::out_of_range, "direction");
  bad([](Light& l) { l.attenuation = {0, 0, 0}; }, ErrorCode::out_of_range, "attenuation");
  bad([](Light& l) { l.attenuation.y = -1; }, ErrorCode::out_of_range, "attenuation");
  bad([](Light& l) { l.cutoff = 4; }, ErrorCode::out_of_range, "cutoff");
  bad([](Light& l) { l.cutoff = 0; }, ErrorCode::out_of_range, "cutoff");
  bad([](Light& l) { l.softness = 1.5f; }, ErrorCode::out_of_range, "softness");
  // A point light needs no direction; a directional light no attenuation.
  SetLight p = sample_light(3);
  p.light.type = Light::Type::point;
  p.light.direction = {0, 0, 0};
  CHECK(dec(encode(ClientRecord{p})).ok());
  SetLight d = sample_light(3);
  d.light.type = Light::Type::directional;
  d.light.attenuation = {0, 0, 0};
  CHECK(dec(encode(ClientRecord{d})).ok());
}

TEST_CASE("Remove rules", "[protocol]") {
  fails(encode(ClientRecord{Remove{RecordType::mesh, 0}}), ErrorCode::bad_id);
  auto m = encode(ClientRecord{Remove{RecordType::mesh, 3}});
  m.push_back(0);
  patch<uint32_t>(m, 12, 5);
  fails(m, ErrorCode::bad_length);
}

// ---------------------------------------------------------------------------------------
// Applying to a scene.

TEST_CASE("Applying decoded updates changes the scene", "[protocol]") {
  Scene scene;
  Limits lim;
  auto bytes = encode(every_client_record());
  auto r = dec(bytes);
  REQUIRE(r.ok());
  std::vector<ErrorCode> codes;
  for (auto& rec : r.value()) codes.push_back(apply(scene, std::move(rec), lim).code());
  // Settings, render requests, refine and budget are for the session; removing light 21 (absent) fails.
  CHECK(codes.front() == ErrorCode::not_scene_update);
  CHECK(codes.back() == ErrorCode::not_scene_update);
  for (size_t i = 12; i < codes.size(); ++i) CHECK(codes[i] == ErrorCode::not_scene_update);
  CHECK(codes[11] == ErrorCode::unknown_id);
  for (size_t i = 1; i < 11; ++i) CHECK(codes[i] == ErrorCode::ok);
  CHECK(scene.width() == 800);
  CHECK(scene.camera().fov_y == 0.8f);
  CHECK(scene.environment().exposure == 1.5f);
  REQUIRE(scene.buffer(2));
  CHECK(scene.buffer(2)->count() == 9);
  CHECK(scene.texture(5)->width == 3);
  CHECK(scene.material(4)->ior == 1.33f);
  CHECK(scene.meshes().count(10) == 1);
  CHECK(scene.lights().count(20) == 1);
  CHECK(scene.triangle_count() == 2);
  CHECK(scene_bytes(scene) == (18 + 27) * 4 + 6 * 4 + 24);
  CHECK(apply(scene, Remove{RecordType::mesh, 10}, lim).ok());
  CHECK(scene.meshes().empty());
  CHECK(apply(scene, Remove{RecordType::buffer, 2}, lim).ok());
  CHECK(apply(scene, Remove{RecordType::texture, 5}, lim).ok());
  CHECK(apply(scene, Remove{RecordType::material, 4}, lim).ok());
  CHECK(apply(scene, Remove{RecordType::light, 20}, lim).ok());
  CHECK(apply(scene, Remove{RecordType::light, 20}, lim).code() == ErrorCode::unknown_id);
  CHECK(apply(scene, Handshake{}, lim).code() == ErrorCode::not_scene_update);
}

TEST_CASE("Meshes whose buffers are missing are accepted; inconsistent ones are rejected", "[protocol]") {
  Scene scene;
  Limits lim;
  // Progressive loading: the mesh first, its buffers later.
  CHECK(apply(scene, sample_mesh(1, 10, 11), lim).ok());
  CHECK(apply(scene, positions_buffer(10, 1), lim).ok());
  CHECK(apply(scene, index_buffer(11, {0, 1, 2}), lim).ok());
  CHECK(scene.validate_mesh(scene.meshes().at(1).value).empty());
  // With the buffers present, an index out of range is rejected at mesh time.
  CHECK(apply(scene, index_buffer(12, {0, 1, 3}), lim).ok());
  auto st = apply(scene, sample_mesh(2, 10, 12), lim);
  CHECK(st.code() == ErrorCode::bad_mesh);
  CHECK(mentions(st.error().message, "index 3 out of range"));
  CHECK(scene.meshes().count(2) == 0);
  // Buffers are never rejected for consistency: a buffer that makes a complete mesh invalid
  // is stored, and the mesh fails validate_mesh until the client fixes it.
  CHECK(apply(scene, index_buffer(11, {0, 1, 5}), lim).ok());
  CHECK_FALSE(scene.validate_mesh(scene.meshes().at(1).value).empty());
  CHECK(apply(scene, index_buffer(11, {2, 1, 0}), lim).ok());
  CHECK(scene.validate_mesh(scene.meshes().at(1).value).empty());
  // Wrong component count of the position buffer.
  SetBuffer b2 = positions_buffer(13, 1);
  b2.buffer.components = 1;
  CHECK(apply(scene, std::move(b2), lim).ok());
  CHECK(apply(scene, sample_mesh(3, 13), lim).code() == ErrorCode::bad_mesh);
  // A NaN position is caught through validate_mesh.
  SetBuffer nan = positions_buffer(14, 1);
  nan.buffer.f[4] = kNaN;
  CHECK(apply(scene, std::move(nan), lim).ok());
  CHECK(apply(scene, sample_mesh(4, 14), lim).code() == ErrorCode::bad_mesh);
}

TEST_CASE("Vertex colour buffers: float3, one per vertex, finite; a mesh waits for its colours", "[protocol]") {
  Scene scene;
  Limits lim;
  CHECK(apply(scene, positions_buffer(10, 1), lim).ok());  // 3 vertices
  auto colors = [](Id id, uint8_t components, size_t values) {
    SetBuffer b;
    b.id = id;
    b.buffer.type = Buffer::Type::f32;
    b.buffer.components = components;
    b.buffer.f.assign(values, 0.5f);
    return b;
  };
  auto with_colors = [](Id id, Id c) {
    SetMesh m = sample_mesh(id, 10);
    m.mesh.colors = c;
    return m;
  };
  // Progressive loading: the colours may come after the mesh.
  CHECK(apply(scene, with_colors(1, 20), lim).ok());
  CHECK_FALSE(scene.validate_mesh(scene.meshes().at(1).value).empty());
  CHECK(mentions(scene.validate_mesh(scene.meshes().at(1).value), "colour buffer 20"));
  CHECK(apply(scene, colors(20, 3, 9), lim).ok());
  CHECK(scene.validate_mesh(scene.meshes().at(1).value).empty());
  CHECK(apply(scene, with_colors(2, 20), lim).ok());
  // Two components (float2): refused as the texcoord rule refuses a float3 texcoord buffer.
  CHECK(apply(scene, colors(21, 2, 6), lim).ok());
  auto st = apply(scene, with_colors(3, 21), lim);
  CHECK(st.code() == ErrorCode::bad_mesh);
  CHECK(mentions(st.error().message, "colour buffer must be float3"));
  // Four components (RGBA) are not taken either.
  CHECK(apply(scene, colors(22, 4, 12), lim).ok());
  CHECK(apply(scene, with_colors(3, 22), lim).code() == ErrorCode::bad_mesh);
  // Integers are not colours.
  SetBuffer ints = index_buffer(23, {0, 1, 2, 0, 1, 2, 0, 1, 2});
  ints.buffer.components = 3;
  CHECK(apply(scene, std::move(ints), lim).ok());
  CHECK(mentions(apply(scene, with_colors(3, 23), lim).error().message, "float3"));
  // Another vertex count than the positions'.
  CHECK(apply(scene, colors(24, 3, 12), lim).ok());
  st = apply(scene, with_colors(3, 24), lim);
  CHECK(st.code() == ErrorCode::bad_mesh);
  CHECK(mentions(st.error().message, "colour count 4 != vertex count 3"));
  // NaN or Inf colours.
  SetBuffer nan = colors(25, 3, 9);
  nan.buffer.f[4] = kNaN;
  CHECK(apply(scene, std::move(nan), lim).ok());
  CHECK(mentions(apply(scene, with_colors(3, 25), lim).error().message, "NaN or Inf"));
  CHECK(scene.meshes().count(3) == 0);
  // A colour buffer replaced by a bad one leaves the mesh unrenderable until fixed.
  CHECK(apply(scene, colors(20, 3, 6), lim).ok());
  CHECK_FALSE(scene.validate_mesh(scene.meshes().at(1).value).empty());
}

TEST_CASE("Scene-wide limits: client bytes and triangles", "[protocol]") {
  Scene scene;
  Limits lim;
  lim.max_client_bytes = 100;
  CHECK(apply(scene, positions_buffer(1, 2), lim).ok());  // 72 bytes
  auto st = apply(scene, positions_buffer(2, 1), lim);   // +36
  CHECK(st.code() == ErrorCode::limit_exceeded);
  CHECK(mentions(st.error().message, "100 bytes"));
  CHECK(apply(scene, positions_buffer(1, 1), lim).ok());  // replacing counts the old size out
  CHECK(apply(scene, sample_texture(3, 5, 4), lim).code() == ErrorCode::limit_exceeded);
  lim = Limits{};
  lim.max_triangles = 3;
  CHECK(apply(scene, positions_buffer(1, 2), lim).ok());
  CHECK(apply(scene, sample_mesh(1, 1), lim).ok());
  CHECK(apply(scene, sample_mesh(2, 1), lim).code() == ErrorCode::limit_exceeded);  // 2 + 2 instances
  CHECK(apply(scene, positions_buffer(1, 4), lim).code() == ErrorCode::limit_exceeded);
  CHECK(apply(scene, positions_buffer(1, 3), lim).ok());
  SetMesh hidden = sample_mesh(2, 1);
  hidden.mesh.visible = false;
  CHECK(apply(scene, std::move(hidden), lim).ok());
}

TEST_CASE("Updates waiting to be applied count against the client's bytes as if applied in order", "[protocol]") {
  Scene scene;
  Limits lim;
  lim.max_client_bytes = 200;
  REQUIRE(apply(scene, positions_buffer(1, 2), lim).ok());  // 72 bytes held
  PendingBytes p;
  CHECK(p.admit(scene, ClientRecord{positions_buffer(2, 2)}, lim).ok());  // 144 once applied
  Status over = p.admit(scene, ClientRecord{positions_buffer(3, 2)}, lim);  // 216
  CHECK(over.code() == ErrorCode::limit_exceeded);
  CHECK(mentions(over.error().message, "buffer 3"));
  CHECK(mentions(over.error().message, "200 bytes"));
  CHECK(p.admit(scene, ClientRecord{positions_buffer(2, 1)}, lim).ok());  // replaces the waiting 72 with 36: 108
  CHECK(p.admit(scene, ClientRecord{positions_buffer(3, 2)}, lim).ok());  // 180
  CHECK(p.admit(scene, ClientRecord{positions_buffer(1, 1)}, lim).ok());  // replaces the scene's 72 with 36: 144
  CHECK(p.admit(scene, ClientRecord{Remove{RecordType::buffer, 3}}, lim).ok());  // frees the waiting 72: 72
  CHECK(p.admit(scene, ClientRecord{sample_texture(5, 4, 4)}, lim).ok());                // 64 texel bytes: 136
  CHECK(p.admit(scene, ClientRecord{sample_texture(6, 5, 4)}, lim).code() == ErrorCode::limit_exceeded);  // +80: 216
  CHECK(p.admit(scene, ClientRecord{SetCamera{}}, lim).ok());  // holds no bytes
  CHECK(scene_bytes(scene) == 72);  // admitting applies nothing
  p.clear();  // the waiting updates were applied or dropped: only the scene counts
  CHECK(p.admit(scene, ClientRecord{positions_buffer(4, 3)}, lim).ok());  // 72 + 108
}

// ---------------------------------------------------------------------------------------
// Robustness.

TEST_CASE("Messages truncated at every byte offset are rejected without crashing", "[protocol]") {
  auto client = encode(every_client_record());
  for (size_t n = 0; n < client.size(); ++n) {
    auto r = decode_client(client.data(), n, Limits{});
    REQUIRE_FALSE(r.ok());
    CHECK_FALSE(r.error().message.empty());
  }
  auto hs = encode(ClientRecord{sample_handshake()});
  for (size_t n = 0; n < hs.size(); ++n) REQUIRE_FALSE(decode_client(hs.data(), n, Limits{}).ok());
  Frame f;
  f.width = 8;
  f.height = 8;
  f.encoding = FrameEncoding::dxt1;
  f.payload.assign(dxt1_size(8, 8), 1);
  HandshakeReply h;
  h.server_version = "x";
  auto server = encode(std::vector<ServerRecord>{h, f, ErrorReply{ErrorCode::internal, true, 0, "m"}, Stats{}});
  REQUIRE(decode_server(server.data(), server.size(), Limits{}).ok());
  for (size_t n = 0; n < server.size(); ++n) REQUIRE_FALSE(decode_server(server.data(), n, Limits{}).ok());
}

TEST_CASE("Every single-byte corruption decodes or fails cleanly", "[protocol]") {
  auto client = encode(every_client_record());
  size_t rejected = 0;
  for (size_t i = 0; i < client.size(); ++i)
    for (uint8_t x : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xff)}) {
      auto m = client;
      m[i] ^= x;
      auto r = dec(m);
      if (!r.ok()) ++rejected;
    }
  CHECK(rejected > client.size());  // most flips hit a checked field
}

TEST_CASE("Server-side rules: frame payload size and error codes", "[protocol]") {
  Frame f;
  f.width = 5;
  f.height = 3;
  f.encoding = FrameEncoding::dxt1;
  f.payload.assign(15, 0);
  auto m = encode(ServerRecord{f});
  auto r = decode_server(m.data(), m.size(), Limits{});
  REQUIRE_FALSE(r.ok());
  CHECK(r.error().code == ErrorCode::bad_length);
  ErrorReply e{ErrorCode(200), false, 0, "x"};
  m = encode(ServerRecord{e});
  r = decode_server(m.data(), m.size(), Limits{});
  REQUIRE_FALSE(r.ok());
  CHECK(r.error().code == ErrorCode::bad_enum);
  for (uint16_t c = 0; c <= kMaxErrorCode; ++c) CHECK(std::string(to_string(ErrorCode(c))) != "unknown");
}

TEST_CASE("The checked-in fuzz corpus holds valid messages", "[protocol]") {
  // fuzz_protocol's seeds, and fuzz_render's messages (it also takes glTF files).
  namespace fs = std::filesystem;
  size_t n = 0;
  for (const char* dir : {"tests/fuzz/corpus/protocol", "tests/fuzz/corpus/render"}) {
    for (auto& entry : fs::directory_iterator(dir)) {
      if (entry.path().extension() == ".gltf") continue;
      std::ifstream f(entry.path(), std::ios::binary);
      std::vector<uint8_t> m((std::istreambuf_iterator<char>(f)), {});
      INFO(entry.path().string());
      bool server = m.size() > 3 && m[3] == uint8_t(Channel::server);
      // The render target's seeds that aborted the node inside Embree (issue 16) are refused
      // where they enter now: a transform or camera outside core/validate.h's bounds.
      const std::string name = entry.path().filename().string();
      if (name.rfind("abort_", 0) == 0 || name.rfind("render_found_", 0) == 0) {
        CHECK(dec(m).code() == ErrorCode::out_of_range);
      } else {
        CHECK((server ? decode_server(m.data(), m.size(), Limits{}).ok() : dec(m).ok()));
      }
      ++n;
    }
  }
  CHECK(n >= 25);
}

TEST_CASE("Server-side rules: handshake reply, frame and stats fields", "[protocol]") {
  auto server_fails = [](std::vector<uint8_t> m, ErrorCode code) {
    auto r = decode_server(m.data(), m.size(), Limits{});
    REQUIRE_FALSE(r.ok());
    INFO(r.error().message);
    CHECK(r.error().code == code);
  };
  HandshakeReply h;
  h.server_version = "v";
  auto good = encode(ServerRecord{h});
  auto m = good;
  m[kBody] = 2;
  server_fails(m, ErrorCode::bad_enum);
  m = good;
  m[kBody + 2] = 0;
  server_fails(m, ErrorCode::out_of_range);
  m = good;
  m[kBody + 3] = 2;  // version string longer than the body
  server_fails(m, ErrorCode::bad_length);
  m = good;
  patch<uint32_t>(m, kBody + 8, 0);
  server_fails(m, ErrorCode::out_of_range);
  Frame f;
  f.width = 4;
  f.height = 4;
  f.payload = {1, 2, 3};
  good = encode(ServerRecord{f});
  REQUIRE(decode_server(good.data(), good.size(), Limits{}).ok());
  m = good;
  m[kBody + 12] = 3;  // encoding: jpeg, dxt1, h264
  server_fails(m, ErrorCode::bad_enum);
  m = good;
  m[kBody + 13] = 3;  // refined: requested, refined, converged
  server_fails(m, ErrorCode::bad_enum);
  m = good;
  m[kBody + 13] = 2;  // the still's last refinement
  {
    auto ok = decode_server(m.data(), m.size(), Limits{});
    REQUIRE(ok.ok());
    CHECK(std::get<Frame>(ok.value()[0]).refined);
    CHECK(std::get<Frame>(ok.value()[0]).converged);
    Frame back = std::get<Frame>(ok.value()[0]);
    CHECK(encode(ServerRecord{back}) == m);
  }
  m = good;
  m[kBody + 13] = 1;
  m[kBody + 14] = m[kBody + 15] = 0;  // 0 samples decode as they are
  {
    auto ok = decode_server(m.data(), m.size(), Limits{});
    REQUIRE(ok.ok());
    CHECK(std::get<Frame>(ok.value()[0]).refined);
    CHECK_FALSE(std::get<Frame>(ok.value()[0]).converged);
    CHECK(std::get<Frame>(ok.value()[0]).samples == 0);
  }
  m = good;
  m[9] = 1;  // server records have op 0
  server_fails(m, ErrorCode::bad_op);
  m = encode(ServerRecord{ErrorReply{ErrorCode::internal, true, 0, "x"}});
  m[kBody + 2] = 2;
  server_fails(m, ErrorCode::bad_enum);
  m = encode(ServerRecord{Stats{}});
  m.push_back(0);
  patch<uint32_t>(m, 12, 45);
  server_fails(m, ErrorCode::bad_length);
  m = encode(ServerRecord{Stats{}});
  m[8] = uint8_t(RecordType::camera);  // a client record from the server
  server_fails(m, ErrorCode::unknown_record);
}

TEST_CASE("The scene's running triangle and byte totals equal a direct recount after random updates", "[unit]") {
  using namespace tessera;
  std::mt19937 rng(7);
  Scene scene;
  protocol::Limits lim;
  auto recount = [&] {
    uint64_t tris = 0, bytes = 0;
    for (auto& [id, e] : scene.meshes()) {
      const Mesh& m = e.value;
      if (!m.visible) continue;
      if (m.indices != kNoId) tris += scene.buffer(m.indices) ? scene.buffer(m.indices)->u.size() / 3 : 0;
      else tris += scene.buffer(m.positions) ? scene.buffer(m.positions)->count() / 3 : 0;
    }
    for (auto& [id, e] : scene.buffers()) bytes += e.value.bytes();
    for (auto& [id, e] : scene.textures()) bytes += e.value.rgba.size();
    return std::make_pair(tris, bytes);
  };
  for (int step = 0; step < 3000; ++step) {
    const Id id = Id(1 + rng() % 12);
    switch (rng() % 5) {
      case 0: {  // a float3 buffer of 3..30 vertices
        protocol::SetBuffer b;
        b.id = id;
        b.buffer.components = 3;
        b.buffer.f.assign(size_t(3 * 3 * (1 + rng() % 10)), 0.5f);
        (void)apply(scene, b, lim);
        break;
      }
      case 1: {  // an index buffer
        protocol::SetBuffer b;
        b.id = id;
        b.buffer.type = Buffer::Type::u32;
        b.buffer.u.assign(size_t(3 * (rng() % 6)), 0u);
        (void)apply(scene, b, lim);
        break;
      }
      case 2: {  // a mesh, indexed or not, visible or not
        protocol::SetMesh m;
        m.id = id;
        m.mesh.positions = Id(1 + rng() % 12);
        m.mesh.indices = rng() % 2 ? Id(1 + rng() % 12) : kNoId;
        m.mesh.visible = rng() % 4 != 0;
        (void)apply(scene, m, lim);
        break;
      }
      case 3: (void)apply(scene, protocol::Remove{protocol::RecordType::buffer, id}, lim); break;
      default: (void)apply(scene, protocol::Remove{protocol::RecordType::mesh, id}, lim); break;
    }
    auto [tris, bytes] = recount();
    REQUIRE(scene.triangle_count() == tris);
    REQUIRE(scene_bytes(scene) == bytes);
  }
  // And a copy carries them along.
  Scene copy = scene;
  CHECK(copy.triangle_count() == scene.triangle_count());
}
