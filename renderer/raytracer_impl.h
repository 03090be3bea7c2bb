#pragma once
// The ray tracer's internals: its state (RayTracer::Impl) and what the packet kernel
// (renderer/raytracer_kernel.inc) needs besides it. Included by renderer/raytracer.cpp, which
// compiles the production kernel, and by the benchmarks' kernel variants
// (app/bench_kernels.cpp), which compile the same kernel source with their own policies.
// Not part of the renderer API: nothing else includes it.
#include "renderer/cpu.h"
#include "renderer/disturbance.h"
#include "renderer/embree_device.h"
#include "renderer/raytracer.h"
#include "renderer/sampling.h"

#include <embree3/rtcore.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <new>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

namespace tessera {
namespace raytracer_detail {

// ---------------------------------------------------------------------------------------
// Embree packet types by width
// ---------------------------------------------------------------------------------------

// In an anonymous namespace, so that the kernel's functions that take a packet of hits (shade,
// gather) stay local to the file that compiles them: GCC then inlines gather, called once, into
// shade. In a named namespace they become weak symbols, and GCC 12 leaves gather an
// out-of-line call per packet in the production kernel.
namespace {
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
}  // namespace

// The context of every occlusion query (shadow and AO rays): Embree's, then for shadow rays
// what passes each lane's ray (lanes are the rays' ids): the transmission left after the partly
// transparent surfaces it crossed, which alpha_filter multiplies by 1 - opacity, and the
// surfaces already counted (a BVH with spatial splits may report one triangle more than once).
// AO rays (shadow false): such surfaces occlude, as before.
// Every query's context starts with this: Embree passes the pointer on to the filter
// functions, which find the session's ray tracer here (its materials and instances). The
// geometries carry no pointer of their own, since they may be shared between sessions
// (renderer/geometry_cache.h).
struct QueryContext {
  RTCIntersectContext rtc;  // first: Embree's filter functions get a pointer to it
  const RayTracer::Impl* impl = nullptr;
  void init(const RayTracer::Impl* tracer, RTCIntersectContextFlags flags) {
    rtcInitIntersectContext(&rtc);
    rtc.flags = flags;
    impl = tracer;
  }
};
struct OcclusionContext {
  QueryContext q;  // first
  bool shadow = false;
  static constexpr int kLanes = 16, kSeen = 8;
  float transmission[kLanes];
  uint8_t seen_count[kLanes];
  uint64_t seen[kLanes][kSeen];  // instance << 32 | primitive
  void init(const RayTracer::Impl* tracer, bool for_shadows, int lanes) {
    q.init(tracer, RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
    shadow = for_shadows;
    for (int i = 0; i < lanes; ++i) transmission[i] = 1.0f, seen_count[i] = 0;
  }
};

// Put before a lane loop (4-16 iterations) of the per-packet path. Where GCC inlines the loop's
// function into the packet loop (render_task's per-packet body, the benchmarks' shading floor),
// it unrolls the loop completely before the vectorizer runs and leaves the copies scalar; kept a
// loop, it becomes one vector instruction sequence. Clang accepts the same pragma.
#define TESSERA_LANE_LOOP _Pragma("GCC unroll 1")

// Compile-time features of a kernel: the general kernel has all, the specialised none.
enum Feature : unsigned { kAO = 1, kSecondary = 2, kTextures = 4, kAll = 7, kNone = 0 };

// ---------------------------------------------------------------------------------------
// Colour and sampling helpers
// ---------------------------------------------------------------------------------------

// Output encoding: a channel, clamped to [0, 1] (NaN to 0), to its 8-bit code, as it is or on
// the sRGB curve. The curve's power segment, 1.055 c^(1/2.4) - 0.055 for c > 0.0031308, is a
// degree-6 polynomial in sqrt(c), fitted minimax over that segment: within 0.04 of a code
// step of the exact curve, so a code differs from the exactly rounded one only where the curve
// passes within 0.04 of a half step. Plain arithmetic, no table: lane loops are vector code.
// Two selects in a row (as a nest of selects on one value, GCC 12 left the loops around scalar).
inline float clamp_unit(float c) {
  const float lo = c > 0.0f ? c : 0.0f;  // NaN: 0
  return lo < 1.0f ? lo : 1.0f;
}
inline int encode_plain(float c) { return int(clamp_unit(c) * 255.0f + 0.5f); }
inline int encode_srgb(float c) {
  c = clamp_unit(c);
  const float s = std::sqrt(c);
  float p = -0.947538009f;
  p = p * s + 3.41827786f;
  p = p * s - 5.00269119f;
  p = p * s + 3.89817749f;
  p = p * s - 1.8994062f;
  p = p * s + 1.57526277f;
  p = p * s - 0.0422316502f;
  const float e = c <= 0.0031308f ? 12.92f * c : p;
  return int(e * 255.0f + 0.5f);
}

// Integer hash for per-pixel sample rotations (deterministic per frame), and the van der
// Corput sequence in base 2: the progressive sampler's (sampling.h), as floats here.
inline uint32_t hash32(uint32_t x) { return sampling::mix(x); }
inline float radical_inverse2(uint32_t i) { return float(sampling::sobol0(i)) * 2.3283064365386963e-10f; }

// sin and cos of 2 pi u for u in [0, 1) (an AO direction's azimuth), without a libm call, so
// that the lane loop around it can stay vector code (sincosf was 3% of a frame's time with
// AO). The turn splits into a quarter q and an angle t in [-pi/4, pi/4]; Taylor polynomials of
// degree 9 (sine) and 8 (cosine) there are within 2e-8 of the functions, below a float's
// rounding of the result, and the quarter swaps and signs them.
inline void sincos_turn(float u, float& sine, float& cosine) {
  const float u4 = 4.0f * u;
  const int32_t q = int32_t(u4 + 0.5f);  // u4 >= 0: truncation is the floor
  const float t = (u4 - float(q)) * (0.5f * kPi);
  const float t2 = t * t;
  const float st = t * (1.0f + t2 * (-1.0f / 6 + t2 * (1.0f / 120 + t2 * (-1.0f / 5040 + t2 * (1.0f / 362880)))));
  const float ct = 1.0f + t2 * (-0.5f + t2 * (1.0f / 24 + t2 * (-1.0f / 720 + t2 * (1.0f / 40320))));
  // The quarter's swap and signs as bit operations: GCC 12 leaves a lane loop scalar when it
  // selects on a bool or nests two selects of one value (the selects here had made the AO
  // direction loop scalar code).
  uint32_t sb, cb;
  std::memcpy(&sb, &st, 4);
  std::memcpy(&cb, &ct, 4);
  const uint32_t swap = 0u - uint32_t(q & 1);  // all ones in odd quarters
  const uint32_t s0 = (sb & ~swap) | (cb & swap), c0 = (cb & ~swap) | (sb & swap);
  const uint32_t s1 = s0 ^ (uint32_t(q & 2) << 30), c1 = c0 ^ (uint32_t((q + 1) & 2) << 30);
  std::memcpy(&sine, &s1, 4);
  std::memcpy(&cosine, &c1, 4);
}

// Orthonormal basis around n (Duff et al. 2017).
inline void basis(const Vec3& n, Vec3& t, Vec3& b) {
  float s = std::copysign(1.0f, n.z);
  float a = -1.0f / (s + n.z);
  float c = n.x * n.y * a;
  t = {1 + s * n.x * n.x * a, s * c, -s * n.x};
  b = {c, s + n.y * n.y * a, -n.y};
}

// A texture's addressing (size, wrap modes, filter) as plain numbers, fixed when the texture
// is converted, for texel_coords: GCC 12 leaves a lane loop scalar when it selects on a bool
// or nests two selects of one value, and selects on these numbers vectorise.
struct TexelAddressing {
  int32_t w = 1, h = 1;
  float fw = 1, fh = 1;
  float shift = 0.5f;                  // texel centres: 0.5 bilinear, 0 nearest
  float filter = 1;                    // 1 bilinear; 0 nearest (the second texel gets weight 0)
  int32_t repeat_s = 1, repeat_t = 1;  // 1 repeat, 0 clamp
  int32_t below_x = 0, above_x = 0, below_y = 0, above_y = 0;  // column (row) for -1 and w (h)

  TexelAddressing() = default;
  TexelAddressing(int32_t width, int32_t height, bool rs, bool rt, bool nearest)
      : w(width), h(height), fw(float(width)), fh(float(height)), shift(nearest ? 0.0f : 0.5f),
        filter(nearest ? 0.0f : 1.0f), repeat_s(rs), repeat_t(rt), below_x(rs ? width - 1 : 0),
        above_x(rs ? 0 : width - 1), below_y(rt ? height - 1 : 0), above_y(rt ? 0 : height - 1) {}
};

// A linear texture's mip levels below its own (level 0): each level a box filter of 2x2 texels
// of the one above (averaged as linear colour for sRGB textures that are decoded), RGBA8 like
// the texture, with its own addressing. Made by RayTracer::Impl::sync (raytracer.cpp) and
// shared by every ray tracer of the process that shows the same texels.
struct MipChain {
  SharedBytes base;                   // level 0's bytes, held: the cache knows a chain by their address
  std::vector<uint8_t> texels;        // levels 1..n, one after another
  std::vector<TexelAddressing> addr;  // levels 0..n
  std::vector<size_t> offset;         // levels 0..n, into texels (level 0: unused)
};

// max/min as the vector instructions compute them (the second operand when either is NaN),
// so that lane loops vectorise: std::fmax is a library call on baseline x86-64.
inline float fmaxf_(float a, float b) { return a > b ? a : b; }
inline float fminf_(float a, float b) { return a < b ? a : b; }

// One texture lookup (bilinear, or nearest as bilinear with one weight) in three steps that a
// loop over lanes sharing a texture can run as three loops: texel_coords and texel_blend are
// branch-free and vectorise, the loads in between are scalar. sample_texture chains the same
// steps for the scalar paths (lanes that hit different textures, alpha masks), so a pixel
// never depends on its packet.
struct TexelCoords {
  int i00, i10, i01, i11;  // texel indices of the 2x2 footprint
  float fx, fy;            // weights of the second column and row
};
__attribute__((always_inline)) inline TexelCoords texel_coords(const TexelAddressing& t, float u, float v) {
  u = u - u == 0.0f ? u : 0.0f;  // NaN and infinities sample the origin
  v = v - v == 0.0f ? v : 0.0f;
  const float u_repeat = u - std::floor(u), u_clamp = fminf_(fmaxf_(u, 0.0f), 1.0f);  // [0, 1]
  const float v_repeat = v - std::floor(v), v_clamp = fminf_(fmaxf_(v, 0.0f), 1.0f);
  u = t.repeat_s != 0 ? u_repeat : u_clamp;
  v = t.repeat_t != 0 ? v_repeat : v_clamp;
  const float x = u * t.fw - t.shift, y = v * t.fh - t.shift;
  const float xf = std::floor(x), yf = std::floor(y);
  TexelCoords c;
  c.fx = (x - xf) * t.filter;
  c.fy = (y - yf) * t.filter;
  // Texel columns and rows in [-1, size + 1]; across the edge: the other side (repeat) or
  // the edge texel (clamp). The second texel of a nearest lookup has weight 0. One of the two
  // selects' results is 0, so their sum is the wrapped index (nested selects stay scalar).
  auto wrap = [](int i, int n, int below, int above) {
    const int inside = i < 0 ? below : i;
    return (i >= n ? above : 0) + (i >= n ? 0 : inside);
  };
  int x0 = int(xf), y0 = int(yf), x1 = x0 + 1, y1 = y0 + 1;
  x0 = wrap(x0, t.w, t.below_x, t.above_x); x1 = wrap(x1, t.w, t.below_x, t.above_x);
  y0 = wrap(y0, t.h, t.below_y, t.above_y); y1 = wrap(y1, t.h, t.below_y, t.above_y);
  c.i00 = y0 * t.w + x0; c.i10 = y0 * t.w + x1;
  c.i01 = y1 * t.w + x0; c.i11 = y1 * t.w + x1;
  return c;
}
// The bilinear blend of four texels, each given as its two 32-bit halves (RG and BA, 16 bits a
// channel), so that the vector loop needs no 64-bit arithmetic.
__attribute__((always_inline)) inline void texel_blend(const uint32_t (&lo)[4], const uint32_t (&hi)[4], float fx, float fy,
                                                     float out[4]) {
  const float w00 = (1 - fx) * (1 - fy) * (1 / 65535.0f), w10 = fx * (1 - fy) * (1 / 65535.0f);
  const float w01 = (1 - fx) * fy * (1 / 65535.0f), w11 = fx * fy * (1 / 65535.0f);
  auto ch = [&](int k, int c) {
    const uint32_t half = c < 2 ? lo[k] : hi[k];
    return float(int((c & 1) ? half >> 16 : half & 0xFFFFu));
  };
  for (int c = 0; c < 4; ++c) out[c] = w00 * ch(0, c) + w10 * ch(1, c) + w01 * ch(2, c) + w11 * ch(3, c);
}
// One stored texel (RGBA8 as the image has it, R in the low byte) as texel_blend's two halves:
// the colour channels through the texture's table (16 bits each: decoded from sRGB, or x 257),
// alpha x 257. Decoding here rather than when the texture is converted halves the texels'
// memory (docs/results/load.md); the values are the ones a converted 16-bit texel held.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "texels are RGBA8 bytes read as one little-endian word");
__attribute__((always_inline)) inline void texel_halves(const uint32_t* lut, const uint8_t* texels, int i, uint32_t& lo,
                                                      uint32_t& hi) {
  uint32_t p;
  std::memcpy(&p, texels + size_t(i) * 4, 4);
  lo = lut[p & 0xFFu] | lut[(p >> 8) & 0xFFu] << 16;
  hi = lut[(p >> 16) & 0xFFu] | (p >> 24) * 257u << 16;
}
template <class Tex>
__attribute__((always_inline)) inline void sample_texture(const Tex& t, float u, float v, float out[4]) {
  const TexelCoords c = texel_coords(t.addr, u, v);
  const int idx[4] = {c.i00, c.i10, c.i01, c.i11};
  uint32_t lo[4], hi[4];
  for (int k = 0; k < 4; ++k) texel_halves(t.lut, t.bytes.data(), idx[k], lo[k], hi[k]);
  texel_blend(lo, hi, c.fx, c.fy, out);
}

// log2(x) for x > 0 to about 1e-4, in plain arithmetic that vectorises (the texture level of a
// lane); x below 1e-30 (and 0, NaN) reads as 1e-30.
inline float log2_approx(float x) {
  x = x > 1e-30f ? x : 1e-30f;
  uint32_t b;
  std::memcpy(&b, &x, 4);
  const float e = float(int(b >> 23) - 127);
  b = (b & 0x007FFFFFu) | 0x3F800000u;  // mantissa in [1, 2)
  float m;
  std::memcpy(&m, &b, 4);
  const float s = (m - 1.0f) / (m + 1.0f), s2 = s * s;  // log2 m = 2 atanh(s) / ln 2
  return e + s * (2.88539008f + s2 * (0.96179669f + s2 * (0.57707801f + s2 * 0.41219858f)));
}

// Trilinear filtering (linear-mipmap-linear, XML3D's and glTF viewers' default for a linear
// texture): a lane's level of detail `lod` (log2 of its footprint in texels, see the kernel's
// textures()) picks two neighbouring mip levels, bilinear in each, blended by the fraction. The
// arithmetic of the kernel's vector path (Kernel::modulate), so a pixel never depends on its
// packet. A texture without mip levels (nearest filter) is sample_texture.
struct TexelLevel {
  int l0, l1;  // the two levels
  float f;     // the second one's weight
};
template <class Tex>
__attribute__((always_inline)) inline TexelLevel texel_level(const Tex& t, float lod) {
  const float top = float(t.max_level);
  float lv = lod + t.lod_size;
  lv = lv > 0.0f ? (lv < top ? lv : top) : 0.0f;  // NaN: 0
  TexelLevel r;
  r.l0 = int(lv);
  r.f = lv - float(r.l0);
  r.l1 = r.l0 < t.max_level ? r.l0 + 1 : r.l0;
  return r;
}
template <class Tex>
__attribute__((always_inline)) inline void sample_texture_lod(const Tex& t, float u, float v, float lod, float out[4]) {
  if (t.max_level == 0) {
    sample_texture(t, u, v, out);
    return;
  }
  const TexelLevel l = texel_level(t, lod);
  float a[4], b[4];
  const int levels[2] = {l.l0, l.l1};
  float* dst[2] = {a, b};
  // With weight 0 the second level adds 0 x (a finite, non-negative value): a alone is the sum.
  const int count = l.f > 0.0f ? 2 : 1;
  if (count == 1)
    for (int c = 0; c < 4; ++c) b[c] = 0.0f;
  for (int k2 = 0; k2 < count; ++k2) {
    const TexelCoords c = texel_coords(t.level_addr[size_t(levels[k2])], u, v);
    const int idx[4] = {c.i00, c.i10, c.i01, c.i11};
    uint32_t lo[4], hi[4];
    const uint8_t* texels = t.level_texels[size_t(levels[k2])];
    for (int k = 0; k < 4; ++k) texel_halves(t.lut, texels, idx[k], lo[k], hi[k]);
    texel_blend(lo, hi, c.fx, c.fy, dst[k2]);
  }
  for (int c = 0; c < 4; ++c) out[c] = a[c] * (1.0f - l.f) + b[c] * l.f;
}

// Which copy of the kernel runs: the packet width's own instruction set where this CPU has
// it (16 lanes: AVX-512, 8 lanes: AVX2 with FMA; renderer/cpu.h), else the SSE2 copy, which
// every x86-64 runs.

}  // namespace raytracer_detail

// ---------------------------------------------------------------------------------------
// Renderer state
// ---------------------------------------------------------------------------------------

struct RayTracer::Impl {
  struct Tex {
    // RGBA8, the scene's own bytes (shared, not copied: the scene may change or drop its
    // texture while this session still shows it, until the next sync); a lookup turns each of
    // its four texels into 16 bits a channel through `lut` (texel_halves): decoded from sRGB
    // for glTF scenes, else as they are.
    SharedBytes bytes;
    const uint32_t* lut = nullptr;  // 256 entries
    raytracer_detail::TexelAddressing addr;  // size, wrap modes and filter
    bool decoded = false;  // colour channels decoded from sRGB
    bool translucent = false;  // some texel's alpha is below 1: a material without an alpha mask lets light through there
    uint64_t version = 0;
    // Mip levels (trilinear filtering, raytracer_detail::sample_texture_lod) for a linear
    // filter: level 0 is `bytes` and `addr`, levels 1..max_level are in `mips` (shared between
    // the ray tracers of a process that show the same texels). Nearest: max_level 0.
    static constexpr int kMaxLevels = 16;
    std::shared_ptr<const raytracer_detail::MipChain> mips;
    int max_level = 0;
    float lod_size = 0;  // log2 of the texture's side (half the log2 of its texel count)
    std::array<const uint8_t*, kMaxLevels> level_texels{};
    std::array<raytracer_detail::TexelAddressing, kMaxLevels> level_addr{};
  };
  struct Geom {
    // The BVH and triangles, possibly shared with other sessions (renderer/geometry_cache.h).
    std::shared_ptr<const SharedGeometry> shared;
    RTCScene blas = nullptr;            // shared->blas
    const uint32_t* indices = nullptr;  // shared->indices: 3 per triangle
    std::vector<float> normals;    // object space, 3 per vertex (empty: flat)
    std::vector<float> texcoords;  // 2 per vertex (empty: none)
    std::vector<float> colors;     // 3 per vertex, negatives as 0 (empty: none)
    uint64_t version = 0;          // max version of the buffers it was built from
    // Textured geometry: per triangle, half the log2 of its texture-space area (in units of the
    // whole texture) over its object-space area, the triangle's part of a lane's level of detail.
    std::vector<float> tri_lod;
    bool filter = false;           // alpha-mask filter attached
    bool see_through = false;      // occlusion filter for refracting and partly transparent materials attached
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
    float lod_bias = 0;    // -log2 of the transform's scale (|det|^(1/3)): its part of a level of detail
    uint64_t version = 0;
    uint64_t geom_version = 0;
    Vec3 origin_used;      // the rebasing origin its transform was built for
  };
  using GeomKey = std::tuple<Id, Id, Id, Id, Id>;  // positions, normals, texcoords, colors, indices

  std::shared_ptr<EmbreeDevice> shared_device = EmbreeDevice::acquire();  // one per process
  RTCDevice device = shared_device->get();
  RTCScene top = nullptr;
  PacketLayout layout;
  std::map<GeomKey, Geom> geoms;
  std::map<Id, Inst> insts;         // by mesh id
  std::vector<Inst*> inst_by_rtc;   // by Embree instance id
  std::map<Id, Tex> textures;
  std::vector<Material> materials;  // [0] = the default material
  std::vector<const Tex*> mat_diffuse_tex, mat_specular_tex, mat_emissive_tex;
  std::map<Id, int> material_index;
  // What the shading kernel reads per lane and per light, prepared once per sync.
  struct ShadeMat {
    Vec3 diffuse, specular, emissive;
    float ambient = 0, exponent = 1, opacity = 1, reflection = 0, refraction = 0, ior = 1;
    bool lit = true;         // not matte
    bool phong = false;      // has a specular highlight
    bool alpha_mask = false;
    bool textured = false;   // some texture of it is loaded
    bool vertex_color = false;  // Material::use_vertex_color: vertex colours multiply diffuse
  };
  std::vector<ShadeMat> shade_mats;  // by material index
  struct LightConst {
    Light::Type type;
    Vec3 position, direction, to_light, radiance, attenuation;
    float cos_outer = 0, inv_edge = 0;  // spot: smoothstep from cos_outer over 1 / inv_edge
    bool hard_edge = true;
    bool cast_shadow = true;  // false: no shadow rays for it (Light::cast_shadow)
  };
  std::vector<LightConst> light_consts;
  Camera camera;
  bool camera_ok = true;  // the camera's transform passes check_camera's transform bounds; else frames are background
  bool camera_check = true;  // set_camera_check (tests)
  Environment env;
  int32_t width = 0, height = 0;
  Vec3 origin;  // world position subtracted from everything (camera-relative rebasing)
  float extent = 1;
  SceneFeatures features;
  SyncStats stats;
  bool committed = false;

  // Throws what the device reported since `before` (EmbreeDevice::errors()): the frame or
  // sync that saw it fails with Embree's message instead of going on with a broken scene.
  void check_device(uint64_t before) const {
    if (shared_device->errors() != before) throw std::runtime_error(shared_device->last_error());
  }

  explicit Impl(PacketLayout l) : layout(l) {
    top = rtcNewScene(device);
    rtcSetSceneFlags(top, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(top, RTC_BUILD_QUALITY_LOW);
    materials.push_back(default_material());
  }
  ~Impl() {
    for (auto& [id, inst] : insts) rtcReleaseGeometry(inst.geom);
    rtcReleaseScene(top);
    geoms.clear();
    shared_device->geometries().trim();
  }

  static Material default_material() {  // XML3D: matte red
    Material m;
    m.model = Material::Model::matte;
    m.diffuse_color = {1, 0, 0};
    return m;
  }

  void sync(const Scene& scene, std::vector<std::string>& warnings);
  // Copies the geometry's buffers out of the scene and takes its BVH from the process's
  // geometry cache; when the cache has none, returns a new entry whose Embree scene is set
  // up but not committed: on the calling thread. Committing (the BVH build) may then run on
  // any thread, before the entry goes into the cache.
  std::shared_ptr<SharedGeometry> build_geom(const Scene& scene, const GeomKey& key, Geom& g);
};

namespace raytracer_detail {
// The production kernels, as render() runs them: with `plain`, the one with AO, secondary
// rays and textures compiled out (RayTracer::plain_kernel says when render() picks it), else
// the general one; in the copy for the packet width and this CPU. The benchmarks call it to
// time one kernel whatever the scene needs.
void render_production(const RayTracer::Impl& impl, bool plain, const Rect& pixels, const RenderSettings& settings,
                       TaskResult& out);
}  // namespace raytracer_detail

}  // namespace tessera
