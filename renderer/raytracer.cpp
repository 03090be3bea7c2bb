#include "renderer/raytracer.h"
#include "renderer/raytracer_impl.h"
#include "renderer/sampling.h"

#include "core/validate.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/blocked_range2d.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <cpuid.h>
#include <x86intrin.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <tuple>

namespace tessera {

using namespace raytracer_detail;

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

// Which copy of the kernel runs (raytracer_impl.h).
bool raytracer_detail::cpu_avx512() {
  static const bool yes = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                          __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw") &&
                          __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx2") &&
                          __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi2");
  return yes;
}
// F16C from CPUID leaf 1 (ECX bit 29): clang 14's __builtin_cpu_supports does not know "f16c".
static bool cpu_f16c() {
  unsigned a = 0, b = 0, c = 0, d = 0;
  return __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C);
}
bool raytracer_detail::cpu_avx2() {
  static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                          __builtin_cpu_supports("bmi2") && cpu_f16c();
  return yes;
}

const char* isa_name(PacketLayout p) {
  switch (p.size()) {
    case 16: return cpu_avx512() ? "AVX-512 (ray16)" : "SSE2 (ray16)";
    case 8: return cpu_avx2() ? "AVX2 (ray8)" : "SSE2 (ray8)";
    default: return "SSE2 (ray4)";
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
// Colour helpers
// ---------------------------------------------------------------------------------------

struct SrgbLut {
  // A texel channel (16 bits) for each 8-bit value: decoded from sRGB, or as it is (x 257).
  std::array<uint32_t, 256> texel_linear, texel_plain;
  // The inverse of texel_linear: for each 16-bit linear value, the sRGB code whose decoded value
  // is nearest (ties to the lower code). Mip levels of sRGB textures are averaged through it.
  std::array<uint8_t, 65536> code_of_linear;
  SrgbLut() {
    for (int i = 0; i < 256; ++i) {
      const float c = i / 255.0f;
      const float linear = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
      texel_linear[size_t(i)] = uint32_t(std::lround(linear * 65535.0f));
      texel_plain[size_t(i)] = uint32_t(i) * 257;
    }
    size_t code = 0;
    for (uint32_t v = 0; v < 65536; ++v) {
      // The next code is nearer once v is past the midpoint of the two decoded values.
      while (code < 255 && 2 * v > texel_linear[code] + texel_linear[code + 1]) ++code;
      code_of_linear[v] = uint8_t(code);
    }
  }
};
const SrgbLut& srgb_lut() {
  static const SrgbLut lut;
  return lut;
}

// Level k + 1 of a mip chain from level k (w x h RGBA8): each texel the mean of a 2x2 box (a
// dimension of 1 stays 1; an odd one drops its last row or column, as glGenerateMipmap may).
// Colour is averaged as linear light where the texture is decoded from sRGB, else as stored.
// In 16-bit units, as the kernel decodes texels (SrgbLut::texel_linear), so a level costs a
// few table reads a texel (the first sync of the pavilion builds about 5 million texels of them).
void mip_level(const uint8_t* src, int w, int h, bool srgb, uint8_t* dst, int dw, int dh) {
  const auto& lin = srgb_lut().texel_linear;
  const auto& code = srgb_lut().code_of_linear;
  tbb::parallel_for(tbb::blocked_range<int>(0, dh, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y != r.end(); ++y) {
      const int ya = std::min(2 * y, h - 1), yb = std::min(2 * y + 1, h - 1);
      for (int x = 0; x < dw; ++x) {
        const int xa = std::min(2 * x, w - 1), xb = std::min(2 * x + 1, w - 1);
        const uint8_t* q[4] = {src + (size_t(ya) * size_t(w) + size_t(xa)) * 4, src + (size_t(ya) * size_t(w) + size_t(xb)) * 4,
                               src + (size_t(yb) * size_t(w) + size_t(xa)) * 4, src + (size_t(yb) * size_t(w) + size_t(xb)) * 4};
        uint8_t* o = dst + (size_t(y) * size_t(dw) + size_t(x)) * 4;
        for (int c = 0; c < 4; ++c) {
          if (srgb && c < 3) {
            o[c] = code[(lin[q[0][c]] + lin[q[1][c]] + lin[q[2][c]] + lin[q[3][c]] + 2) / 4];
          } else {
            o[c] = uint8_t((unsigned(q[0][c]) + q[1][c] + q[2][c] + q[3][c] + 2) / 4);
          }
        }
      }
    }
  });
}

// The mip chain of a texture's bytes (levels down to 1x1, at most Tex::kMaxLevels in all), from
// the process's cache when another ray tracer made it for the same bytes.
std::shared_ptr<const MipChain> mip_chain(const SharedBytes& bytes, int w, int h, bool repeat_s, bool repeat_t,
                                          bool srgb) {
  using Key = std::tuple<const uint8_t*, int, int, bool, bool, bool>;
  static std::mutex mutex;
  static std::map<Key, std::weak_ptr<const MipChain>> cache;
  const Key key{bytes.data(), w, h, repeat_s, repeat_t, srgb};
  {
    std::lock_guard<std::mutex> lock(mutex);
    for (auto it = cache.begin(); it != cache.end();) it = it->second.expired() ? cache.erase(it) : std::next(it);
    auto it = cache.find(key);
    if (it != cache.end())
      if (auto chain = it->second.lock()) return chain;
  }
  auto chain = std::make_shared<MipChain>();
  chain->base = bytes;  // keeps the key's address this texture's while the chain lives
  chain->addr.push_back(TexelAddressing(w, h, repeat_s, repeat_t, false));
  chain->offset.push_back(0);
  size_t total = 0;
  for (int lw = w, lh = h, n = 1; (lw > 1 || lh > 1) && n < RayTracer::Impl::Tex::kMaxLevels; ++n) {
    lw = std::max(lw / 2, 1);
    lh = std::max(lh / 2, 1);
    chain->addr.push_back(TexelAddressing(lw, lh, repeat_s, repeat_t, false));
    chain->offset.push_back(total);
    total += size_t(lw) * size_t(lh) * 4;
  }
  chain->texels.resize(total);
  for (size_t k = 1; k < chain->addr.size(); ++k) {
    const TexelAddressing& a = chain->addr[k - 1];
    const uint8_t* src = k == 1 ? bytes.data() : chain->texels.data() + chain->offset[k - 1];
    mip_level(src, a.w, a.h, srgb, chain->texels.data() + chain->offset[k], chain->addr[k].w, chain->addr[k].h);
  }
  std::lock_guard<std::mutex> lock(mutex);
  cache[key] = chain;
  return chain;
}

inline float max_abs(const Vec3& p) { return std::fmax(std::fabs(p.x), std::fmax(std::fabs(p.y), std::fabs(p.z))); }

}  // namespace

// ---------------------------------------------------------------------------------------
// Alpha masks: an Embree filter function rejects hits where the mask is transparent. For
// occlusion it also lets refracting surfaces through, and shadow rays through partly
// transparent ones (opacity < 1 without an alpha mask) at the transmission 1 - opacity (times
// the diffuse texture's alpha, as shading reads it): a 50%-opaque pane casts a half shadow.
// ---------------------------------------------------------------------------------------

template <bool kOcclusion>
static void alpha_filter(const RTCFilterFunctionNArguments* args) {
  // Every query passes a QueryContext (raytracer_kernel.inc), first in an OcclusionContext
  // for occlusion queries: the session's ray tracer is found there, not in the geometry,
  // which other sessions may share.
  auto* qc = reinterpret_cast<const QueryContext*>(args->context);
  const RayTracer::Impl& impl = *qc->impl;
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] != -1) continue;
    unsigned inst = RTCHitN_instID(args->hit, args->N, i, 0);
    if (inst >= impl.inst_by_rtc.size() || !impl.inst_by_rtc[inst]) continue;
    const RayTracer::Impl::Geom* g = impl.inst_by_rtc[inst]->g;
    int mi = impl.inst_by_rtc[inst]->material;
    const Material& m = impl.materials[mi];
    if (kOcclusion && m.refraction > 0) {  // refracting surfaces cast no shadow and no occlusion
      args->valid[i] = 0;
      continue;
    }
    // Partly transparent as shading sees it: opacity below 1, or a diffuse texture whose alpha
    // is (the kernel multiplies the opacity by it where there is no alpha mask).
    const bool translucent = kOcclusion && !m.alpha_mask && (m.opacity < 1 || (impl.mat_diffuse_tex[mi] && impl.mat_diffuse_tex[mi]->translucent));
    if (!m.alpha_mask && !translucent) continue;
    // An occlusion query's OcclusionContext: the filter may change what it carries for this query.
    auto* oc = kOcclusion ? reinterpret_cast<OcclusionContext*>(const_cast<QueryContext*>(qc)) : nullptr;
    if (translucent && !oc->shadow) continue;  // AO: an occluder
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
      sample_texture(*tex, w * t0[0] + u * t1[0] + v * t2[0], w * t0[1] + u * t1[1] + v * t2[1], rgba);
      alpha *= rgba[3];
    }
    if (!translucent) {
      if (alpha < m.alpha_cutoff) args->valid[i] = 0;
      continue;
    }
    const unsigned lane = RTCRayN_id(args->ray, args->N, i);
    if (lane >= unsigned(OcclusionContext::kLanes)) continue;  // not a kernel ray: an occluder
    const uint64_t key = uint64_t(inst) << 32 | RTCHitN_primID(args->hit, args->N, i);
    uint8_t& n = oc->seen_count[lane];
    bool counted = false;
    for (int k = 0; k < n; ++k) counted = counted || oc->seen[lane][k] == key;
    if (!counted) {
      if (n < OcclusionContext::kSeen) oc->seen[lane][n++] = key;
      oc->transmission[lane] *= 1.0f - std::fmin(std::fmax(alpha, 0.0f), 1.0f);
    }
    // Almost nothing left: occluded (traversal stops); else the ray goes on through it.
    if (oc->transmission[lane] > 1.0f / 512) args->valid[i] = 0;
  }
}

// ---------------------------------------------------------------------------------------
// Sync: only what changed since the last sync is rebuilt.
// ---------------------------------------------------------------------------------------

std::shared_ptr<SharedGeometry> RayTracer::Impl::build_geom(const Scene& scene, const GeomKey& key, Geom& g) {
  auto [pos_id, nrm_id, uv_id, col_id, idx_id] = key;
  const Buffer& pos = *scene.buffer(pos_id);
  const size_t nv = pos.count();
  std::vector<uint32_t> implicit;  // unindexed: vertices 0, 1, 2, ...
  const std::vector<uint32_t>* idx = &implicit;
  if (idx_id != kNoId) {
    idx = &scene.buffer(idx_id)->u;
  } else {
    implicit.resize(nv - nv % 3);
    for (size_t i = 0; i < implicit.size(); ++i) implicit[i] = uint32_t(i);
  }
  g.normals = nrm_id != kNoId ? scene.buffer(nrm_id)->f : std::vector<float>{};
  g.texcoords = uv_id != kNoId ? scene.buffer(uv_id)->f : std::vector<float>{};
  g.colors = col_id != kNoId ? scene.buffer(col_id)->f : std::vector<float>{};
  for (float& c : g.colors) c = std::fmax(c, 0.0f);  // colours are >= 0 (validate_mesh refused NaN and Inf)
  const size_t nt = idx->size() / 3;
  // Per triangle: half the log2 of its texture-space area over its object-space area (a lane's
  // level of detail adds its ray cone's footprint; Akenine-Moeller et al., "Texture Level of
  // Detail Strategies for Real-Time Ray Tracing", Ray Tracing Gems, 2019). Degenerate: level 0.
  g.tri_lod.clear();
  if (!g.texcoords.empty()) {
    g.tri_lod.resize(nt);
    const float* P = pos.f.data();
    const float* T = g.texcoords.data();
    for (size_t t = 0; t < nt; ++t) {
      const uint32_t a = (*idx)[t * 3], b = (*idx)[t * 3 + 1], c = (*idx)[t * 3 + 2];
      if (size_t(std::max({a, b, c})) >= std::min(nv, g.texcoords.size() / 2)) {
        g.tri_lod[t] = -64.0f;
        continue;
      }
      const Vec3 pa{P[a * 3], P[a * 3 + 1], P[a * 3 + 2]}, pb{P[b * 3], P[b * 3 + 1], P[b * 3 + 2]},
          pc{P[c * 3], P[c * 3 + 1], P[c * 3 + 2]};
      const float area = length(cross(pb - pa, pc - pa));
      const float ua = T[b * 2] - T[a * 2], va = T[b * 2 + 1] - T[a * 2 + 1];
      const float ub = T[c * 2] - T[a * 2], vb = T[c * 2 + 1] - T[a * 2 + 1];
      const float uv_area = std::fabs(ua * vb - va * ub);
      const float ratio = uv_area / area;
      g.tri_lod[t] = ratio > 0 && std::isfinite(ratio) ? std::fmin(std::fmax(0.5f * std::log2(ratio), -64.0f), 64.0f) : -64.0f;
    }
  }
  GeometryContent content{pos.f.data(), nv, idx->data(), nt, g.filter, g.see_through, EmbreeDevice::high_quality_bvh()};
  GeometryCache& cache = shared_device->geometries();
  const uint64_t h = cache.hash(content);
  g.shared = cache.find(content, h);
  if (g.shared) {
    g.blas = g.shared->blas;
    g.indices = g.shared->indices.data();
    ++stats.geometries_shared;
    return nullptr;
  }
  auto e = std::make_shared<SharedGeometry>();
  e->vertex_count = nv;
  e->triangle_count = nt;
  e->filter = g.filter;
  e->see_through = g.see_through;
  e->high_quality = content.high_quality;
  e->hash = h;
  e->bytes = GeometryCache::estimate_bytes(nv, nt);
  e->positions.assign(pos.f.begin(), pos.f.begin() + ptrdiff_t(nv * 3));
  e->positions.resize(nv * 3 + 4, 0.0f);  // Embree may read 16 bytes at the last vertex
  e->indices.assign(idx->begin(), idx->begin() + ptrdiff_t(nt * 3));
  e->blas = rtcNewScene(device);
  rtcSetSceneBuildQuality(e->blas, e->high_quality ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
  RTCGeometry tri = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, e->positions.data(), 0, 3 * sizeof(float), nv);
  rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, e->indices.data(), 0, 3 * sizeof(uint32_t), nt);
  if (e->filter) rtcSetGeometryIntersectFilterFunction(tri, alpha_filter<false>);
  if (e->filter || e->see_through) rtcSetGeometryOccludedFilterFunction(tri, alpha_filter<true>);
  rtcCommitGeometry(tri);
  rtcAttachGeometry(e->blas, tri);
  rtcReleaseGeometry(tri);
  g.shared = nullptr;
  g.blas = nullptr;
  g.indices = nullptr;
  return e;
}

void RayTracer::Impl::sync(const Scene& scene, std::vector<std::string>& warnings) {
  stats = {};
  env = scene.environment();
  // Textures: the scene's bytes, shared, and how a lookup reads them (Tex).
  for (auto it = textures.begin(); it != textures.end();)
    it = scene.textures().count(it->first) ? std::next(it) : textures.erase(it);
  for (auto& [id, e] : scene.textures()) {
    Tex& t = textures[id];
    const Texture& src = e.value;
    const bool decode = env.linear && src.srgb;
    if (t.version == e.version && t.decoded == decode) continue;
    // Texel indices are 32-bit ints in the kernel.
    if (src.width <= 0 || src.height <= 0 || int64_t(src.width) * src.height > (int64_t(1) << 30) ||
        src.rgba.size() != size_t(src.width) * src.height * 4) {
      warnings.push_back("texture " + std::to_string(id) + " has an inconsistent or too large size; ignored");
      t = Tex{};
      t.version = e.version;
      t.decoded = decode;  // warned once: not again at every sync
      continue;
    }
    t.addr = TexelAddressing(src.width, src.height, src.sampler.wrap_s == Sampler::Wrap::repeat,
                             src.sampler.wrap_t == Sampler::Wrap::repeat, src.sampler.filter == Sampler::Filter::nearest);
    t.decoded = decode;
    t.version = e.version;
    t.bytes = src.rgba;  // shared
    t.lut = decode ? srgb_lut().texel_linear.data() : srgb_lut().texel_plain.data();
    t.translucent = src.has_alpha();
    // Minification as the markup's default filter (linear-mipmap-linear) and the rasterizer
    // have it: trilinear over the mip chain; nearest: level 0 only.
    t.mips = nullptr;
    t.max_level = 0;
    t.lod_size = 0.5f * std::log2(float(src.width) * float(src.height));
    t.level_texels.fill(nullptr);
    t.level_texels[0] = t.bytes.data();
    t.level_addr[0] = t.addr;
    if (src.sampler.filter == Sampler::Filter::linear) {
      t.mips = mip_chain(t.bytes, src.width, src.height, src.sampler.wrap_s == Sampler::Wrap::repeat,
                         src.sampler.wrap_t == Sampler::Wrap::repeat, decode);
      t.max_level = int(t.mips->addr.size()) - 1;
      for (int k = 1; k <= t.max_level; ++k) {
        t.level_texels[size_t(k)] = t.mips->texels.data() + t.mips->offset[size_t(k)];
        t.level_addr[size_t(k)] = t.mips->addr[size_t(k)];
      }
    }
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
    return it != textures.end() && !it->second.bytes.empty() ? &it->second : nullptr;  // empty: ignored
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
  // A camera outside the bounds of core/validate.h (possible only for scenes built in code:
  // every entry point refuses it) renders the background and moves no origin: its rays
  // would not be finite or within what Embree accepts. The field of view is clamped by the
  // kernel, so only the transform counts here.
  camera = scene.camera();
  const std::string camera_why = check_transform(camera.to_world, kCameraLimits);
  camera_ok = camera_why.empty() || !camera_check;
  if (!camera_ok) warnings.push_back("camera not used (frames show the background): to_world: " + camera_why);
  Vec3 cam = camera.to_world.transform_point({0, 0, 0});
  Vec3 new_origin = origin;
  if (camera_ok && finite(cam) && max_abs(cam) <= kWorldLimit && max_abs(cam - origin) > 4096.0f)
    new_origin = {std::round(cam.x / 1024) * 1024, std::round(cam.y / 1024) * 1024, std::round(cam.z / 1024) * 1024};
  origin = new_origin;

  // Geometry: which (buffer set) keys are used by renderable meshes, and which need filters.
  for (auto& [k, g] : geoms) g.used = false;
  std::map<GeomKey, bool> needs_filter, see_through;
  std::map<Id, GeomKey> mesh_key;
  for (auto [id, mesh] : scene.renderable_meshes(warnings)) {
    const Mesh& m = *mesh;
    GeomKey key{m.positions, m.normals, m.texcoords, m.colors, m.indices};
    mesh_key[id] = key;
    auto mit = material_index.find(m.material);
    const Material& mat = mit == material_index.end() ? materials[0] : materials[mit->second];
    needs_filter[key] = needs_filter[key] || mat.alpha_mask;
    const Tex* diffuse = tex_of(mat.diffuse_texture);
    see_through[key] = see_through[key] || mat.refraction > 0 ||
                       (!mat.alpha_mask && (mat.opacity < 1 || (diffuse && diffuse->translucent && m.texcoords != kNoId)));
  }
  std::vector<std::pair<const GeomKey*, Geom*>> to_build;  // set up anew (from the cache, or built)
  for (auto& [id, key] : mesh_key) {
    auto [p, n, t, c, i] = key;
    uint64_t v = 0;
    for (Id b : {p, n, t, c, i})
      if (b != kNoId) v = std::max(v, scene.buffers().at(b).version);
    Geom& g = geoms[key];
    if (g.used) continue;  // another mesh instances the same buffers
    g.used = true;
    bool filter = needs_filter[key], thru = see_through[key];
    if (!g.blas || g.version != v || g.filter != filter || g.see_through != thru) {
      g.version = v;
      g.filter = filter;
      g.see_through = thru;
      to_build.emplace_back(&key, &g);
    }
  }
  // The scene's buffers are copied here, on the calling thread (which owns the scene); each
  // geometry's BVH is then built on its own task: a scene of many small meshes (the kitchen: 400)
  // built one after another would use one core, since Embree parallelises a build only inside a
  // large mesh. Commits of different Embree scenes may run concurrently.
  // Geometries that another session (or an earlier sync) built already come from the process's
  // geometry cache; only the others are built, and then offered to it.
  std::vector<std::pair<Geom*, std::shared_ptr<SharedGeometry>>> fresh_builds;
  for (auto& [key, g] : to_build)
    if (auto e = build_geom(scene, *key, *g)) fresh_builds.emplace_back(g, std::move(e));
  tbb::parallel_for(size_t(0), fresh_builds.size(), [&](size_t k) { rtcCommitScene(fresh_builds[k].second->blas); });
  for (auto& [g, e] : fresh_builds) {
    g->shared = shared_device->geometries().insert(std::move(e));  // or an equal one built meanwhile
    g->blas = g->shared->blas;
    g->indices = g->shared->indices.data();
  }
  stats.geometries_built += to_build.size();

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
      const float det = std::fabs(e.value.transform.det3());
      inst.lod_bias = det > 0 && std::isfinite(det) ? -std::log2(det) / 3.0f : 0.0f;
      inst.version = e.version;
      inst.g = &g;
      inst.geom_version = g.version;
      inst.origin_used = origin;
      ++stats.instances_updated;
      top_changed = true;
    }
  }
  bool released = false;
  for (auto it = geoms.begin(); it != geoms.end();) {
    if (it->second.used) { ++it; continue; }
    it = geoms.erase(it);
    released = true;
  }
  if (released || !fresh_builds.empty()) shared_device->geometries().trim();
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

  light_consts.clear();
  for (auto& [id, e] : scene.lights()) {
    Light l = e.value;
    if (!l.on || !finite(l.position) || !finite(l.direction) || !finite(l.color) || !std::isfinite(l.intensity)) continue;
    if (l.type != Light::Type::directional && !check_point(l.position).empty()) {  // shadow rays start at hits, aim here
      warnings.push_back("light " + std::to_string(id) + " not used: position " + check_point(l.position));
      continue;
    }
    l.position = l.position - origin;
    l.direction = normalize(l.direction);
    if (l.type != Light::Type::point && length(l.direction) == 0) continue;
    LightConst c;
    c.type = l.type;
    c.position = l.position;
    c.direction = l.direction;
    c.to_light = -l.direction;
    c.radiance = l.color * l.intensity;
    c.attenuation = l.attenuation;
    c.cos_outer = std::cos(l.cutoff);
    const float cos_inner = std::cos(l.cutoff * (1.0f - std::fmin(std::fmax(l.softness, 0.0f), 1.0f)));
    c.hard_edge = !(cos_inner > c.cos_outer);
    c.inv_edge = c.hard_edge ? 0.0f : 1.0f / (cos_inner - c.cos_outer);
    c.cast_shadow = l.cast_shadow;
    light_consts.push_back(c);
  }
  shade_mats.clear();
  for (size_t i = 0; i < materials.size(); ++i) {
    const Material& m = materials[i];
    ShadeMat c;
    c.diffuse = m.diffuse_color;
    c.specular = m.specular_color;
    c.emissive = m.emissive_color;
    c.ambient = m.ambient_intensity;
    c.exponent = std::fmax(m.shininess * 128.0f, 1.0f);
    c.opacity = m.alpha_mask ? 1.0f : m.opacity;  // the filter already removed the cut-out parts
    c.reflection = m.reflection;
    c.refraction = m.refraction;
    c.ior = m.ior;
    c.lit = m.model != Material::Model::matte;
    c.phong = m.model == Material::Model::phong;
    c.alpha_mask = m.alpha_mask;
    c.textured = mat_diffuse_tex[i] || mat_specular_tex[i] || mat_emissive_tex[i];
    c.vertex_color = m.use_vertex_color;
    shade_mats.push_back(c);
  }
  width = scene.width();
  height = scene.height();

  features = {};
  features.lights = !light_consts.empty();
  for (auto& [id, inst] : insts) {
    const Material& m = materials[inst.material];
    if (m.reflection > 0 || m.refraction > 0 || (m.opacity < 1 && !m.alpha_mask)) features.secondary = true;
    if (mat_diffuse_tex[inst.material] || mat_specular_tex[inst.material] || mat_emissive_tex[inst.material]) features.textures = true;
    if (inst.g->filter) features.alpha_masks = true;
    if (m.use_vertex_color && !inst.g->colors.empty()) features.vertex_colors = true;
  }
}

// ---------------------------------------------------------------------------------------
// The packet kernel, compiled once per instruction set (renderer/raytracer_kernel.inc)
// ---------------------------------------------------------------------------------------
// No FMA contraction in any copy: a fused multiply-add rounds once where the SSE2 copy rounds
// twice, so contracted copies would give a pixel different values on AVX2 and AVX-512 nodes
// of one heterogeneous cluster, and the AO pattern, seeded by the hit position's bits, would
// change between them. With contraction off every copy computes the same IEEE operations.
// It is off for this whole file by a compile flag (renderer/CMakeLists.txt), not by
// `#pragma GCC optimize`: that pragma also dropped -fno-trapping-math inside its region, which
// kept GCC from vectorising loops with masked divisions or conversions.
namespace isa_sse {
#include "renderer/raytracer_kernel.inc"
}  // namespace isa_sse

#if defined(__clang__)
// clang ignores `#pragma GCC target` (-Wunknown-pragmas), so its AVX2 and AVX-512 copies would
// be the same baseline code as the one above: the dispatch takes that one (the sanitizer
// builds use clang; three copies were a third of their renderer's compile time).
namespace isa_avx2 = isa_sse;
namespace isa_avx512 = isa_sse;
#else
TESSERA_ISA_AVX2_BEGIN
namespace isa_avx2 {
#include "renderer/raytracer_kernel.inc"
}  // namespace isa_avx2
TESSERA_ISA_END

TESSERA_ISA_AVX512_BEGIN
namespace isa_avx512 {
#include "renderer/raytracer_kernel.inc"
}  // namespace isa_avx512
TESSERA_ISA_END
#endif

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

void RayTracer::sync(const Scene& scene, std::vector<std::string>& warnings) {
  const uint64_t before = impl_->shared_device->errors();
  impl_->sync(scene, warnings);
  impl_->check_device(before);
}
PacketLayout RayTracer::packet_layout() const { return impl_->layout; }
void RayTracer::set_camera_check(bool on) { impl_->camera_check = on; }
SceneFeatures RayTracer::features() const { return impl_->features; }
float RayTracer::scene_extent() const { return impl_->extent; }
RayTracer::SyncStats RayTracer::last_sync() const { return impl_->stats; }

template <unsigned F>
static void render_dispatch(const RayTracer::Impl& impl, const Rect& pixels, const RenderSettings& settings,
                            TaskResult& out) {
  switch (impl.layout.size()) {
    case 16:
      if (cpu_avx512()) isa_avx512::render_task<16, F>(impl, pixels, settings, out, isa_avx512::Production{});
      else isa_sse::render_task<16, F>(impl, pixels, settings, out, isa_sse::Production{});
      return;
    case 8:
      if (cpu_avx2()) isa_avx2::render_task<8, F>(impl, pixels, settings, out, isa_avx2::Production{});
      else isa_sse::render_task<8, F>(impl, pixels, settings, out, isa_sse::Production{});
      return;
    default:
      isa_sse::render_task<4, F>(impl, pixels, settings, out, isa_sse::Production{});
  }
}

bool RayTracer::plain_kernel(const RenderSettings& settings) const {
  const SceneFeatures& f = impl_->features;
  return !(f.secondary || f.textures || f.alpha_masks || f.vertex_colors || settings.ao_samples > 0);
}

// A scene that needs no AO, secondary rays or textures runs the kernel with them compiled out:
// the general kernel's unused branches cost such scenes about 2% (`tessera bench --plain
// --compare specialised` measures it), and both kernels give the same bytes.
void raytracer_detail::render_production(const RayTracer::Impl& impl, bool plain, const Rect& pixels,
                                         const RenderSettings& settings, TaskResult& out) {
  if (plain) render_dispatch<kNone>(impl, pixels, settings, out);
  else render_dispatch<kAll>(impl, pixels, settings, out);
}

void RayTracer::render(const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  if (settings.block_samples && (kPlanBlock % impl_->layout.w != 0 || kPlanBlock % impl_->layout.h != 0))
    throw std::invalid_argument("a plan of blocks (adaptive refinement) needs packets that tile a " +
                                std::to_string(kPlanBlock) + "x" + std::to_string(kPlanBlock) + " block, not " +
                                std::to_string(impl_->layout.w) + "x" + std::to_string(impl_->layout.h));
  const uint64_t before = impl_->shared_device->errors();
  render_production(*impl_, plain_kernel(settings), pixels, settings, out);
  impl_->check_device(before);
}

}  // namespace tessera
