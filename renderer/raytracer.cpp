#include "renderer/raytracer.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range2d.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <x86intrin.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <stdexcept>
#include <thread>
#include <tuple>

namespace tessera {

// ---------------------------------------------------------------------------------------
// CPU facts
// ---------------------------------------------------------------------------------------

PacketLayout detect_packet_layout() {
  if (const char* env = std::getenv("TESSERA_PACKET")) {  // "4x4", "4x2" or "2x2"
    if (!std::strcmp(env, "4x4")) return {4, 4};
    if (!std::strcmp(env, "4x2")) return {4, 2};
    if (!std::strcmp(env, "2x2")) return {2, 2};
  }
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f")) return {4, 4};
  if (__builtin_cpu_supports("avx2")) return {4, 2};
  return {2, 2};
}

const char* isa_name(PacketLayout p) {
  switch (p.size()) {
    case 16: return "AVX-512 (ray16)";
    case 8: return "AVX2 (ray8)";
    default: return "SSE (ray4)";
  }
}

double tsc_khz() {
  static const double khz = [] {
    std::ifstream f("/sys/devices/system/cpu/cpu0/tsc_freq_khz");
    double v = 0;
    if (f >> v && v > 0) return v;
    // Calibrate against the steady clock over 50 ms.
    auto t0 = std::chrono::steady_clock::now();
    uint64_t c0 = __rdtsc();
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    uint64_t c1 = __rdtsc();
    double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return double(c1 - c0) / ms;  // ticks per ms = kHz
  }();
  return khz;
}

namespace {

// ---------------------------------------------------------------------------------------
// Embree packet types by width
// ---------------------------------------------------------------------------------------

template <int N> struct Packet;
template <> struct Packet<4> {
  using RayHit = RTCRayHit4;
  using Ray = RTCRay4;
  static void intersect(const int* v, RTCScene s, RTCIntersectContext* c, RayHit* r) { rtcIntersect4(v, s, c, r); }
  static void occluded(const int* v, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded4(v, s, c, r); }
};
template <> struct Packet<8> {
  using RayHit = RTCRayHit8;
  using Ray = RTCRay8;
  static void intersect(const int* v, RTCScene s, RTCIntersectContext* c, RayHit* r) { rtcIntersect8(v, s, c, r); }
  static void occluded(const int* v, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded8(v, s, c, r); }
};
template <> struct Packet<16> {
  using RayHit = RTCRayHit16;
  using Ray = RTCRay16;
  static void intersect(const int* v, RTCScene s, RTCIntersectContext* c, RayHit* r) { rtcIntersect16(v, s, c, r); }
  static void occluded(const int* v, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded16(v, s, c, r); }
};

// Compile-time features of a kernel: the general kernel has all, the specialised none.
enum Feature : unsigned { kAO = 1, kSecondary = 2, kTextures = 4, kAll = 7, kNone = 0 };

// ---------------------------------------------------------------------------------------
// Colour helpers
// ---------------------------------------------------------------------------------------

struct SrgbLut {
  std::array<float, 256> to_linear;
  SrgbLut() {
    for (int i = 0; i < 256; ++i) {
      float c = i / 255.0f;
      to_linear[i] = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
  }
};
const SrgbLut& srgb_lut() {
  static const SrgbLut lut;
  return lut;
}

// Linear [0, 1] to sRGB bytes through a 4096-entry table (max error under half a step).
struct SrgbEncodeLut {
  std::array<uint8_t, 4097> table;
  SrgbEncodeLut() {
    for (int i = 0; i <= 4096; ++i) {
      float c = i / 4096.0f;
      float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
      table[i] = uint8_t(s * 255.0f + 0.5f);
    }
  }
};
const SrgbEncodeLut& srgb_encode_lut() {
  static const SrgbEncodeLut lut;
  return lut;
}
inline uint8_t encode_srgb(float c, const SrgbEncodeLut& lut) {
  c = c > 0.0f ? (c < 1.0f ? c : 1.0f) : 0.0f;  // also maps NaN to 0
  return lut.table[int(c * 4096.0f + 0.5f)];
}
inline uint8_t encode_linear(float c) { return uint8_t(std::fmin(std::fmax(c, 0.0f), 1.0f) * 255.0f + 0.5f); }

inline float smoothstep(float e0, float e1, float x) {
  if (e1 <= e0) return x >= e0 ? 1.0f : 0.0f;
  float t = std::fmin(std::fmax((x - e0) / (e1 - e0), 0.0f), 1.0f);
  return t * t * (3 - 2 * t);
}

// Integer hash for per-pixel sample rotations (deterministic per frame).
inline uint32_t hash32(uint32_t x) {
  x ^= x >> 16; x *= 0x7feb352dU; x ^= x >> 15; x *= 0x846ca68bU; x ^= x >> 16;
  return x;
}
inline float radical_inverse2(uint32_t i) {  // van der Corput sequence in base 2
  i = (i << 16) | (i >> 16);
  i = ((i & 0x55555555u) << 1) | ((i & 0xAAAAAAAAu) >> 1);
  i = ((i & 0x33333333u) << 2) | ((i & 0xCCCCCCCCu) >> 2);
  i = ((i & 0x0F0F0F0Fu) << 4) | ((i & 0xF0F0F0F0u) >> 4);
  i = ((i & 0x00FF00FFu) << 8) | ((i & 0xFF00FF00u) >> 8);
  return float(i) * 2.3283064365386963e-10f;
}

// Orthonormal basis around n (Duff et al. 2017).
inline void basis(const Vec3& n, Vec3& t, Vec3& b) {
  float s = std::copysign(1.0f, n.z);
  float a = -1.0f / (s + n.z);
  float c = n.x * n.y * a;
  t = {1 + s * n.x * n.x * a, s * c, -s * n.x};
  b = {c, s + n.y * n.y * a, -n.y};
}

inline float max_abs(const Vec3& p) { return std::fmax(std::fabs(p.x), std::fmax(std::fabs(p.y), std::fabs(p.z))); }

}  // namespace

// ---------------------------------------------------------------------------------------
// Renderer state
// ---------------------------------------------------------------------------------------

struct RayTracer::Impl {
  struct Tex {
    int32_t w = 0, h = 0;
    std::vector<uint8_t> rgba;
    Sampler sampler;
    bool srgb = true;
    uint64_t version = 0;
  };
  struct Geom {
    Impl* owner = nullptr;
    RTCScene blas = nullptr;
    std::vector<float> normals;    // object space, 3 per vertex (empty: flat)
    std::vector<float> texcoords;  // 2 per vertex (empty: none)
    std::vector<uint32_t> indices; // 3 per triangle
    uint64_t version = 0;          // max version of the buffers it was built from
    bool filter = false;           // alpha-mask filter attached
    bool see_through = false;      // occlusion filter for refracting materials attached
    bool used = false;
  };
  struct Inst {
    Id mesh = kNoId;
    RTCGeometry geom = nullptr;
    unsigned id = RTC_INVALID_GEOMETRY_ID;
    Geom* g = nullptr;
    int material = 0;      // index into materials_
    Mat4 normal_matrix;    // inverse transpose of the object-to-world transform
    float det_sign = 1;
    uint64_t version = 0;
    uint64_t geom_version = 0;
    Vec3 origin_used;      // the rebasing origin its transform was built for
  };
  using GeomKey = std::tuple<Id, Id, Id, Id>;  // positions, normals, texcoords, indices

  RTCDevice device = nullptr;
  RTCScene top = nullptr;
  PacketLayout layout;
  std::map<GeomKey, Geom> geoms;
  std::map<Id, Inst> insts;         // by mesh id
  std::vector<Inst*> inst_by_rtc;   // by Embree instance id
  std::map<Id, Tex> textures;
  std::vector<Material> materials;  // [0] = the default material
  std::vector<const Tex*> mat_diffuse_tex, mat_specular_tex, mat_emissive_tex;
  std::map<Id, int> material_index;
  std::vector<Light> lights;
  Camera camera;
  Environment env;
  int32_t width = 0, height = 0;
  Vec3 origin;  // world position subtracted from everything (camera-relative rebasing)
  float extent = 1;
  SceneFeatures features;
  SyncStats stats;
  bool committed = false;

  static void on_error(void*, RTCError code, const char* str) {
    std::fprintf(stderr, "embree error %d: %s\n", int(code), str ? str : "");
  }

  explicit Impl(PacketLayout l) : layout(l) {
    device = rtcNewDevice(nullptr);
    if (!device) throw std::runtime_error("cannot create the Embree device");
    rtcSetDeviceErrorFunction(device, on_error, nullptr);
    top = rtcNewScene(device);
    rtcSetSceneFlags(top, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(top, RTC_BUILD_QUALITY_LOW);
    materials.push_back(default_material());
  }
  ~Impl() {
    for (auto& [id, inst] : insts) rtcReleaseGeometry(inst.geom);
    for (auto& [k, g] : geoms) rtcReleaseScene(g.blas);
    rtcReleaseScene(top);
    rtcReleaseDevice(device);
  }

  static Material default_material() {  // XML3D: matte red
    Material m;
    m.model = Material::Model::matte;
    m.diffuse_color = {1, 0, 0};
    return m;
  }

  void sync(const Scene& scene, std::vector<std::string>& warnings);
  void build_geom(const Scene& scene, const GeomKey& key, Geom& g);
  // How a non-default schedule spreads the packets (render_scheduled); nullptr = work stealing.
  struct SchedulePlan {
    ThreadSchedule schedule;
    const std::vector<Rect>* tiles;
    int threads;
  };
  template <int N, unsigned F>
  void render_task(const Rect& pixels, const RenderSettings& s, TaskResult& out, const SchedulePlan* plan = nullptr);
  template <int N>
  double trace_primary(const Rect& pixels, uint64_t* rays);
};

// ---------------------------------------------------------------------------------------
// Alpha masks: an Embree filter function rejects hits where the mask is transparent.
// ---------------------------------------------------------------------------------------
namespace {
}  // namespace

template <class Tex>
static inline void sample_texture(const Tex& t, float u, float v, bool linear, float out[4]) {
  auto wrap = [](float c, Sampler::Wrap w) {
    if (w == Sampler::Wrap::repeat) return c - std::floor(c);
    return std::fmin(std::fmax(c, 0.0f), 1.0f);
  };
  if (!std::isfinite(u)) u = 0;
  if (!std::isfinite(v)) v = 0;
  u = wrap(u, t.sampler.wrap_s);
  v = wrap(v, t.sampler.wrap_t);
  const auto& lut = srgb_lut().to_linear;
  auto texel = [&](int x, int y, float w, float acc[4]) {
    if (t.sampler.wrap_s == Sampler::Wrap::repeat) x = ((x % t.w) + t.w) % t.w;
    else x = std::min(std::max(x, 0), t.w - 1);
    if (t.sampler.wrap_t == Sampler::Wrap::repeat) y = ((y % t.h) + t.h) % t.h;
    else y = std::min(std::max(y, 0), t.h - 1);
    const uint8_t* p = &t.rgba[(size_t(y) * t.w + x) * 4];
    if (linear && t.srgb) {
      acc[0] += w * lut[p[0]]; acc[1] += w * lut[p[1]]; acc[2] += w * lut[p[2]];
    } else {
      acc[0] += w * p[0] * (1 / 255.0f); acc[1] += w * p[1] * (1 / 255.0f); acc[2] += w * p[2] * (1 / 255.0f);
    }
    acc[3] += w * p[3] * (1 / 255.0f);
  };
  out[0] = out[1] = out[2] = out[3] = 0;
  float x = u * t.w - 0.5f, y = v * t.h - 0.5f;
  if (t.sampler.filter == Sampler::Filter::nearest) {
    texel(int(std::floor(x + 0.5f)), int(std::floor(y + 0.5f)), 1.0f, out);
    return;
  }
  int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  float fx = x - x0, fy = y - y0;
  texel(x0, y0, (1 - fx) * (1 - fy), out);
  texel(x0 + 1, y0, fx * (1 - fy), out);
  texel(x0, y0 + 1, (1 - fx) * fy, out);
  texel(x0 + 1, y0 + 1, fx * fy, out);
}

template <bool kOcclusion>
static void alpha_filter(const RTCFilterFunctionNArguments* args) {
  auto* g = static_cast<RayTracer::Impl::Geom*>(args->geometryUserPtr);
  const RayTracer::Impl& impl = *g->owner;
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] != -1) continue;
    unsigned inst = RTCHitN_instID(args->hit, args->N, i, 0);
    if (inst >= impl.inst_by_rtc.size() || !impl.inst_by_rtc[inst]) continue;
    int mi = impl.inst_by_rtc[inst]->material;
    const Material& m = impl.materials[mi];
    if (kOcclusion && m.refraction > 0) {  // refracting surfaces cast no shadow and no occlusion
      args->valid[i] = 0;
      continue;
    }
    if (!m.alpha_mask) continue;
    float alpha = m.opacity;
    const auto* tex = impl.mat_diffuse_tex[mi];
    if (tex && !g->texcoords.empty()) {
      unsigned prim = RTCHitN_primID(args->hit, args->N, i);
      float u = RTCHitN_u(args->hit, args->N, i), v = RTCHitN_v(args->hit, args->N, i);
      const uint32_t* tri = &g->indices[size_t(prim) * 3];
      const float* t0 = &g->texcoords[size_t(tri[0]) * 2];
      const float* t1 = &g->texcoords[size_t(tri[1]) * 2];
      const float* t2 = &g->texcoords[size_t(tri[2]) * 2];
      float w = 1 - u - v;
      float rgba[4];
      sample_texture(*tex, w * t0[0] + u * t1[0] + v * t2[0], w * t0[1] + u * t1[1] + v * t2[1], false, rgba);
      alpha *= rgba[3];
    }
    if (alpha < m.alpha_cutoff) args->valid[i] = 0;
  }
}

// ---------------------------------------------------------------------------------------
// Sync: only what changed since the last sync is rebuilt.
// ---------------------------------------------------------------------------------------

void RayTracer::Impl::build_geom(const Scene& scene, const GeomKey& key, Geom& g) {
  auto [pos_id, nrm_id, uv_id, idx_id] = key;
  const Buffer& pos = *scene.buffer(pos_id);
  size_t nv = pos.count();
  g.indices.clear();
  if (idx_id != kNoId) {
    g.indices = scene.buffer(idx_id)->u;
  } else {
    g.indices.resize(nv - nv % 3);
    for (size_t i = 0; i < g.indices.size(); ++i) g.indices[i] = uint32_t(i);
  }
  g.normals = nrm_id != kNoId ? scene.buffer(nrm_id)->f : std::vector<float>{};
  g.texcoords = uv_id != kNoId ? scene.buffer(uv_id)->f : std::vector<float>{};
  if (g.blas) rtcReleaseScene(g.blas);
  g.blas = rtcNewScene(device);
  rtcSetSceneBuildQuality(g.blas, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry tri = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(tri, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), nv));
  std::memcpy(vb, pos.f.data(), nv * 3 * sizeof(float));
  size_t nt = g.indices.size() / 3;
  auto* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(tri, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), nt));
  std::memcpy(ib, g.indices.data(), nt * 3 * sizeof(uint32_t));
  g.owner = this;
  rtcSetGeometryUserData(tri, &g);
  if (g.filter) rtcSetGeometryIntersectFilterFunction(tri, alpha_filter<false>);
  if (g.filter || g.see_through) rtcSetGeometryOccludedFilterFunction(tri, alpha_filter<true>);
  rtcCommitGeometry(tri);
  rtcAttachGeometry(g.blas, tri);
  rtcReleaseGeometry(tri);
  rtcCommitScene(g.blas);
}

void RayTracer::Impl::sync(const Scene& scene, std::vector<std::string>& warnings) {
  stats = {};
  // Textures.
  for (auto it = textures.begin(); it != textures.end();)
    it = scene.textures().count(it->first) ? std::next(it) : textures.erase(it);
  for (auto& [id, e] : scene.textures()) {
    Tex& t = textures[id];
    if (t.version == e.version) continue;
    const Texture& src = e.value;
    if (src.width <= 0 || src.height <= 0 || src.rgba.size() != size_t(src.width) * src.height * 4) {
      warnings.push_back("texture " + std::to_string(id) + " has inconsistent size; ignored");
      t = Tex{};
      t.version = e.version;
      continue;
    }
    t.w = src.width; t.h = src.height; t.rgba = src.rgba; t.sampler = src.sampler; t.srgb = src.srgb; t.version = e.version;
  }
  // Materials (rebuilt whole: they are small).
  materials.assign(1, default_material());
  material_index.clear();
  for (auto& [id, e] : scene.materials()) {
    material_index[id] = int(materials.size());
    Material m = e.value;
    m.opacity = std::fmin(std::fmax(std::isfinite(m.opacity) ? m.opacity : 1.0f, 0.0f), 1.0f);
    m.reflection = std::fmin(std::fmax(std::isfinite(m.reflection) ? m.reflection : 0.0f, 0.0f), 1.0f);
    m.refraction = std::fmin(std::fmax(std::isfinite(m.refraction) ? m.refraction : 0.0f, 0.0f), 1.0f);
    if (!(m.ior > 0.01f && m.ior < 100.0f)) m.ior = 1.0f;
    materials.push_back(m);
  }
  auto tex_of = [&](Id id) -> const Tex* {
    auto it = textures.find(id);
    return it != textures.end() && it->second.w > 0 ? &it->second : nullptr;
  };
  mat_diffuse_tex.resize(materials.size());
  mat_specular_tex.resize(materials.size());
  mat_emissive_tex.resize(materials.size());
  for (size_t i = 0; i < materials.size(); ++i) {
    mat_diffuse_tex[i] = tex_of(materials[i].diffuse_texture);
    mat_specular_tex[i] = tex_of(materials[i].specular_texture);
    mat_emissive_tex[i] = tex_of(materials[i].emissive_texture);
  }

  // Camera-relative rebasing: keep world coordinates small around the camera so that a
  // scene far from the origin keeps its float precision. The origin moves in steps of
  // 1024 units, so ordinary scenes keep origin 0 and never rebuild for it.
  camera = scene.camera();
  Vec3 cam = camera.to_world.transform_point({0, 0, 0});
  Vec3 new_origin = origin;
  if (max_abs(cam - origin) > 4096.0f)
    new_origin = {std::round(cam.x / 1024) * 1024, std::round(cam.y / 1024) * 1024, std::round(cam.z / 1024) * 1024};
  origin = new_origin;

  // Geometry: which (buffer set) keys are used by renderable meshes, and which need filters.
  for (auto& [k, g] : geoms) g.used = false;
  std::map<GeomKey, bool> needs_filter, see_through;
  std::map<Id, GeomKey> mesh_key;
  for (auto [id, mesh] : scene.renderable_meshes(warnings)) {
    const Mesh& m = *mesh;
    GeomKey key{m.positions, m.normals, m.texcoords, m.indices};
    mesh_key[id] = key;
    auto mit = material_index.find(m.material);
    const Material& mat = mit == material_index.end() ? materials[0] : materials[mit->second];
    needs_filter[key] = needs_filter[key] || mat.alpha_mask;
    see_through[key] = see_through[key] || mat.refraction > 0;
  }
  for (auto& [id, key] : mesh_key) {
    auto [p, n, t, i] = key;
    uint64_t v = 0;
    for (Id b : {p, n, t, i})
      if (b != kNoId) v = std::max(v, scene.buffers().at(b).version);
    Geom& g = geoms[key];
    g.used = true;
    bool filter = needs_filter[key], thru = see_through[key];
    if (!g.blas || g.version != v || g.filter != filter || g.see_through != thru) {
      g.version = v;
      g.filter = filter;
      g.see_through = thru;
      build_geom(scene, key, g);
      ++stats.geometries_built;
    }
  }

  // Instances: one per mesh.
  bool top_changed = false;
  for (auto it = insts.begin(); it != insts.end();) {
    if (mesh_key.count(it->first)) { ++it; continue; }
    rtcDetachGeometry(top, it->second.id);
    rtcReleaseGeometry(it->second.geom);
    it = insts.erase(it);
    ++stats.instances_removed;
    top_changed = true;
  }
  for (auto& [id, key] : mesh_key) {
    const auto& e = scene.meshes().at(id);
    Geom& g = geoms[key];
    Inst& inst = insts[id];
    auto mit = material_index.find(e.value.material);
    inst.material = mit == material_index.end() ? 0 : mit->second;
    bool fresh = inst.geom == nullptr;
    if (fresh) {
      inst.mesh = id;
      inst.geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
      inst.id = rtcAttachGeometry(top, inst.geom);
    }
    if (fresh || inst.version != e.version || inst.g != &g || inst.geom_version != g.version || inst.origin_used != origin) {
      rtcSetGeometryInstancedScene(inst.geom, g.blas);
      Mat4 xf = Mat4::translate(-origin) * e.value.transform;
      rtcSetGeometryTransform(inst.geom, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, xf.m.data());
      rtcCommitGeometry(inst.geom);
      inst.normal_matrix = transpose(inverse(e.value.transform));
      inst.det_sign = e.value.transform.det3() < 0 ? -1.0f : 1.0f;
      inst.version = e.version;
      inst.g = &g;
      inst.geom_version = g.version;
      inst.origin_used = origin;
      ++stats.instances_updated;
      top_changed = true;
    }
  }
  for (auto it = geoms.begin(); it != geoms.end();) {
    if (it->second.used) { ++it; continue; }
    rtcReleaseScene(it->second.blas);
    it = geoms.erase(it);
  }
  inst_by_rtc.assign(0, nullptr);
  for (auto& [id, inst] : insts) {
    if (inst.id >= inst_by_rtc.size()) inst_by_rtc.resize(inst.id + 1, nullptr);
    inst_by_rtc[inst.id] = &inst;
  }
  if (top_changed || !committed) {
    rtcCommitScene(top);
    committed = true;
  }
  RTCBounds b;
  rtcGetSceneBounds(top, &b);
  extent = insts.empty() ? 1.0f : length(Vec3{b.upper_x - b.lower_x, b.upper_y - b.lower_y, b.upper_z - b.lower_z});
  if (!(extent > 0) || !std::isfinite(extent)) extent = 1.0f;

  lights.clear();
  for (auto& [id, e] : scene.lights()) {
    Light l = e.value;
    if (!l.on || !finite(l.position) || !finite(l.direction) || !finite(l.color) || !std::isfinite(l.intensity)) continue;
    l.position = l.position - origin;
    l.direction = normalize(l.direction);
    if (l.type != Light::Type::point && length(l.direction) == 0) continue;
    lights.push_back(l);
  }
  env = scene.environment();
  width = scene.width();
  height = scene.height();

  features = {};
  features.lights = !lights.empty();
  for (auto& [id, inst] : insts) {
    const Material& m = materials[inst.material];
    if (m.reflection > 0 || m.refraction > 0 || (m.opacity < 1 && !m.alpha_mask)) features.secondary = true;
    if (mat_diffuse_tex[inst.material] || mat_specular_tex[inst.material] || mat_emissive_tex[inst.material]) features.textures = true;
    if (inst.g->filter) features.alpha_masks = true;
  }
}

// ---------------------------------------------------------------------------------------
// The packet kernel
// ---------------------------------------------------------------------------------------
namespace {

template <int N>
struct alignas(64) Lanes {
  int valid[N];  // first member of an alignas(64) struct: aligned as Embree needs
  float ox[N], oy[N], oz[N], dx[N], dy[N], dz[N];
  float weight[N];  // throughput of this path (for culling)

  void set(int i, const Vec3& o, const Vec3& d, float w) {
    valid[i] = -1;
    ox[i] = o.x; oy[i] = o.y; oz[i] = o.z;
    dx[i] = d.x; dy[i] = d.y; dz[i] = d.z;
    weight[i] = w;
  }
};

// Primary rays of a pinhole camera through pixel centres (shared by the shading kernel and
// the bare-kernel benchmark, so both trace exactly the same rays). Directions are not
// normalised: Embree does not need it, and hit positions are o + t d either way.
struct PrimaryCamera {
  Vec3 origin, cx, cy, cz;
  float sx_scale = 1, sy_scale = 1;
  int32_t width = 1, height = 1;

  PrimaryCamera(const Camera& camera, const Vec3& rebase, int32_t w, int32_t h) : width(w), height(h) {
    // Vertical field of view clamped away from 0 and 180 degrees.
    float tan_half = std::tan(std::fmin(std::fmax(camera.fov_y, 1e-6f), kPi - 1e-4f) * 0.5f);
    origin = camera.to_world.transform_point({0, 0, 0}) - rebase;
    cx = camera.to_world.transform_vector({1, 0, 0});
    cy = camera.to_world.transform_vector({0, 1, 0});
    cz = camera.to_world.transform_vector({0, 0, -1});
    sx_scale = tan_half * (float(w) / float(h));
    sy_scale = tan_half;
  }
  Vec3 direction(int x, int y) const {
    float sx = (2.0f * (x + 0.5f) / float(width) - 1.0f) * sx_scale;
    float sy = (1.0f - 2.0f * (y + 0.5f) / float(height)) * sy_scale;
    return cz + cx * sx + cy * sy;
  }
};

template <int N>
struct Colors {
  float r[N], g[N], b[N];
};

// Everything shading needs about one hit.
struct Hit {
  Vec3 p, n, ng, v;  // position, shading normal, geometric normal (both facing the viewer), to viewer
  bool entering;     // the ray hit the geometric front side
  int material = 0;
  float uv[2] = {0, 0};
  bool has_uv = false;
};

inline Vec3 reflect(const Vec3& d, const Vec3& n) { return d - n * (2 * dot(d, n)); }

}  // namespace

template <int N, unsigned F>
struct Kernel {
  using P = Packet<N>;
  const RayTracer::Impl& s;
  const RenderSettings& cfg;
  RayCounts& rays;
  float ao_dist;

  // Scale-aware offset for a secondary ray's origin.
  float eps(const Vec3& p) const { return 1e-4f * std::fmax(max_abs(p), 1e-3f * s.extent) + 1e-30f; }

  void trace(Lanes<N>& in, int depth, Colors<N>& out, bool primary) {
    alignas(64) typename P::RayHit rh;
    for (int i = 0; i < N; ++i) {
      rh.ray.org_x[i] = in.ox[i]; rh.ray.org_y[i] = in.oy[i]; rh.ray.org_z[i] = in.oz[i];
      rh.ray.dir_x[i] = in.dx[i]; rh.ray.dir_y[i] = in.dy[i]; rh.ray.dir_z[i] = in.dz[i];
      rh.ray.tnear[i] = 0.0f;
      rh.ray.tfar[i] = in.valid[i] ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity();
      rh.ray.time[i] = 0; rh.ray.mask[i] = 0xFFFFFFFFu; rh.ray.id[i] = 0; rh.ray.flags[i] = 0;
      rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
      out.r[i] = out.g[i] = out.b[i] = 0;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = primary ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    P::intersect(in.valid, s.top, &ctx, &rh);
    int count = 0;
    for (int i = 0; i < N; ++i) count += in.valid[i] != 0;
    if (primary) rays.primary += count; else rays.secondary += count;
    shade(in, rh, depth, out);
  }

  // Fills hit records for the valid lanes that hit something; misses get the background.
  void shade(Lanes<N>& in, typename P::RayHit& rh, int depth, Colors<N>& out) {
    Hit hits[N];
    bool hit_mask[N];
    const Environment& env = s.env;
    for (int i = 0; i < N; ++i) {
      hit_mask[i] = false;
      if (!in.valid[i]) continue;
      unsigned inst_id = rh.hit.instID[0][i];
      if (rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID || inst_id >= s.inst_by_rtc.size() || !s.inst_by_rtc[inst_id]) {
        out.r[i] = env.background.x; out.g[i] = env.background.y; out.b[i] = env.background.z;
        continue;
      }
      hit_mask[i] = true;
      const auto& inst = *s.inst_by_rtc[inst_id];
      const auto& g = *inst.g;
      Hit& h = hits[i];
      h.material = inst.material;
      Vec3 d{in.dx[i], in.dy[i], in.dz[i]};
      float t = rh.ray.tfar[i];
      h.p = Vec3{in.ox[i], in.oy[i], in.oz[i]} + d * t;
      h.v = normalize(-d);
      Vec3 ng = normalize(inst.normal_matrix.transform_vector({rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]}) * inst.det_sign);
      unsigned prim = rh.hit.primID[i];
      float u = rh.hit.u[i], v = rh.hit.v[i], w = 1 - u - v;
      const uint32_t* tri = &g.indices[size_t(prim) * 3];
      Vec3 n = ng;
      if (!g.normals.empty()) {
        const float* n0 = &g.normals[size_t(tri[0]) * 3];
        const float* n1 = &g.normals[size_t(tri[1]) * 3];
        const float* n2 = &g.normals[size_t(tri[2]) * 3];
        Vec3 on{w * n0[0] + u * n1[0] + v * n2[0], w * n0[1] + u * n1[1] + v * n2[1], w * n0[2] + u * n1[2] + v * n2[2]};
        Vec3 wn = normalize(inst.normal_matrix.transform_vector(on));
        if (finite(wn) && length(wn) > 0.5f) n = wn;
      }
      h.entering = dot(ng, d) < 0;
      if (!h.entering) ng = -ng;
      if (dot(n, ng) < 0) n = -n;  // shading normal on the viewer's side of the surface
      h.n = n;
      h.ng = ng;
      if constexpr ((F & kTextures) != 0) {
        if (!g.texcoords.empty() && (s.mat_diffuse_tex[h.material] || s.mat_specular_tex[h.material] ||
                                     s.mat_emissive_tex[h.material])) {
          const float* t0 = &g.texcoords[size_t(tri[0]) * 2];
          const float* t1 = &g.texcoords[size_t(tri[1]) * 2];
          const float* t2 = &g.texcoords[size_t(tri[2]) * 2];
          h.uv[0] = w * t0[0] + u * t1[0] + v * t2[0];
          h.uv[1] = w * t0[1] + u * t1[1] + v * t2[1];
          h.has_uv = true;
        }
      }
    }

    // Local shading inputs per lane.
    Vec3 diffuse[N], specular[N], color[N];
    float opacity[N];
    for (int i = 0; i < N; ++i) {
      if (!hit_mask[i]) continue;
      const Hit& h = hits[i];
      const Material& m = s.materials[h.material];
      Vec3 dc = m.diffuse_color, sc = m.specular_color, ec = m.emissive_color;
      float op = m.opacity;
      if constexpr ((F & kTextures) != 0) {
        if (h.has_uv) {
          float rgba[4];
          if (const auto* t = s.mat_diffuse_tex[h.material]) {
            sample_texture(*t, h.uv[0], h.uv[1], env.linear, rgba);
            dc = dc * Vec3{rgba[0], rgba[1], rgba[2]};
            if (!m.alpha_mask) op *= rgba[3];
          }
          if (const auto* t = s.mat_specular_tex[h.material]) {
            sample_texture(*t, h.uv[0], h.uv[1], env.linear, rgba);
            sc = sc * Vec3{rgba[0], rgba[1], rgba[2]};
          }
          if (const auto* t = s.mat_emissive_tex[h.material]) {
            sample_texture(*t, h.uv[0], h.uv[1], env.linear, rgba);
            ec = ec * Vec3{rgba[0], rgba[1], rgba[2]};
          }
        }
      }
      if (m.alpha_mask) op = 1.0f;  // the filter already removed the cut-out parts
      diffuse[i] = dc;
      specular[i] = sc;
      opacity[i] = op;
      if (m.model == Material::Model::matte) color[i] = dc;  // unlit
      else color[i] = ec + dc * m.ambient_intensity;
    }

    // Direct light with shadows: one occlusion packet per light.
    for (const Light& light : s.lights) {
      alignas(64) typename P::Ray sr;
      alignas(64) int valid[N];  // Embree needs the mask aligned to the packet width
      Vec3 contrib[N];
      int count = 0;
      for (int i = 0; i < N; ++i) {
        valid[i] = 0;
        if (!hit_mask[i] || s.materials[hits[i].material].model == Material::Model::matte) continue;
        const Hit& h = hits[i];
        Vec3 l;
        float dist = std::numeric_limits<float>::infinity(), atten = 1.0f;
        if (light.type == Light::Type::directional) {
          l = -light.direction;
        } else {
          Vec3 to = light.position - h.p;
          dist = length(to);
          if (!(dist > 0)) continue;
          l = to / dist;
          float den = light.attenuation.x + light.attenuation.y * dist + light.attenuation.z * dist * dist;
          atten = den > 0 ? 1.0f / den : 0.0f;
          if (light.type == Light::Type::spot) {
            float c = dot(-l, light.direction);
            float cos_outer = std::cos(light.cutoff);
            float cos_inner = std::cos(light.cutoff * (1.0f - std::fmin(std::fmax(light.softness, 0.0f), 1.0f)));
            atten *= smoothstep(cos_outer, cos_inner, c);
          }
        }
        float ndl = dot(h.n, l);
        if (ndl <= 0 || atten <= 0 || dot(h.ng, l) <= 0) continue;
        Vec3 e = light.color * (light.intensity * atten);
        Vec3 c = diffuse[i] * (ndl * (s.env.linear ? 1.0f / kPi : 1.0f));
        const Material& m = s.materials[h.material];
        if (m.model == Material::Model::phong && max_component(specular[i]) > 0) {
          float rv = dot(reflect(-l, h.n), h.v);
          if (rv > 0) c += specular[i] * std::pow(rv, std::fmax(m.shininess * 128.0f, 1.0f));
        }
        contrib[i] = c * e;
        if (!cfg.shadows) {
          color[i] += contrib[i];
          continue;
        }
        Vec3 o = h.p + h.ng * eps(h.p);
        sr.org_x[i] = o.x; sr.org_y[i] = o.y; sr.org_z[i] = o.z;
        sr.dir_x[i] = l.x; sr.dir_y[i] = l.y; sr.dir_z[i] = l.z;
        sr.tnear[i] = 0;
        sr.tfar[i] = std::isfinite(dist) ? dist * (1 - 1e-4f) : std::numeric_limits<float>::infinity();
        sr.time[i] = 0; sr.mask[i] = 0xFFFFFFFFu; sr.id[i] = 0; sr.flags[i] = 0;
        valid[i] = -1;
        ++count;
      }
      if (!count || !cfg.shadows) continue;
      for (int i = 0; i < N; ++i)
        if (!valid[i]) { sr.tnear[i] = 0; sr.tfar[i] = -1; sr.org_x[i] = sr.org_y[i] = sr.org_z[i] = 0; sr.dir_x[i] = sr.dir_y[i] = 0; sr.dir_z[i] = 1; }
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
      P::occluded(valid, s.top, &ctx, &sr);
      rays.shadow += count;
      for (int i = 0; i < N; ++i)
        if (valid[i] && sr.tfar[i] >= 0) color[i] += contrib[i];
    }

    // Sky ambient, occluded by ambient occlusion.
    bool ambient = max_component(env.ambient) > 0;
    float ao[N];
    for (int i = 0; i < N; ++i) ao[i] = 1.0f;
    if constexpr ((F & kAO) != 0) {
      if (ambient && cfg.ao_samples > 0) occlusion(hits, hit_mask, ao);
    }
    if (ambient)
      for (int i = 0; i < N; ++i)
        if (hit_mask[i] && s.materials[hits[i].material].model != Material::Model::matte)
          color[i] += diffuse[i] * env.ambient * ao[i];

    // Reflection, refraction and see-through, each as a packet of secondary rays.
    if constexpr ((F & kSecondary) != 0) {
      if (!s.features.secondary) {
        // No material reflects, refracts or is see-through: nothing to trace.
      } else if (depth + 1 < cfg.max_depth) {
        secondary(in, hits, hit_mask, opacity, color, depth);
      } else {
        // At the depth limit, see-through surfaces show the background.
        for (int i = 0; i < N; ++i)
          if (hit_mask[i]) {
            float keep = opacity[i] * (1.0f - s.materials[hits[i].material].refraction);
            color[i] = color[i] * keep + env.background * (1 - keep);
          }
      }
    } else {
      (void)opacity;
    }
    for (int i = 0; i < N; ++i)
      if (hit_mask[i]) { out.r[i] = color[i].x; out.g[i] = color[i].y; out.b[i] = color[i].z; }
  }

  void occlusion(const Hit* hits, const bool* hit_mask, float* ao) {
    const int S = cfg.ao_samples;
    int open[N] = {};
    uint32_t rot[N];
    Vec3 t[N], b[N];
    for (int i = 0; i < N; ++i)
      if (hit_mask[i]) {
        basis(hits[i].n, t[i], b[i]);
        // Per-hit rotation of the sample pattern (Cranley-Patterson), decorrelated per frame.
        uint32_t hx, hy, hz;
        std::memcpy(&hx, &hits[i].p.x, 4); std::memcpy(&hy, &hits[i].p.y, 4); std::memcpy(&hz, &hits[i].p.z, 4);
        rot[i] = hash32(hx ^ hash32(hy ^ hash32(hz ^ (cfg.frame * 0x9E3779B9u))));
      }
    for (int k = 0; k < S; ++k) {
      alignas(64) typename P::Ray r;
      alignas(64) int valid[N];  // Embree needs the mask aligned to the packet width
      int count = 0;
      for (int i = 0; i < N; ++i) {
        valid[i] = 0;
        r.tnear[i] = 0; r.tfar[i] = -1; r.time[i] = 0; r.mask[i] = 0xFFFFFFFFu; r.id[i] = 0; r.flags[i] = 0;
        r.org_x[i] = r.org_y[i] = r.org_z[i] = 0; r.dir_x[i] = r.dir_y[i] = 0; r.dir_z[i] = 1;
        if (!hit_mask[i]) continue;
        // Cosine-weighted hemisphere sample from a rotated Hammersley point.
        float u1 = (k + 0.5f) / S + (rot[i] & 0xFFFF) * (1.0f / 65536.0f);
        float u2 = radical_inverse2(uint32_t(k)) + (rot[i] >> 16) * (1.0f / 65536.0f);
        u1 -= std::floor(u1); u2 -= std::floor(u2);
        float rad = std::sqrt(u1), phi = 2 * kPi * u2;
        float x = rad * std::cos(phi), y = rad * std::sin(phi), z = std::sqrt(std::fmax(0.0f, 1 - u1));
        Vec3 d = t[i] * x + b[i] * y + hits[i].n * z;
        if (dot(d, hits[i].ng) <= 0) continue;  // below the geometric surface: counts as occluded
        Vec3 o = hits[i].p + hits[i].ng * eps(hits[i].p);
        r.org_x[i] = o.x; r.org_y[i] = o.y; r.org_z[i] = o.z;
        r.dir_x[i] = d.x; r.dir_y[i] = d.y; r.dir_z[i] = d.z;
        r.tfar[i] = ao_dist;
        valid[i] = -1;
        ++count;
      }
      if (!count) continue;
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
      P::occluded(valid, s.top, &ctx, &r);
      rays.ao += count;
      for (int i = 0; i < N; ++i)
        if (valid[i] && r.tfar[i] >= 0) ++open[i];
    }
    for (int i = 0; i < N; ++i)
      if (hit_mask[i]) ao[i] = float(open[i]) / float(S);
  }

  void secondary(const Lanes<N>& in, const Hit* hits, const bool* hit_mask, const float* opacity, Vec3* color, int depth) {
    // Up to three child packets: reflected, refracted, and straight through (opacity < 1).
    Lanes<N> refl{}, refr{}, thru{};
    float w_refl[N] = {}, w_refr[N] = {}, w_thru[N] = {}, keep[N];
    bool any_refl = false, any_refr = false, any_thru = false;
    for (int i = 0; i < N; ++i) {
      keep[i] = 1.0f;
      if (!hit_mask[i]) continue;
      const Hit& h = hits[i];
      const Material& m = s.materials[h.material];
      Vec3 d = -h.v;
      float op = opacity[i];
      float kr = m.reflection, kt = m.refraction;
      float fres_r = 0, fres_t = 0;
      Vec3 tdir;
      if (kt > 0) {
        // Dielectric Fresnel; the shading normal faces the viewer, so eta depends on the side hit.
        float eta = h.entering ? 1.0f / m.ior : m.ior;
        float cosi = std::fmin(std::fmax(dot(h.n, h.v), 0.0f), 1.0f);
        float sin2t = eta * eta * (1 - cosi * cosi);
        if (sin2t >= 1.0f) {
          fres_r = 1.0f;  // total internal reflection
        } else {
          float cost = std::sqrt(1 - sin2t);
          float rs = (eta * cosi - cost) / (eta * cosi + cost);
          float rp = (cosi - eta * cost) / (cosi + eta * cost);
          fres_r = 0.5f * (rs * rs + rp * rp);
          fres_t = 1 - fres_r;
          tdir = normalize(d * eta + h.n * (eta * cosi - cost));
        }
      }
      float wr = op * (kr + kt * fres_r);
      float wt = op * kt * fres_t;
      float wthru = 1 - op;
      keep[i] = op * (1 - kt);  // local shading share
      float base = in.weight[i];
      if (wr * base > 1e-3f) {
        Vec3 rd = normalize(reflect(d, h.n));
        if (dot(rd, h.ng) < 0) rd = normalize(reflect(d, h.ng));
        refl.set(i, h.p + h.ng * eps(h.p), rd, base * wr);
        w_refl[i] = wr;
        any_refl = true;
      }
      if (wt * base > 1e-3f) {
        refr.set(i, h.p - h.ng * eps(h.p), tdir, base * wt);
        w_refr[i] = wt;
        any_refr = true;
      }
      if (wthru * base > 1e-3f) {
        thru.set(i, h.p - h.ng * eps(h.p), d, base * wthru);
        w_thru[i] = wthru;
        any_thru = true;
      }
    }
    for (int i = 0; i < N; ++i)
      if (hit_mask[i]) color[i] = color[i] * keep[i];
    auto add = [&](Lanes<N>& l, const float* w) {
      Colors<N> c;
      trace(l, depth + 1, c, false);
      for (int i = 0; i < N; ++i)
        if (l.valid[i]) color[i] += Vec3{c.r[i], c.g[i], c.b[i]} * w[i];
    };
    if (any_refl) add(refl, w_refl);
    if (any_refr) add(refr, w_refr);
    if (any_thru) add(thru, w_thru);
  }
};

template <int N, unsigned F>
void RayTracer::Impl::render_task(const Rect& requested, const RenderSettings& cfg, TaskResult& out, const SchedulePlan* plan) {
  Rect pixels = intersect(requested, {0, 0, width, height});
  out.pixels = pixels;
  out.image = Image(pixels.width(), pixels.height());
  out.rays = {};
  out.kernel_ms = 0;
  out.cost = {};
  auto t0 = std::chrono::steady_clock::now();
  if (pixels.empty()) {
    out.rendering_ms = 0;
    return;
  }
  const int pw = layout.w, ph = layout.h;
  Rect packets{pixels.x0 / pw, pixels.y0 / ph, (pixels.x1 + pw - 1) / pw, (pixels.y1 + ph - 1) / ph};
  out.cost.packets = packets;
  out.cost.cost.assign(size_t(packets.area()), 0);

  const PrimaryCamera cam(camera, origin, width, height);
  float ao_dist = cfg.ao_distance > 0 ? cfg.ao_distance : 0.1f * extent;
  const double ns_per_tick = 1e6 / tsc_khz();
  const float exposure = env.exposure;
  const bool linear = env.linear;
  const SrgbEncodeLut& enc = srgb_encode_lut();

  // Renders the packets [x0, x1) x [y0, y1) of the task, counting rays into rc.
  auto render_block = [&](int y0, int y1, int x0, int x1, RayCounts& rc) {
    Kernel<N, F> k{*this, cfg, rc, ao_dist};
    for (int py = y0; py != y1; ++py)
      for (int px = x0; px != x1; ++px) {
        uint64_t c0 = cfg.cost_map ? __rdtsc() : 0;
        Lanes<N> lanes;
        int xs[N], ys[N];
        for (int i = 0; i < N; ++i) {
          int x = px * pw + i % pw, y = py * ph + i / pw;
          xs[i] = x; ys[i] = y;
          lanes.set(i, cam.origin, cam.direction(x, y), 1.0f);
          lanes.valid[i] = pixels.contains(x, y) ? -1 : 0;
        }
        Colors<N> c;
        k.trace(lanes, 0, c, true);
        for (int i = 0; i < N; ++i) {
          if (!lanes.valid[i]) continue;
          uint8_t* p = out.image.pixel(xs[i] - pixels.x0, ys[i] - pixels.y0);
          float r_ = c.r[i] * exposure, g_ = c.g[i] * exposure, b_ = c.b[i] * exposure;
          if (linear) { p[0] = encode_srgb(r_, enc); p[1] = encode_srgb(g_, enc); p[2] = encode_srgb(b_, enc); }
          else { p[0] = encode_linear(r_); p[1] = encode_linear(g_); p[2] = encode_linear(b_); }
          p[3] = 255;
        }
        if (cfg.cost_map) {
          uint64_t ticks = __rdtsc() - c0;
          double ns = double(ticks) * ns_per_tick;
          out.cost.cost[size_t(py - packets.y0) * packets.width() + size_t(px - packets.x0)] =
              uint32_t(std::fmin(ns, 4294967295.0));
        }
      }
  };
  if (!plan || plan->schedule == ThreadSchedule::work_stealing) {
    tbb::combinable<RayCounts> counts;
    tbb::parallel_for(tbb::blocked_range2d<int>(packets.y0, packets.y1, 1, packets.x0, packets.x1, 8),
                      [&](const tbb::blocked_range2d<int>& r) {
                        render_block(r.rows().begin(), r.rows().end(), r.cols().begin(), r.cols().end(), counts.local());
                      });
    out.rays = counts.combine([](const RayCounts& a, const RayCounts& b) { RayCounts s = a; s += b; return s; });
  } else {
    // One std::thread per worker (the calling thread is worker 0); each counts its own rays.
    const bool tiles = plan->schedule == ThreadSchedule::static_tiles;
    const size_t workers = tiles ? plan->tiles->size() : size_t(plan->threads);
    if (tiles) {  // the tiles must cover the task's packets exactly once
      int64_t covered = 0;
      for (size_t i = 0; i < workers; ++i) {
        Rect a = intersect((*plan->tiles)[i], packets);
        covered += a.area();
        for (size_t j = 0; j < i; ++j)
          if (!intersect(a, intersect((*plan->tiles)[j], packets)).empty())
            throw std::invalid_argument("static tiles overlap");
      }
      if (covered != packets.area()) throw std::invalid_argument("static tiles do not cover the task");
    }
    std::vector<RayCounts> rc(workers);
    std::atomic<int> next_row{packets.y0};
    auto work = [&](size_t w) {
      if (tiles) {
        Rect t = intersect((*plan->tiles)[w], packets);
        if (!t.empty()) render_block(t.y0, t.y1, t.x0, t.x1, rc[w]);
      } else {
        for (int py; (py = next_row.fetch_add(1, std::memory_order_relaxed)) < packets.y1;)
          render_block(py, py + 1, packets.x0, packets.x1, rc[w]);
      }
    };
    std::vector<std::thread> pool;
    pool.reserve(workers);
    for (size_t w = 1; w < workers; ++w) pool.emplace_back(work, w);
    if (workers > 0) work(0);
    for (std::thread& t : pool) t.join();
    for (const RayCounts& c : rc) out.rays += c;
  }
  out.rendering_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (cfg.cost_map) out.kernel_ms = double(out.cost.total()) * 1e-6;
  else out.cost = {};
}

template <int N>
double RayTracer::Impl::trace_primary(const Rect& requested, uint64_t* rays) {
  Rect pixels = intersect(requested, {0, 0, width, height});
  if (rays) *rays = 0;
  if (pixels.empty()) return 0;
  const int pw = layout.w, ph = layout.h;
  Rect packets{pixels.x0 / pw, pixels.y0 / ph, (pixels.x1 + pw - 1) / pw, (pixels.y1 + ph - 1) / ph};
  const PrimaryCamera cam(camera, origin, width, height);
  tbb::combinable<uint64_t> count;
  auto t0 = std::chrono::steady_clock::now();
  tbb::parallel_for(tbb::blocked_range2d<int>(packets.y0, packets.y1, 1, packets.x0, packets.x1, 8),
                    [&](const tbb::blocked_range2d<int>& r) {
                      uint64_t& n = count.local();
                      for (int py = r.rows().begin(); py != r.rows().end(); ++py)
                        for (int px = r.cols().begin(); px != r.cols().end(); ++px) {
                          alignas(64) typename Packet<N>::RayHit rh;
                          alignas(64) int valid[N];  // Embree needs the mask aligned to the packet width
                          for (int i = 0; i < N; ++i) {
                            int x = px * pw + i % pw, y = py * ph + i / pw;
                            valid[i] = pixels.contains(x, y) ? -1 : 0;
                            Vec3 d = cam.direction(x, y);
                            rh.ray.org_x[i] = cam.origin.x; rh.ray.org_y[i] = cam.origin.y; rh.ray.org_z[i] = cam.origin.z;
                            rh.ray.dir_x[i] = d.x; rh.ray.dir_y[i] = d.y; rh.ray.dir_z[i] = d.z;
                            rh.ray.tnear[i] = 0; rh.ray.tfar[i] = std::numeric_limits<float>::infinity();
                            rh.ray.time[i] = 0; rh.ray.mask[i] = 0xFFFFFFFFu; rh.ray.id[i] = 0; rh.ray.flags[i] = 0;
                            rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
                            rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;  // required with instancing
                            n += valid[i] != 0;
                          }
                          RTCIntersectContext ctx;
                          rtcInitIntersectContext(&ctx);
                          ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
                          Packet<N>::intersect(valid, top, &ctx, &rh);
                        }
                    });
  double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (rays) *rays = count.combine([](uint64_t a, uint64_t b) { return a + b; });
  return ms;
}

// ---------------------------------------------------------------------------------------
// Public interface
// ---------------------------------------------------------------------------------------

RayTracer::RayTracer(PacketLayout layout) {
  if (layout.w == 0 && layout.h == 0) layout = detect_packet_layout();
  if (layout.size() != 4 && layout.size() != 8 && layout.size() != 16)
    throw std::invalid_argument("packet layout must hold 4, 8 or 16 rays");
  impl_ = std::make_unique<Impl>(layout);
}
RayTracer::~RayTracer() = default;

void RayTracer::sync(const Scene& scene, std::vector<std::string>& warnings) { impl_->sync(scene, warnings); }
PacketLayout RayTracer::packet_layout() const { return impl_->layout; }
SceneFeatures RayTracer::features() const { return impl_->features; }
float RayTracer::scene_extent() const { return impl_->extent; }
RayTracer::SyncStats RayTracer::last_sync() const { return impl_->stats; }

// Calls f with the packet width as a compile-time constant.
template <class F>
static decltype(auto) dispatch_width(int rays_per_packet, F&& f) {
  switch (rays_per_packet) {
    case 16: return f(std::integral_constant<int, 16>{});
    case 8: return f(std::integral_constant<int, 8>{});
    default: return f(std::integral_constant<int, 4>{});
  }
}

void RayTracer::render(const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  dispatch_width(impl_->layout.size(), [&](auto n) { impl_->render_task<decltype(n)::value, kAll>(pixels, settings, out); });
}

void RayTracer::render_specialised(const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  const SceneFeatures& f = impl_->features;
  if (f.secondary || f.textures || f.alpha_masks || settings.ao_samples > 0)
    throw std::invalid_argument("the specialised kernel renders only scenes without AO, secondary rays, textures and alpha masks");
  dispatch_width(impl_->layout.size(), [&](auto n) { impl_->render_task<decltype(n)::value, kNone>(pixels, settings, out); });
}

const char* schedule_name(ThreadSchedule s) {
  switch (s) {
    case ThreadSchedule::static_tiles: return "static tiles";
    case ThreadSchedule::shared_queue: return "shared queue";
    default: return "work stealing";
  }
}

void RayTracer::render_scheduled(const Rect& pixels, const RenderSettings& settings, ThreadSchedule schedule,
                                 const std::vector<Rect>& tiles, int threads, TaskResult& out) {
  if (schedule == ThreadSchedule::static_tiles && tiles.empty())
    throw std::invalid_argument("static_tiles needs at least one tile");
  if (schedule == ThreadSchedule::shared_queue && threads < 1)
    throw std::invalid_argument("shared_queue needs at least one thread");
  const Impl::SchedulePlan plan{schedule, &tiles, threads};
  dispatch_width(impl_->layout.size(),
                 [&](auto n) { impl_->render_task<decltype(n)::value, kAll>(pixels, settings, out, &plan); });
}

double RayTracer::trace_primary_only(const Rect& pixels, uint64_t* rays) {
  return dispatch_width(impl_->layout.size(), [&](auto n) { return impl_->trace_primary<decltype(n)::value>(pixels, rays); });
}

}  // namespace tessera
