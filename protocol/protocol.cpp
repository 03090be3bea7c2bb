#include "protocol/protocol.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "codecs/deflate.h"
#include "codecs/jpeg.h"
#include "core/image.h"
#include "core/validate.h"

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the wire format is little endian and read with memcpy");

namespace tessera::protocol {

const char* to_string(ErrorCode c) {
  switch (c) {
    case ErrorCode::ok: return "ok";
    case ErrorCode::truncated: return "truncated";
    case ErrorCode::bad_magic: return "bad_magic";
    case ErrorCode::bad_version: return "bad_version";
    case ErrorCode::bad_channel: return "bad_channel";
    case ErrorCode::too_large: return "too_large";
    case ErrorCode::unknown_record: return "unknown_record";
    case ErrorCode::bad_op: return "bad_op";
    case ErrorCode::bad_length: return "bad_length";
    case ErrorCode::bad_reserved: return "bad_reserved";
    case ErrorCode::bad_id: return "bad_id";
    case ErrorCode::bad_enum: return "bad_enum";
    case ErrorCode::bad_components: return "bad_components";
    case ErrorCode::not_finite: return "not_finite";
    case ErrorCode::out_of_range: return "out_of_range";
    case ErrorCode::limit_exceeded: return "limit_exceeded";
    case ErrorCode::bad_payload: return "bad_payload";
    case ErrorCode::bad_texture: return "bad_texture";
    case ErrorCode::bad_mesh: return "bad_mesh";
    case ErrorCode::unknown_id: return "unknown_id";
    case ErrorCode::bad_handshake: return "bad_handshake";
    case ErrorCode::not_scene_update: return "not_scene_update";
    case ErrorCode::internal: return "internal";
    case ErrorCode::no_effect: return "no_effect";
    case ErrorCode::bad_task: return "bad_task";
    case ErrorCode::render_failed: return "render_failed";
    case ErrorCode::no_scene: return "no_scene";
    case ErrorCode::bad_batch: return "bad_batch";
    case ErrorCode::bad_tile: return "bad_tile";
    case ErrorCode::node_lost: return "node_lost";
    case ErrorCode::no_node: return "no_node";
    case ErrorCode::node_late: return "node_late";
  }
  return "unknown";
}

const char* to_string(RecordType t) {
  switch (t) {
    case RecordType::handshake: return "handshake";
    case RecordType::settings: return "settings";
    case RecordType::refine: return "refine";
    case RecordType::budget: return "budget";
    case RecordType::video: return "video";
    case RecordType::resolution: return "resolution";
    case RecordType::camera: return "camera";
    case RecordType::environment: return "environment";
    case RecordType::buffer: return "buffer";
    case RecordType::texture: return "texture";
    case RecordType::material: return "material";
    case RecordType::mesh: return "mesh";
    case RecordType::light: return "light";
    case RecordType::render: return "render";
    case RecordType::buffer_ref: return "buffer_ref";
    case RecordType::texture_ref: return "texture_ref";
    case RecordType::reference: return "reference";
    case RecordType::handshake_reply: return "handshake_reply";
    case RecordType::frame: return "frame";
    case RecordType::error: return "error";
    case RecordType::stats: return "stats";
  }
  return "?";
}

bool is_fatal(ErrorCode c) { return c == ErrorCode::bad_version || c == ErrorCode::bad_handshake; }

ErrorReply to_reply(const Error& e) {
  ErrorReply r;
  r.code = uint16_t(e.code) <= kMaxErrorCode ? e.code : ErrorCode::internal;  // node codes stay in the node
  r.fatal = is_fatal(e.code);
  r.record = e.record;
  r.message = r.code == e.code ? e.message : std::string(to_string(e.code)) + ": " + e.message;
  return r;
}

namespace {

// ---------------------------------------------------------------------------------------
// Writing.

class Writer {
 public:
  explicit Writer(std::vector<uint8_t>& out) : out_(out) {}
  template <class T>
  void put(T v) {
    static_assert(std::is_arithmetic_v<T>);
    size_t n = out_.size();
    out_.resize(n + sizeof(T));
    std::memcpy(out_.data() + n, &v, sizeof(T));
  }
  void u8(uint8_t v) { put(v); }
  void u16(uint16_t v) { put(v); }
  void u32(uint32_t v) { put(v); }
  void u64(uint64_t v) { put(v); }
  void f32(float v) { put(v); }
  void vec3(const Vec3& v) { f32(v.x), f32(v.y), f32(v.z); }
  void mat4(const Mat4& m) {
    for (float v : m.m) f32(v);
  }
  void bytes(const void* p, size_t n) {
    if (!n) return;
    size_t at = out_.size();
    out_.resize(at + n);
    std::memcpy(out_.data() + at, p, n);
  }
  // Starts a record: returns the offset of its body length, patched by end_record.
  size_t begin_record(RecordType t, Op op) {
    u8(uint8_t(t));
    u8(uint8_t(op));
    u16(0);
    size_t at = out_.size();
    u32(0);
    return at;
  }
  void end_record(size_t at) {
    uint32_t len = uint32_t(out_.size() - at - 4);
    std::memcpy(out_.data() + at, &len, 4);
  }

 private:
  std::vector<uint8_t>& out_;
};

void message_header(Writer& w, Channel c, uint32_t count) {
  w.u8(kMagic0);
  w.u8(kMagic1);
  w.u8(kVersion);
  w.u8(uint8_t(c));
  w.u32(count);
}

struct ClientEncoder {
  Writer& w;
  void operator()(const Handshake& h) {
    size_t at = w.begin_record(RecordType::handshake, Op::set);
    w.u8(uint8_t(h.renderer));
    w.u8(uint8_t(h.display));
    w.u8(h.jpeg_quality);
    w.u8(0);
    w.u32(h.max_nodes);
    w.u32(uint32_t(h.width));
    w.u32(uint32_t(h.height));
    w.end_record(at);
  }
  void operator()(const Settings& s) {
    size_t at = w.begin_record(RecordType::settings, Op::set);
    w.u32(s.ao_samples);
    w.u32(s.max_depth);
    w.end_record(at);
  }
  void operator()(const Refine& r) {
    size_t at = w.begin_record(RecordType::refine, Op::set);
    w.u32(r.samples);
    w.end_record(at);
  }
  void operator()(const Budget& b) {
    size_t at = w.begin_record(RecordType::budget, Op::set);
    w.u32(b.frame_ms);
    w.end_record(at);
  }
  void operator()(const Video& v) {
    size_t at = w.begin_record(RecordType::video, Op::set);
    w.u32(v.bitrate_kbps);
    w.u8(v.keyframe ? 1 : 0);
    w.u8(0);
    w.u8(0);
    w.u8(0);
    w.end_record(at);
  }
  void operator()(const Resolution& r) {
    size_t at = w.begin_record(RecordType::resolution, Op::set);
    w.u32(uint32_t(r.width));
    w.u32(uint32_t(r.height));
    w.end_record(at);
  }
  void operator()(const SetCamera& c) {
    size_t at = w.begin_record(RecordType::camera, Op::set);
    w.mat4(c.camera.to_world);
    w.f32(c.camera.fov_y);
    w.end_record(at);
  }
  void operator()(const SetEnvironment& e) {
    size_t at = w.begin_record(RecordType::environment, Op::set);
    w.vec3(e.environment.ambient);
    w.vec3(e.environment.background);
    w.f32(e.environment.exposure);
    w.u8(e.environment.linear ? 1 : 0);
    w.u8(0), w.u8(0), w.u8(0);
    w.end_record(at);
  }
  void operator()(const SetBuffer& b) {
    size_t at = w.begin_record(RecordType::buffer, Op::set);
    const Buffer& buf = b.buffer;
    const void* data = buf.type == Buffer::Type::f32 ? static_cast<const void*>(buf.f.data()) : buf.u.data();
    size_t values = buf.type == Buffer::Type::f32 ? buf.f.size() : buf.u.size();
    w.u32(b.id);
    w.u8(uint8_t(buf.type));
    w.u8(buf.components);
    w.u8(b.deflate ? kBufferDeflate : 0);
    w.u8(0);
    w.u32(uint32_t(values));
    if (b.deflate) {
      auto z = deflate_zlib(static_cast<const uint8_t*>(data), values * 4);
      w.bytes(z.data(), z.size());
    } else {
      w.bytes(data, values * 4);
    }
    w.end_record(at);
  }
  void operator()(const SetTexture& t) {
    size_t at = w.begin_record(RecordType::texture, Op::set);
    w.u32(t.id);
    w.u8(uint8_t(t.format));
    w.u8(uint8_t(t.texture.sampler.wrap_s));
    w.u8(uint8_t(t.texture.sampler.wrap_t));
    w.u8(uint8_t(t.texture.sampler.filter));
    w.u8(t.texture.srgb ? 1 : 0);
    w.u8(0), w.u8(0), w.u8(0);
    w.u32(uint32_t(t.texture.width));
    w.u32(uint32_t(t.texture.height));
    if (t.format == TextureFormat::rgba8)
      w.bytes(t.texture.rgba.data(), t.texture.rgba.size());
    else
      w.bytes(t.encoded.data(), t.encoded.size());
    w.end_record(at);
  }
  void operator()(const SetBufferRef& b) {
    size_t at = w.begin_record(RecordType::buffer_ref, Op::set);
    w.u32(b.id);
    w.u8(uint8_t(b.type));
    w.u8(b.components);
    w.u8(uint8_t(b.source));
    w.u8(0);
    w.u32(b.value_count);
    w.u32(b.byte_stride);
    w.u64(b.byte_offset);
    w.bytes(b.url.data(), std::min(b.url.size(), wire::buffer_ref::url_max_length));
    w.end_record(at);
  }
  void operator()(const SetTextureRef& t) {
    size_t at = w.begin_record(RecordType::texture_ref, Op::set);
    w.u32(t.id);
    w.u8(uint8_t(t.sampler.wrap_s));
    w.u8(uint8_t(t.sampler.wrap_t));
    w.u8(uint8_t(t.sampler.filter));
    w.u8(t.srgb ? 1 : 0);
    w.bytes(t.url.data(), std::min(t.url.size(), wire::texture_ref::url_max_length));
    w.end_record(at);
  }
  void operator()(const SetMaterial& s) {
    size_t at = w.begin_record(RecordType::material, Op::set);
    const Material& m = s.material;
    w.u32(s.id);
    w.u8(uint8_t(m.model));
    w.u8(uint8_t((m.alpha_mask ? kMaterialAlphaMask : 0) | (m.double_sided ? kMaterialDoubleSided : 0) |
                 (m.use_vertex_color ? kMaterialUseVertexColor : 0)));
    w.u16(0);
    w.vec3(m.diffuse_color);
    w.vec3(m.specular_color);
    w.f32(m.shininess);
    w.vec3(m.emissive_color);
    w.f32(m.ambient_intensity);
    w.f32(m.opacity);
    w.u32(m.diffuse_texture);
    w.u32(m.specular_texture);
    w.u32(m.emissive_texture);
    w.f32(m.reflection);
    w.f32(m.refraction);
    w.f32(m.ior);
    w.f32(m.alpha_cutoff);
    w.end_record(at);
  }
  void operator()(const SetMesh& s) {
    size_t at = w.begin_record(RecordType::mesh, Op::set);
    const Mesh& m = s.mesh;
    w.u32(s.id);
    w.u32(m.positions);
    w.u32(m.normals);
    w.u32(m.texcoords);
    w.u32(m.colors);
    w.u32(m.indices);
    w.u32(m.material);
    w.mat4(m.transform);
    w.u8(m.visible ? 1 : 0);
    w.u8(0), w.u8(0), w.u8(0);
    w.end_record(at);
  }
  void operator()(const SetLight& s) {
    size_t at = w.begin_record(RecordType::light, Op::set);
    const Light& l = s.light;
    w.u32(s.id);
    w.u8(uint8_t(l.type));
    w.u8(l.on ? 1 : 0);
    w.u8(l.cast_shadow ? 1 : 0);
    w.u8(0);
    w.vec3(l.color);
    w.f32(l.intensity);
    w.vec3(l.position);
    w.vec3(l.direction);
    w.vec3(l.attenuation);
    w.f32(l.cutoff);
    w.f32(l.softness);
    w.end_record(at);
  }
  void operator()(const Remove& r) {
    size_t at = w.begin_record(r.what, Op::remove);
    w.u32(r.id);
    w.end_record(at);
  }
  void operator()(const RenderRequest& r) {
    size_t at = w.begin_record(RecordType::render, Op::set);
    w.u32(r.frame);
    w.end_record(at);
  }
};

constexpr size_t kFrameFixed = wire::frame::kFixed;

void frame_fixed(Writer& w, const Frame& f) {
  w.u32(f.frame);
  w.u32(uint32_t(f.width));
  w.u32(uint32_t(f.height));
  w.u8(uint8_t(f.encoding));
  w.u8(f.refined ? (f.converged ? 2 : 1) : 0);  // 2: the still's last refinement
  w.u16(std::max<uint16_t>(1, f.samples));
  w.f32(f.timings.kernel_ms);
  w.f32(f.timings.rendering_ms);
  w.f32(f.timings.sat_ms);
  w.f32(f.timings.tiling_ms);
  w.f32(f.timings.pipeline_ms);
  w.f32(f.timings.encode_ms);
}

struct ServerEncoder {
  Writer& w;
  void operator()(const HandshakeReply& h) {
    size_t at = w.begin_record(RecordType::handshake_reply, Op::set);
    size_t n = std::min(h.server_version.size(), wire::handshake_reply::server_version_max_length);
    w.u8(uint8_t(h.renderer));
    w.u8(uint8_t(h.display));
    w.u8(h.jpeg_quality);
    w.u8(uint8_t(n));
    w.u32(h.nodes);
    w.u32(uint32_t(h.width));
    w.u32(uint32_t(h.height));
    w.u32(h.max_message_bytes);
    w.u64(h.max_buffer_bytes);
    w.bytes(h.server_version.data(), n);
    w.end_record(at);
  }
  void operator()(const Frame& f) {
    size_t at = w.begin_record(RecordType::frame, Op::set);
    frame_fixed(w, f);
    w.bytes(f.payload.data(), f.payload.size());
    w.end_record(at);
  }
  void operator()(const ErrorReply& e) {
    size_t at = w.begin_record(RecordType::error, Op::set);
    w.u16(uint16_t(e.code));
    w.u8(e.fatal ? 1 : 0);
    w.u8(0);
    w.u32(e.record);
    w.bytes(e.message.data(), std::min(e.message.size(), wire::error::message_max_length));
    w.end_record(at);
  }
  void operator()(const Reference& f) {
    size_t at = w.begin_record(RecordType::reference, Op::set);
    w.u8(uint8_t(f.what));
    w.u8(f.ok ? 1 : 0);
    w.u16(0);
    w.u32(f.id);
    w.u64(f.bytes);
    w.bytes(f.message.data(), std::min(f.message.size(), wire::reference::message_max_length));
    w.end_record(at);
  }
  void operator()(const Stats& s) {
    size_t at = w.begin_record(RecordType::stats, Op::set);
    w.u32(s.frames);
    w.u32(s.dropped);
    w.u64(s.bytes_sent);
    w.u64(s.scene_bytes);
    w.u64(s.triangles);
    w.u32(s.nodes);
    w.f32(s.fps);
    w.f32(s.mean_pipeline_ms);
    w.end_record(at);
  }
};

}  // namespace

std::vector<uint8_t> encode(const std::vector<ClientRecord>& records) {
  std::vector<uint8_t> out;
  Writer w(out);
  message_header(w, Channel::client, uint32_t(records.size()));
  for (const auto& r : records) std::visit(ClientEncoder{w}, r);
  return out;
}

std::vector<uint8_t> encode(const std::vector<ServerRecord>& records) {
  std::vector<uint8_t> out;
  Writer w(out);
  message_header(w, Channel::server, uint32_t(records.size()));
  for (const auto& r : records) std::visit(ServerEncoder{w}, r);
  return out;
}

std::vector<uint8_t> encode(const ClientRecord& record) {
  std::vector<uint8_t> out;
  Writer w(out);
  message_header(w, Channel::client, 1);
  std::visit(ClientEncoder{w}, record);
  return out;
}

std::vector<uint8_t> encode(const ServerRecord& record) {
  std::vector<uint8_t> out;
  Writer w(out);
  message_header(w, Channel::server, 1);
  std::visit(ServerEncoder{w}, record);
  return out;
}

void encode_frame_header(const Frame& f, size_t payload_size, std::vector<uint8_t>& out) {
  Writer w(out);
  message_header(w, Channel::server, 1);
  w.u8(uint8_t(RecordType::frame));
  w.u8(uint8_t(Op::set));
  w.u16(0);
  w.u32(uint32_t(kFrameFixed + payload_size));
  frame_fixed(w, f);
}

// ---------------------------------------------------------------------------------------
// Reading and validation.

namespace {

// Reads a record body; reads past the end are caught up front by the length checks, and
// as a second line of defence return zeros and clear `ok`.
class Reader {
 public:
  Reader(const uint8_t* p, size_t n) : p_(p), left_(n) {}
  template <class T>
  T get() {
    T v{};
    if (left_ < sizeof(T)) {
      ok_ = false;
      left_ = 0;
      return v;
    }
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    left_ -= sizeof(T);
    return v;
  }
  uint8_t u8() { return get<uint8_t>(); }
  uint16_t u16() { return get<uint16_t>(); }
  uint32_t u32() { return get<uint32_t>(); }
  uint64_t u64() { return get<uint64_t>(); }
  float f32() { return get<float>(); }
  Vec3 vec3() {
    float x = f32(), y = f32(), z = f32();
    return {x, y, z};
  }
  Mat4 mat4() {
    Mat4 m;
    for (float& v : m.m) v = f32();
    return m;
  }
  const uint8_t* rest() const { return p_; }
  size_t left() const { return left_; }
  bool ok() const { return ok_; }

 private:
  const uint8_t* p_;
  size_t left_;
  bool ok_ = true;
};

// Validation context for one record: builds errors that name the record.
struct Check {
  uint32_t index;
  RecordType type;
  Error err;
  bool failed = false;

  bool fail(ErrorCode c, const std::string& what) {
    if (!failed) {
      failed = true;
      err.code = c;
      err.record = index;
      err.message = std::string("record ") + std::to_string(index) + " (" + to_string(type) + "): " + what;
    }
    return false;
  }
  bool finite(float v, const char* field) {
    return std::isfinite(v) || fail(ErrorCode::not_finite, std::string(field) + " is not finite");
  }
  bool finite(const Vec3& v, const char* field) {
    return tessera::finite(v) || fail(ErrorCode::not_finite, std::string(field) + " is not finite");
  }
  bool finite(const Mat4& m, const char* field) {
    return m.finite() || fail(ErrorCode::not_finite, std::string(field) + " is not finite");
  }
  // A count or size a node caps (Limits): "<field> v exceeds the limit limit".
  bool at_most(uint64_t v, uint64_t limit, const char* field) {
    return v <= limit || fail(ErrorCode::limit_exceeded, std::string(field) + " " + std::to_string(v) +
                                                              " exceeds the limit " + std::to_string(limit));
  }
  // Finite and within the field's range (protocol/wire.toml), by the range's kind.
  bool range(float v, wire::Closed r, const char* field) {
    if (!finite(v, field)) return false;
    if (v < r.lo || v > r.hi)
      return fail(ErrorCode::out_of_range, std::string(field) + " = " + std::to_string(v) + " outside [" +
                                               std::to_string(r.lo) + ", " + std::to_string(r.hi) + "]");
    return true;
  }
  bool range(float v, wire::Open r, const char* field) {
    if (!finite(v, field)) return false;
    if (!(v > r.lo && v < r.hi))
      return fail(ErrorCode::out_of_range, std::string(field) + " = " + std::to_string(v) + " outside (" +
                                               std::to_string(r.lo) + ", " + std::to_string(r.hi) + ")");
    return true;
  }
  bool range(float v, wire::Above r, const char* field) {
    if (!finite(v, field)) return false;
    if (!(v > r.lo)) return fail(ErrorCode::out_of_range, std::string(field) + " must be > " + std::to_string(r.lo));
    return true;
  }
  bool range(uint32_t v, wire::IntRange r, const char* field, ErrorCode code = ErrorCode::out_of_range) {
    if (v < r.lo || v > r.hi)
      return fail(code, std::string(field) + " " + std::to_string(v) + " outside " + std::to_string(r.lo) + ".." +
                            std::to_string(r.hi));
    return true;
  }
  bool non_negative(const Vec3& v, const char* field) {
    if (!finite(v, field)) return false;
    if (v.x < 0 || v.y < 0 || v.z < 0) return fail(ErrorCode::out_of_range, std::string(field) + " is negative");
    return true;
  }
  bool enumeration(uint8_t v, uint8_t max, const char* field) {
    return v <= max || fail(ErrorCode::bad_enum, std::string(field) + " = " + std::to_string(v) + " (valid: 0.." +
                                                     std::to_string(max) + ")");
  }
  bool flag(uint8_t v, const char* field) { return enumeration(v, 1, field); }
  bool reserved(uint32_t v) { return v == 0 || fail(ErrorCode::bad_reserved, "reserved field is not zero"); }
  bool id(Id v, const char* field) { return v != kNoId || fail(ErrorCode::bad_id, std::string(field) + " is 0 (reserved)"); }
  bool length(size_t got, size_t want) {
    return got == want || fail(ErrorCode::bad_length, "body length " + std::to_string(got) + ", expected " +
                                                          std::to_string(want));
  }
  bool min_length(size_t got, size_t want) {
    return got >= want || fail(ErrorCode::bad_length, "body length " + std::to_string(got) + ", at least " +
                                                          std::to_string(want) + " expected");
  }
  // Width and height: at least their minimum (protocol/wire.toml), then within the limits.
  bool resolution(uint32_t w, uint32_t h, wire::IntRange wr, wire::IntRange hr, const Limits& lim) {
    if (w < wr.lo || h < hr.lo)
      return fail(ErrorCode::out_of_range, "resolution " + std::to_string(w) + "x" + std::to_string(h) + " is empty");
    if (w > uint32_t(lim.max_width) || h > uint32_t(lim.max_height))
      return fail(ErrorCode::limit_exceeded, "resolution " + std::to_string(w) + "x" + std::to_string(h) +
                                                 " exceeds the limit " + std::to_string(lim.max_width) + "x" +
                                                 std::to_string(lim.max_height));
    return true;
  }
};

// Decodes the client records of one message.
class ClientDecoder {
 public:
  ClientDecoder(const Limits& lim) : lim_(lim) {}

  // Decodes one record body into `out`; false with c.err set on failure.
  bool decode(Check& c, Op op, Reader& r, ClientRecord& out) {
    RecordType t = c.type;
    if (op == Op::remove) {
      if (!wire::removable(t))
        return c.fail(ErrorCode::bad_op, "remove is only defined for buffer, texture, material, mesh and light");
      if (!c.length(r.left(), wire::kRemoveBody)) return false;
      Remove rm;
      rm.what = t;
      rm.id = r.u32();
      if (!c.id(rm.id, "id")) return false;
      out = rm;
      return true;
    }
    switch (t) {
      case RecordType::handshake: return handshake(c, r, out);
      case RecordType::settings: {
        if (!c.length(r.left(), wire::settings::kFixed)) return false;
        Settings s;
        s.ao_samples = r.u32();
        s.max_depth = r.u32();
        if (!c.at_most(s.ao_samples, lim_.max_ao_samples, "ao_samples") ||
            !c.at_most(s.max_depth, lim_.max_depth, "max_depth"))
          return false;
        out = s;
        return true;
      }
      case RecordType::refine: {
        if (!c.length(r.left(), wire::refine::kFixed)) return false;
        Refine rf{r.u32()};
        if (!c.at_most(rf.samples, lim_.max_refine_samples, "refine samples")) return false;
        out = rf;
        return true;
      }
      case RecordType::video: {
        if (!c.length(r.left(), wire::video::kFixed)) return false;
        Video v;
        v.bitrate_kbps = r.u32();
        const uint8_t key = r.u8();
        const uint32_t reserved = uint32_t(r.u8()) | uint32_t(r.u8()) << 8 | uint32_t(r.u8()) << 16;
        if (!c.range(v.bitrate_kbps, wire::video::bitrate_kbps, "video bitrate_kbps") || !c.flag(key, "keyframe") ||
            !c.reserved(reserved))
          return false;
        if (v.bitrate_kbps != 0 && v.bitrate_kbps < kMinVideoKbps)
          return c.fail(ErrorCode::out_of_range, "video bitrate_kbps " + std::to_string(v.bitrate_kbps) + " outside " +
                                                     std::to_string(kMinVideoKbps) + ".." +
                                                     std::to_string(wire::video::bitrate_kbps.hi) + " (0: unchanged)");
        v.keyframe = key != 0;
        out = v;
        return true;
      }
      case RecordType::budget: {
        if (!c.length(r.left(), wire::budget::kFixed)) return false;
        Budget b{r.u32()};
        if (!c.at_most(b.frame_ms, lim_.max_frame_budget_ms, "budget frame_ms")) return false;
        out = b;
        return true;
      }
      case RecordType::resolution: {
        if (!c.length(r.left(), wire::resolution::kFixed)) return false;
        uint32_t w = r.u32(), h = r.u32();
        if (!c.resolution(w, h, wire::resolution::width, wire::resolution::height, lim_)) return false;
        out = Resolution{int32_t(w), int32_t(h)};
        return true;
      }
      case RecordType::camera: {
        if (!c.length(r.left(), wire::camera::kFixed)) return false;
        SetCamera s;
        s.camera.to_world = r.mat4();
        s.camera.fov_y = r.f32();
        if (!c.finite(s.camera.to_world, "to_world") || !c.range(s.camera.fov_y, wire::camera::fov_y, "fov_y"))
          return false;
        // Invertible, well-conditioned and bounded (core/validate.h): a huge or nearly
        // singular camera would give rays that Embree asserts on.
        if (std::string why = check_transform(s.camera.to_world, kCameraLimits); !why.empty())
          return c.fail(ErrorCode::out_of_range, "to_world: " + why);
        out = std::move(s);
        return true;
      }
      case RecordType::environment: {
        if (!c.length(r.left(), wire::environment::kFixed)) return false;
        SetEnvironment s;
        Environment& e = s.environment;
        e.ambient = r.vec3();
        e.background = r.vec3();
        e.exposure = r.f32();
        uint8_t linear = r.u8();
        uint32_t res = r.u8() | (r.u8() << 8) | (r.u8() << 16);
        e.linear = linear != 0;
        if (!c.non_negative(e.ambient, "ambient") || !c.non_negative(e.background, "background") ||
            !c.finite(e.exposure, "exposure") || !c.flag(linear, "linear") || !c.reserved(res))
          return false;
        if (!c.range(e.exposure, wire::environment::exposure, "exposure")) return false;
        out = std::move(s);
        return true;
      }
      case RecordType::buffer: return buffer(c, r, out);
      case RecordType::texture: return texture(c, r, out);
      case RecordType::material: return material(c, r, out);
      case RecordType::buffer_ref: return buffer_ref(c, r, out);
      case RecordType::texture_ref: return texture_ref(c, r, out);
      case RecordType::mesh: {
        if (!c.length(r.left(), wire::mesh::kFixed)) return false;
        SetMesh s;
        Mesh& m = s.mesh;
        s.id = r.u32();
        m.positions = r.u32();
        m.normals = r.u32();
        m.texcoords = r.u32();
        m.colors = r.u32();
        m.indices = r.u32();
        m.material = r.u32();
        m.transform = r.mat4();
        uint8_t visible = r.u8();
        uint32_t res = r.u8() | (r.u8() << 8) | (r.u8() << 16);
        m.visible = visible != 0;
        if (!c.id(s.id, "id") || !c.id(m.positions, "positions") || !c.finite(m.transform, "transform") ||
            !c.flag(visible, "visible") || !c.reserved(res))
          return false;
        if (std::string why = check_transform(m.transform, kMeshLimits); !why.empty())
          return c.fail(ErrorCode::out_of_range, "transform: " + why);
        out = std::move(s);
        return true;
      }
      case RecordType::light: return light(c, r, out);
      case RecordType::render: {
        if (!c.length(r.left(), wire::render::kFixed)) return false;
        out = RenderRequest{r.u32()};
        return true;
      }
      default: return c.fail(ErrorCode::unknown_record, "not a client record");
    }
  }

 private:
  bool handshake(Check& c, Reader& r, ClientRecord& out) {
    if (!c.length(r.left(), wire::handshake::kFixed)) return false;
    Handshake h;
    uint8_t renderer = r.u8(), display = r.u8();
    h.jpeg_quality = r.u8();
    uint8_t res = r.u8();
    h.max_nodes = r.u32();
    uint32_t w = r.u32(), hh = r.u32();
    if (!c.enumeration(renderer, wire::enum_max::renderer, "renderer") ||
        !c.enumeration(display, wire::enum_max::display, "display") || !c.reserved(res))
      return false;
    h.renderer = RendererKind(renderer);
    h.display = DisplayKind(display);
    if (!c.range(h.jpeg_quality, wire::handshake::jpeg_quality, "jpeg_quality")) return false;
    if (h.max_nodes > lim_.max_nodes)
      return c.fail(ErrorCode::limit_exceeded, "max_nodes " + std::to_string(h.max_nodes) + " exceeds the limit " +
                                                   std::to_string(lim_.max_nodes));
    if (!c.resolution(w, hh, wire::handshake::width, wire::handshake::height, lim_)) return false;
    h.width = int32_t(w);
    h.height = int32_t(hh);
    out = h;
    return true;
  }

  // Counts decoded bytes against the per-message payload limit.
  bool charge(Check& c, uint64_t bytes) {
    if (bytes > lim_.max_message_payload_bytes - payload_)
      return c.fail(ErrorCode::limit_exceeded, "buffers and textures in this message exceed the limit of " +
                                                   std::to_string(lim_.max_message_payload_bytes) + " bytes");
    payload_ += bytes;
    return true;
  }

  bool buffer(Check& c, Reader& r, ClientRecord& out) {
    const size_t body = r.left();
    if (!c.min_length(body, wire::buffer::kFixed)) return false;
    SetBuffer s;
    s.id = r.u32();
    uint8_t type = r.u8(), comps = r.u8(), flags = r.u8(), res = r.u8();
    uint32_t values = r.u32();
    if (!c.id(s.id, "id") || !c.enumeration(type, wire::enum_max::buffer_type, "type") || !c.reserved(res)) return false;
    if (flags & ~kBufferDeflate) return c.fail(ErrorCode::bad_reserved, "unknown buffer flags");
    if (!c.range(comps, wire::buffer::components, "components", ErrorCode::bad_components)) return false;
    if (values % comps)
      return c.fail(ErrorCode::bad_components, std::to_string(values) + " values are not a multiple of " +
                                                   std::to_string(comps) + " components");
    uint64_t bytes = uint64_t(values) * 4;
    if (bytes > lim_.max_buffer_bytes)
      return c.fail(ErrorCode::limit_exceeded, "buffer of " + std::to_string(bytes) + " bytes exceeds the limit of " +
                                                   std::to_string(lim_.max_buffer_bytes));
    if (values / comps > lim_.max_vertices)
      return c.fail(ErrorCode::limit_exceeded, std::to_string(values / comps) + " elements exceed the limit of " +
                                                   std::to_string(lim_.max_vertices));
    s.deflate = flags & kBufferDeflate;
    if (!s.deflate && !c.length(body, wire::buffer::kFixed + bytes)) return false;
    if (!charge(c, bytes)) return false;
    s.buffer.type = Buffer::Type(type);
    s.buffer.components = comps;
    // Sizes are checked: now allocate exactly the declared size.
    uint8_t* dst;
    if (s.buffer.type == Buffer::Type::f32) {
      s.buffer.f.resize(values);
      dst = reinterpret_cast<uint8_t*>(s.buffer.f.data());
    } else {
      s.buffer.u.resize(values);
      dst = reinterpret_cast<uint8_t*>(s.buffer.u.data());
    }
    if (s.deflate) {
      std::string err;
      if (!inflate_zlib_exact(r.rest(), r.left(), dst, size_t(bytes), err)) return c.fail(ErrorCode::bad_payload, err);
    } else if (bytes) {
      std::memcpy(dst, r.rest(), size_t(bytes));
    }
    out = std::move(s);
    return true;
  }

  bool texture(Check& c, Reader& r, ClientRecord& out) {
    const size_t body = r.left();
    if (!c.min_length(body, wire::texture::kFixed)) return false;
    SetTexture s;
    s.id = r.u32();
    uint8_t format = r.u8(), wrap_s = r.u8(), wrap_t = r.u8(), filter = r.u8(), srgb = r.u8();
    uint32_t res = r.u8() | (r.u8() << 8) | (r.u8() << 16);
    uint32_t w = r.u32(), h = r.u32();
    if (!c.id(s.id, "id") || !c.enumeration(format, wire::enum_max::texture_format, "format") ||
        !c.enumeration(wrap_s, wire::enum_max::wrap, "wrap_s") || !c.enumeration(wrap_t, wire::enum_max::wrap, "wrap_t") ||
        !c.enumeration(filter, wire::enum_max::filter, "filter") || !c.flag(srgb, "srgb") ||
        !c.reserved(res))
      return false;
    if (w < wire::texture::width.lo || h < wire::texture::height.lo)
      return c.fail(ErrorCode::out_of_range, "texture size " + std::to_string(w) + "x" +
                                                                     std::to_string(h) + " is empty");
    if (w > uint32_t(lim_.max_texture_size) || h > uint32_t(lim_.max_texture_size))
      return c.fail(ErrorCode::limit_exceeded, "texture size " + std::to_string(w) + "x" + std::to_string(h) +
                                                   " exceeds the limit " + std::to_string(lim_.max_texture_size));
    uint64_t bytes = uint64_t(w) * h * 4;
    s.format = TextureFormat(format);
    if (s.format == TextureFormat::rgba8 && !c.length(body, wire::texture::kFixed + bytes)) return false;
    if (!charge(c, bytes)) return false;
    Texture& t = s.texture;
    t.sampler.wrap_s = Sampler::Wrap(wrap_s);
    t.sampler.wrap_t = Sampler::Wrap(wrap_t);
    t.sampler.filter = Sampler::Filter(filter);
    t.srgb = srgb != 0;
    std::string dims = std::to_string(w) + "x" + std::to_string(h);
    if (s.format == TextureFormat::rgba8) {
      t.width = int32_t(w);
      t.height = int32_t(h);
      t.rgba.assign(r.rest(), r.rest() + bytes);
    } else {
      // Read the encoded image's own size before decoding, so the decoder allocates no more
      // than the declared (and limited) size.
      uint32_t ew = 0, eh = 0;
      std::string err;
      if (s.format == TextureFormat::png) {
        if (!png_dimensions(r.rest(), r.left(), ew, eh)) return c.fail(ErrorCode::bad_texture, "not a PNG file");
      } else {
        int jw = 0, jh = 0;
        if (!jpeg_dimensions(r.rest(), r.left(), jw, jh, err)) return c.fail(ErrorCode::bad_texture, err);
        ew = uint32_t(jw);
        eh = uint32_t(jh);
      }
      if (ew != w || eh != h)
        return c.fail(ErrorCode::bad_texture, "encoded image is " + std::to_string(ew) + "x" + std::to_string(eh) +
                                                  ", declared " + dims);
      Image img;
      bool ok = s.format == TextureFormat::png ? decode_image(r.rest(), r.left(), img, err)
                                               : jpeg_decode(r.rest(), r.left(), img, err);
      if (!ok) return c.fail(ErrorCode::bad_texture, err.empty() ? "image does not decode" : err);
      if (img.width != int32_t(w) || img.height != int32_t(h) || img.rgba.size() != bytes)
        return c.fail(ErrorCode::bad_texture, "decoded image does not match the declared " + dims);
      t.width = img.width;
      t.height = img.height;
      t.rgba = std::move(img.rgba);
    }
    out = std::move(s);
    return true;
  }

  // A reference's URL: the rest of the body, 1..4096 bytes (what it may name is the node's
  // business: update/asset_store.h).
  static bool url(Check& c, Reader& r, size_t max_length, std::string& out) {
    if (r.left() == 0 || r.left() > max_length)
      return c.fail(ErrorCode::bad_length, "url of " + std::to_string(r.left()) + " bytes (1.." +
                                               std::to_string(max_length) + ")");
    out.assign(reinterpret_cast<const char*>(r.rest()), r.left());
    return true;
  }

  bool buffer_ref(Check& c, Reader& r, ClientRecord& out) {
    if (!c.min_length(r.left(), wire::buffer_ref::kFixed)) return false;
    SetBufferRef s;
    s.id = r.u32();
    uint8_t type = r.u8(), comps = r.u8(), source = r.u8(), res = r.u8();
    s.value_count = r.u32();
    s.byte_stride = r.u32();
    s.byte_offset = r.u64();
    if (!c.id(s.id, "id") || !c.enumeration(type, wire::enum_max::buffer_type, "type") ||
        !c.enumeration(source, wire::enum_max::source_type, "source") || !c.reserved(res))
      return false;
    if (!c.range(comps, wire::buffer_ref::components, "components", ErrorCode::bad_components)) return false;
    s.type = Buffer::Type(type);
    s.components = comps;
    s.source = SourceType(source);
    if ((s.type == Buffer::Type::f32) != (s.source == SourceType::f32))
      return c.fail(ErrorCode::bad_enum, std::string("source ") + (s.source == SourceType::f32 ? "f32" : "integer") +
                                             " does not fit a buffer of type " + (type ? "u32" : "f32"));
    if (s.value_count % comps)
      return c.fail(ErrorCode::bad_components, std::to_string(s.value_count) + " values are not a multiple of " +
                                                   std::to_string(comps) + " components");
    const uint64_t bytes = uint64_t(s.value_count) * 4;
    if (bytes > lim_.max_buffer_bytes)
      return c.fail(ErrorCode::limit_exceeded, "buffer of " + std::to_string(bytes) + " bytes exceeds the limit of " +
                                                   std::to_string(lim_.max_buffer_bytes));
    if (s.value_count / comps > lim_.max_vertices)
      return c.fail(ErrorCode::limit_exceeded, std::to_string(s.value_count / comps) + " elements exceed the limit of " +
                                                   std::to_string(lim_.max_vertices));
    if (!c.range(s.byte_stride, wire::buffer_ref::byte_stride, "byte_stride")) return false;
    const uint32_t size = source_size(s.source);
    if (s.byte_stride && (s.byte_stride < comps * size || s.byte_stride % size))
      return c.fail(ErrorCode::out_of_range, "byte_stride " + std::to_string(s.byte_stride) + " does not hold " +
                                                 std::to_string(comps) + " values of " + std::to_string(size) +
                                                 " bytes, or is not a multiple of " + std::to_string(size));
    if (!url(c, r, wire::buffer_ref::url_max_length, s.url)) return false;
    out = std::move(s);
    return true;
  }

  bool texture_ref(Check& c, Reader& r, ClientRecord& out) {
    if (!c.min_length(r.left(), wire::texture_ref::kFixed)) return false;
    SetTextureRef s;
    s.id = r.u32();
    uint8_t wrap_s = r.u8(), wrap_t = r.u8(), filter = r.u8(), srgb = r.u8();
    if (!c.id(s.id, "id") || !c.enumeration(wrap_s, wire::enum_max::wrap, "wrap_s") ||
        !c.enumeration(wrap_t, wire::enum_max::wrap, "wrap_t") || !c.enumeration(filter, wire::enum_max::filter, "filter") ||
        !c.flag(srgb, "srgb"))
      return false;
    s.sampler.wrap_s = Sampler::Wrap(wrap_s);
    s.sampler.wrap_t = Sampler::Wrap(wrap_t);
    s.sampler.filter = Sampler::Filter(filter);
    s.srgb = srgb != 0;
    if (!url(c, r, wire::texture_ref::url_max_length, s.url)) return false;
    out = std::move(s);
    return true;
  }

  bool material(Check& c, Reader& r, ClientRecord& out) {
    if (!c.length(r.left(), wire::material::kFixed)) return false;
    SetMaterial s;
    Material& m = s.material;
    s.id = r.u32();
    uint8_t model = r.u8(), flags = r.u8();
    uint16_t res = r.u16();
    m.diffuse_color = r.vec3();
    m.specular_color = r.vec3();
    m.shininess = r.f32();
    m.emissive_color = r.vec3();
    m.ambient_intensity = r.f32();
    m.opacity = r.f32();
    m.diffuse_texture = r.u32();
    m.specular_texture = r.u32();
    m.emissive_texture = r.u32();
    m.reflection = r.f32();
    m.refraction = r.f32();
    m.ior = r.f32();
    m.alpha_cutoff = r.f32();
    if (!c.id(s.id, "id") || !c.enumeration(model, wire::enum_max::material_model, "model") || !c.reserved(res)) return false;
    if (flags & ~(kMaterialAlphaMask | kMaterialDoubleSided | kMaterialUseVertexColor))
      return c.fail(ErrorCode::bad_reserved, "unknown material flags");
    m.model = Material::Model(model);
    m.alpha_mask = flags & kMaterialAlphaMask;
    m.double_sided = flags & kMaterialDoubleSided;
    m.use_vertex_color = flags & kMaterialUseVertexColor;
    if (!c.non_negative(m.diffuse_color, "diffuse_color") || !c.non_negative(m.specular_color, "specular_color") ||
        !c.range(m.shininess, wire::material::shininess, "shininess") ||
        !c.non_negative(m.emissive_color, "emissive_color") ||
        !c.range(m.ambient_intensity, wire::material::ambient_intensity, "ambient_intensity") ||
        !c.range(m.opacity, wire::material::opacity, "opacity") ||
        !c.range(m.reflection, wire::material::reflection, "reflection") ||
        !c.range(m.refraction, wire::material::refraction, "refraction") || !c.range(m.ior, wire::material::ior, "ior") ||
        !c.range(m.alpha_cutoff, wire::material::alpha_cutoff, "alpha_cutoff"))
      return false;
    out = std::move(s);
    return true;
  }

  bool light(Check& c, Reader& r, ClientRecord& out) {
    if (!c.length(r.left(), wire::light::kFixed)) return false;
    SetLight s;
    Light& l = s.light;
    s.id = r.u32();
    uint8_t type = r.u8(), on = r.u8(), cast_shadow = r.u8(), res = r.u8();
    l.color = r.vec3();
    l.intensity = r.f32();
    l.position = r.vec3();
    l.direction = r.vec3();
    l.attenuation = r.vec3();
    l.cutoff = r.f32();
    l.softness = r.f32();
    if (!c.id(s.id, "id") || !c.enumeration(type, wire::enum_max::light_type, "type") || !c.flag(on, "on") ||
        !c.flag(cast_shadow, "cast_shadow") || !c.reserved(res))
      return false;
    l.type = Light::Type(type);
    l.on = on != 0;
    l.cast_shadow = cast_shadow != 0;
    if (!c.non_negative(l.color, "color") || !c.range(l.intensity, wire::light::intensity, "intensity") ||
        !c.finite(l.position, "position") || !c.finite(l.direction, "direction") ||
        !c.non_negative(l.attenuation, "attenuation") || !c.range(l.cutoff, wire::light::cutoff, "cutoff") ||
        !c.range(l.softness, wire::light::softness, "softness"))
      return false;
    if (l.type != Light::Type::point && dot(l.direction, l.direction) == 0)
      return c.fail(ErrorCode::out_of_range, "direction is zero");
    // Shadow rays aim at point and spot lights and along the others' directions (core/validate.h).
    if (l.type != Light::Type::directional)
      if (std::string why = check_point(l.position); !why.empty()) return c.fail(ErrorCode::out_of_range, "position " + why);
    if (l.type != Light::Type::point)
      if (std::string why = check_direction(l.direction); !why.empty())
        return c.fail(ErrorCode::out_of_range, "direction " + why);
    if (l.type != Light::Type::directional && l.attenuation == Vec3(0, 0, 0))
      return c.fail(ErrorCode::out_of_range, "attenuation is all zero");
    if (l.type == Light::Type::spot && l.cutoff == 0) return c.fail(ErrorCode::out_of_range, "cutoff is zero");
    out = std::move(s);
    return true;
  }

  const Limits& lim_;
  uint64_t payload_ = 0;
};

bool server_record(Check& c, Reader& r, const Limits& lim, ServerRecord& out) {
  switch (c.type) {
    case RecordType::handshake_reply: {
      const size_t body = r.left();
      if (!c.min_length(body, wire::handshake_reply::kFixed)) return false;
      HandshakeReply h;
      uint8_t renderer = r.u8(), display = r.u8();
      h.jpeg_quality = r.u8();
      uint8_t n = r.u8();
      h.nodes = r.u32();
      uint32_t w = r.u32(), hh = r.u32();
      h.max_message_bytes = r.u32();
      h.max_buffer_bytes = r.u64();
      if (!c.length(body, wire::handshake_reply::kFixed + size_t(n))) return false;
      h.server_version.assign(reinterpret_cast<const char*>(r.rest()), n);
      if (!c.enumeration(renderer, wire::enum_max::renderer, "renderer") ||
          !c.enumeration(display, wire::enum_max::display, "display"))
        return false;
      h.renderer = RendererKind(renderer);
      h.display = DisplayKind(display);
      if (!c.range(h.jpeg_quality, wire::handshake_reply::jpeg_quality, "jpeg_quality")) return false;
      if (!c.resolution(w, hh, wire::handshake_reply::width, wire::handshake_reply::height, lim)) return false;
      h.width = int32_t(w);
      h.height = int32_t(hh);
      out = std::move(h);
      return true;
    }
    case RecordType::frame: {
      const size_t body = r.left();
      if (!c.min_length(body, kFrameFixed)) return false;
      Frame f;
      f.frame = r.u32();
      uint32_t w = r.u32(), h = r.u32();
      uint8_t enc = r.u8(), refined = r.u8();
      f.samples = r.u16();
      FrameTimings& t = f.timings;
      t.kernel_ms = r.f32();
      t.rendering_ms = r.f32();
      t.sat_ms = r.f32();
      t.tiling_ms = r.f32();
      t.pipeline_ms = r.f32();
      t.encode_ms = r.f32();
      if (!c.enumeration(enc, wire::enum_max::frame_encoding, "encoding") || !c.enumeration(refined, wire::enum_max::refinement, "refined") ||
          !c.resolution(w, h, wire::frame::width, wire::frame::height, lim))
        return false;
      f.encoding = FrameEncoding(enc);
      f.refined = refined != 0;
      f.converged = refined == 2;
      f.width = int32_t(w);
      f.height = int32_t(h);
      if (f.encoding == FrameEncoding::dxt1 &&
          !c.length(body, kFrameFixed + size_t((w + 3) / 4) * size_t((h + 3) / 4) * 8))
        return false;
      f.payload.assign(r.rest(), r.rest() + r.left());
      out = std::move(f);
      return true;
    }
    case RecordType::error: {
      if (!c.min_length(r.left(), wire::error::kFixed)) return false;
      ErrorReply e;
      uint16_t code = r.u16();
      uint8_t fatal = r.u8(), res = r.u8();
      e.record = r.u32();
      if (code > kMaxErrorCode) return c.fail(ErrorCode::bad_enum, "error code " + std::to_string(code));
      if (!c.flag(fatal, "fatal") || !c.reserved(res)) return false;
      e.code = ErrorCode(code);
      e.fatal = fatal != 0;
      e.message.assign(reinterpret_cast<const char*>(r.rest()), r.left());
      out = std::move(e);
      return true;
    }
    case RecordType::reference: {
      if (!c.min_length(r.left(), wire::reference::kFixed)) return false;
      Reference f;
      uint8_t what = r.u8(), ok = r.u8();
      uint16_t res = r.u16();
      f.id = r.u32();
      f.bytes = r.u64();
      if (!c.enumeration(what, wire::enum_max::ref_kind, "what") || !c.flag(ok, "ok") || !c.reserved(res) ||
          !c.id(f.id, "id"))
        return false;
      f.what = RefKind(what);
      f.ok = ok != 0;
      f.message.assign(reinterpret_cast<const char*>(r.rest()), r.left());
      out = std::move(f);
      return true;
    }
    case RecordType::stats: {
      if (!c.length(r.left(), wire::stats::kFixed)) return false;
      Stats s;
      s.frames = r.u32();
      s.dropped = r.u32();
      s.bytes_sent = r.u64();
      s.scene_bytes = r.u64();
      s.triangles = r.u64();
      s.nodes = r.u32();
      s.fps = r.f32();
      s.mean_pipeline_ms = r.f32();
      out = s;
      return true;
    }
    default: return c.fail(ErrorCode::unknown_record, "not a server record");
  }
}

Error message_error(ErrorCode c, std::string m, uint32_t record = kNoRecord) {
  Error e;
  e.code = c;
  e.message = std::move(m);
  e.record = record;
  return e;
}

// Walks the framing of a message and calls `each(check, op, reader)` per record.
template <class Each>
Result<Ok> walk(const uint8_t* data, size_t size, const Limits& lim, Channel ch, Each&& each) {
  if (size > lim.max_message_bytes)
    return message_error(ErrorCode::too_large, "message of " + std::to_string(size) + " bytes exceeds the limit of " +
                                                   std::to_string(lim.max_message_bytes));
  if (size < kMessageHeaderSize)
    return message_error(ErrorCode::truncated, "message of " + std::to_string(size) + " bytes is shorter than its " +
                                                   std::to_string(kMessageHeaderSize) + "-byte header");
  if (data[0] != kMagic0 || data[1] != kMagic1) return message_error(ErrorCode::bad_magic, "message does not start with \"TS\"");
  if (data[2] != kVersion)
    return message_error(ErrorCode::bad_version, "protocol version " + std::to_string(data[2]) + " not supported (server speaks " +
                                                     std::to_string(kVersion) + ")");
  if (data[3] != uint8_t(ch))
    return message_error(ErrorCode::bad_channel, std::string("expected a ") + (ch == Channel::client ? "client" : "server") +
                                                     " message, channel byte is " + std::to_string(data[3]));
  uint32_t count;
  std::memcpy(&count, data + 4, 4);
  if (count == 0) return message_error(ErrorCode::bad_length, "message holds no records");
  if (count > lim.max_records)
    return message_error(ErrorCode::too_large, std::to_string(count) + " records exceed the limit of " +
                                                   std::to_string(lim.max_records));
  // Each record needs at least its header: reject impossible counts before reserving.
  if (count > (size - kMessageHeaderSize) / kRecordHeaderSize)
    return message_error(ErrorCode::truncated, std::to_string(count) + " records cannot fit in " + std::to_string(size) +
                                                   " bytes");
  size_t at = kMessageHeaderSize;
  for (uint32_t i = 0; i < count; ++i) {
    if (size - at < kRecordHeaderSize)
      return message_error(ErrorCode::truncated, "record " + std::to_string(i) + ": header truncated", i);
    uint8_t type = data[at], op = data[at + 1];
    uint16_t res;
    uint32_t len;
    std::memcpy(&res, data + at + 2, 2);
    std::memcpy(&len, data + at + 4, 4);
    at += kRecordHeaderSize;
    if (len > size - at)
      return message_error(ErrorCode::truncated, "record " + std::to_string(i) + ": body of " + std::to_string(len) +
                                                     " bytes, only " + std::to_string(size - at) + " left", i);
    if (!wire::known_record(type, ch))
      return message_error(ErrorCode::unknown_record, "record " + std::to_string(i) + ": unknown record type " +
                                                          std::to_string(type), i);
    if (op > uint8_t(Op::remove))
      return message_error(ErrorCode::bad_op, "record " + std::to_string(i) + ": unknown op " + std::to_string(op), i);
    if (ch == Channel::server && op != uint8_t(Op::set))
      return message_error(ErrorCode::bad_op, "record " + std::to_string(i) + ": server records have op 0", i);
    if (res != 0)
      return message_error(ErrorCode::bad_reserved, "record " + std::to_string(i) + ": reserved header field is not zero", i);
    Check c{i, RecordType(type), {}};
    Reader r(data + at, len);
    if (!each(c, Op(op), r)) return c.err;
    at += len;
  }
  if (at != size)
    return message_error(ErrorCode::bad_length, std::to_string(size - at) + " bytes after the last record");
  return Ok{};
}

}  // namespace

Result<std::vector<ClientRecord>> decode_client(const uint8_t* data, size_t size, const Limits& limits) {
  std::vector<ClientRecord> out;
  ClientDecoder dec(limits);
  bool handshake = false;
  size_t count = 0;
  auto st = walk(data, size, limits, Channel::client, [&](Check& c, Op op, Reader& r) {
    ++count;
    if (c.type == RecordType::handshake) handshake = true;
    ClientRecord rec;
    if (!dec.decode(c, op, r, rec)) return false;
    out.push_back(std::move(rec));
    return true;
  });
  if (!st) return st.error();
  if (handshake && count != 1)
    return message_error(ErrorCode::bad_handshake, "a handshake must be the only record in its message");
  return out;
}

Result<std::vector<ServerRecord>> decode_server(const uint8_t* data, size_t size, const Limits& limits) {
  std::vector<ServerRecord> out;
  auto st = walk(data, size, limits, Channel::server, [&](Check& c, Op, Reader& r) {
    ServerRecord rec;
    if (!server_record(c, r, limits, rec)) return false;
    out.push_back(std::move(rec));
    return true;
  });
  if (!st) return st.error();
  return out;
}

Status check_session_order(bool handshake_done, const std::vector<ClientRecord>& records) {
  bool has = !records.empty() && std::holds_alternative<Handshake>(records.front());
  if (!handshake_done && !has)
    return message_error(ErrorCode::bad_handshake, "the first message must be a handshake", 0);
  if (handshake_done && has) return message_error(ErrorCode::bad_handshake, "handshake repeated", 0);
  return Ok{};
}

}  // namespace tessera::protocol
