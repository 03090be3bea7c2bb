#include "renderer/rasterizer.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <tuple>

namespace tessera {

namespace {

// ---------------------------------------------------------------------------------------
// EGL: one surfaceless display per process (EGL displays are per-process singletons, so it
// is initialised once and never terminated: terminating it would destroy the contexts of
// other sessions' rasterizers).
// ---------------------------------------------------------------------------------------

std::string egl_error_name(EGLint e) {
  switch (e) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    default: {
      char b[32];
      std::snprintf(b, sizeof b, "EGL error 0x%04x", unsigned(e));
      return b;
    }
  }
}

[[noreturn]] void egl_fail(const std::string& what) {
  throw std::runtime_error("rasterizer: cannot create an OpenGL ES 3 context: " + what +
                           " (needs EGL with EGL_MESA_platform_surfaceless, e.g. Debian's libegl-mesa0)");
}

struct EglDisplay {
  std::mutex mutex;
  bool tried = false;
  EGLDisplay dpy = EGL_NO_DISPLAY;
  std::string error;
};

// Opens and initialises the surfaceless display; returns why not, or "" on success.
std::string open_surfaceless_display(EGLDisplay* out) {
  const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (!client_ext) return "no EGL implementation answers (eglQueryString: " + egl_error_name(eglGetError()) + ")";
  if (!std::strstr(client_ext, "EGL_MESA_platform_surfaceless"))
    return "the EGL implementation lacks EGL_MESA_platform_surfaceless";
  auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!get_display) return "eglGetPlatformDisplayEXT is not available";
  EGLDisplay dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (dpy == EGL_NO_DISPLAY) return "eglGetPlatformDisplayEXT(surfaceless): " + egl_error_name(eglGetError());
  EGLint major = 0, minor = 0;
  if (!eglInitialize(dpy, &major, &minor)) return "eglInitialize: " + egl_error_name(eglGetError());
  *out = dpy;
  return {};
}

EGLDisplay surfaceless_display() {
  static EglDisplay d;
  std::lock_guard<std::mutex> lock(d.mutex);
  if (!d.tried) {
    d.tried = true;
    d.error = open_surfaceless_display(&d.dpy);
  }
  if (!d.error.empty()) egl_fail(d.error);
  return d.dpy;
}

// ---------------------------------------------------------------------------------------
// Shaders: a GLSL ES 3.00 transcription of web/src/render/XML3DMaterial.js, with the
// compile-time defines turned into uniforms (one program for every material). World space
// is camera-relative (the camera sits at the origin) to keep float precision far from the
// scene's origin.
// ---------------------------------------------------------------------------------------

constexpr int kMaxLights = 8;  // per light type, as the WebGL fallback (MAX_LIGHTS)

const char* kVertexShader = R"(#version 300 es
layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec2 aUv;
layout(location = 3) in vec3 aColor;
uniform mat4 uModel;         // object -> camera-relative world
uniform mat3 uNormalMatrix;  // inverse transpose of the model's 3x3
uniform mat4 uViewProj;
out vec3 vWorldPos;
out vec3 vNormal;
out vec2 vUv;
out vec3 vColor;
void main() {
  vec4 wp = uModel * vec4(aPosition, 1.0);
  vWorldPos = wp.xyz;
  vNormal = uNormalMatrix * aNormal;
  vUv = aUv;
  vColor = aColor;
  gl_Position = uViewProj * wp;
}
)";

// Prefixed with "#version 300 es\n#define CAN_DISCARD 0|1\n".
const char* kFragmentShader = R"(
precision highp float;
precision highp int;
#define MAX_LIGHTS 8
uniform int uModelKind;  // 0 matte, 1 diffuse, 2 phong
uniform vec3 uDiffuseColor;
uniform vec3 uSpecularColor;
uniform vec3 uEmissiveColor;
uniform float uShininess;
uniform float uAmbientIntensity;
uniform float uOpacity;
uniform float uAlphaCutoff;
uniform bool uAlphaMask;
uniform bool uHasDiffuseTexture;
uniform bool uHasSpecularTexture;
uniform bool uHasEmissiveTexture;
uniform bool uUseVertexColor;  // XML3D's useVertexColor, and the mesh has colours
uniform sampler2D uDiffuseTexture;
uniform sampler2D uSpecularTexture;
uniform sampler2D uEmissiveTexture;
uniform vec3 uSceneAmbient;
uniform int uNumPoint;
uniform int uNumDir;
uniform int uNumSpot;
uniform vec3 uPointPosition[MAX_LIGHTS];
uniform vec3 uPointIntensity[MAX_LIGHTS];
uniform vec3 uPointAttenuation[MAX_LIGHTS];
uniform vec3 uDirDirection[MAX_LIGHTS];
uniform vec3 uDirIntensity[MAX_LIGHTS];
uniform vec3 uSpotPosition[MAX_LIGHTS];
uniform vec3 uSpotDirection[MAX_LIGHTS];
uniform vec3 uSpotIntensity[MAX_LIGHTS];
uniform vec3 uSpotAttenuation[MAX_LIGHTS];
uniform vec2 uSpotCone[MAX_LIGHTS];  // cos(outer), cos(inner)
uniform float uDiffuseScale;  // 1 (XML3D) or 1/pi (linear glTF scenes, as the ray tracer)
uniform float uExposure;
uniform bool uEncodeSrgb;
uniform bool uBlend;
in vec3 vWorldPos;
in vec3 vNormal;
in vec2 vUv;
in vec3 vColor;
out vec4 fragColor;

vec3 shade(vec3 L, vec3 I, vec3 N, vec3 V, vec3 kd, vec3 ks) {
  float ndl = max(dot(N, L), 0.0);
  vec3 c = kd * (ndl * uDiffuseScale);
  if (uModelKind == 2) {
    vec3 R = reflect(-L, N);
    c += ks * pow(max(dot(R, V), 0.0), uShininess * 128.0) * step(0.0, dot(N, L));
  }
  return I * c;
}

vec3 encode_srgb(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}

void main() {
  vec3 kd = uDiffuseColor;
  if (uUseVertexColor) kd *= max(vColor, vec3(0.0));
  float alpha = uOpacity;
  if (uHasDiffuseTexture) {
    vec4 t = texture(uDiffuseTexture, vUv);
    kd *= t.rgb;
    alpha *= t.a;
  }
#if CAN_DISCARD  // a program without discard lets llvmpipe test depth before shading
  if (uAlphaMask) {
    if (alpha < uAlphaCutoff) discard;
    alpha = 1.0;
  }
  if (alpha < 0.05) discard;
#endif
  vec3 color;
  if (uModelKind == 0) {
    color = kd;
  } else {
    vec3 ks = uSpecularColor;
    if (uHasSpecularTexture) ks *= texture(uSpecularTexture, vUv).rgb;
    vec3 ke = uEmissiveColor;
    if (uHasEmissiveTexture) ke *= texture(uEmissiveTexture, vUv).rgb;
    vec3 V = normalize(-vWorldPos);
    // Two-sided lighting as the ray tracer: the geometric normal turned to the viewer, and
    // the shading normal turned to the geometric normal's side.
    vec3 Ng = cross(dFdx(vWorldPos), dFdy(vWorldPos));
    if (dot(Ng, V) < 0.0) Ng = -Ng;
    vec3 N = normalize(vNormal);
    if (dot(N, Ng) < 0.0) N = -N;
    color = ke + uAmbientIntensity * kd + uSceneAmbient * kd;
    for (int i = 0; i < MAX_LIGHTS; i++) {
      if (i >= uNumPoint) break;
      vec3 L = uPointPosition[i] - vWorldPos;
      float d = length(L);
      vec3 a = uPointAttenuation[i];
      color += shade(L / d, uPointIntensity[i] / (a.x + a.y * d + a.z * d * d), N, V, kd, ks);
    }
    for (int i = 0; i < MAX_LIGHTS; i++) {
      if (i >= uNumDir) break;
      color += shade(-uDirDirection[i], uDirIntensity[i], N, V, kd, ks);
    }
    for (int i = 0; i < MAX_LIGHTS; i++) {
      if (i >= uNumSpot) break;
      vec3 L = uSpotPosition[i] - vWorldPos;
      float d = length(L);
      L /= d;
      float c = dot(-L, uSpotDirection[i]);
      vec2 cone = uSpotCone[i];
      float s = cone.y > cone.x + 1e-6 ? smoothstep(cone.x, cone.y, c) : step(cone.x, c);
      vec3 a = uSpotAttenuation[i];
      color += shade(L, s * uSpotIntensity[i] / (a.x + a.y * d + a.z * d * d), N, V, kd, ks);
    }
  }
  color *= uExposure;
  if (uEncodeSrgb) color = encode_srgb(color);
  fragColor = vec4(color, uBlend ? alpha : 1.0);
}
)";

float srgb_encode(float c) {
  c = std::fmin(std::fmax(c, 0.0f), 1.0f);
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

Material default_material() {  // XML3D: matte red (as the ray tracer)
  Material m;
  m.model = Material::Model::matte;
  m.diffuse_color = {1, 0, 0};
  return m;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// State
// ---------------------------------------------------------------------------------------

struct Rasterizer::Impl {
  struct Tex {
    GLuint name = 0;
    uint64_t version = 0;
    bool decoded = false;  // uploaded as sRGB (decoded to linear when sampled)
    bool has_alpha = false;
  };
  using GeomKey = std::tuple<Id, Id, Id, Id, Id>;  // positions, normals, texcoords, colors, indices
  struct Geom {
    GLuint vao = 0, vbo[4] = {0, 0, 0, 0}, ibo = 0;
    GLsizei count = 0;  // vertices to draw
    bool indexed = false, has_uv = false, has_color = false;
    Vec3 lo, hi;        // object-space bounds
    uint64_t version = 0;
    bool used = false;
  };
  struct Inst {
    GeomKey key;
    Mat4 transform;
    Id material = kNoId;
    uint64_t version = 0;
  };
  struct Uniforms {
    GLint model, normal_matrix, view_proj, model_kind, diffuse, specular, emissive, shininess, ambient_intensity,
        opacity, alpha_cutoff, alpha_mask, has_diffuse_tex, has_specular_tex, has_emissive_tex, diffuse_tex,
        specular_tex, emissive_tex, scene_ambient, num_point, num_dir, num_spot, point_pos, point_int, point_att,
        dir_dir, dir_int, spot_pos, spot_dir, spot_int, spot_att, spot_cone, diffuse_scale, exposure, encode_srgb,
        blend, use_vertex_color;
  };

  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  std::string context_error;  // non-empty: creation failed once; every call reports it
  struct Program {
    GLuint name = 0;
    Uniforms u{};
  };
  Program programs[2];  // [0] may discard (alpha masks, alpha textures, opacity < 0.05), [1] never does
  GLuint white = 0, fbo = 0, color_rb = 0, depth_rb = 0;
  int32_t fb_w = 0, fb_h = 0;
  GLint max_texture = 0, max_renderbuffer = 0;

  std::map<Id, Tex> textures;
  std::map<GeomKey, Geom> geoms;
  std::map<Id, Inst> insts;
  std::map<Id, Material> materials;
  std::vector<Light> lights;
  Camera camera;
  Environment env;
  int32_t width = 0, height = 0;
  SyncStats stats;

  ~Impl() {
    if (ctx == EGL_NO_CONTEXT) return;
    if (eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
      for (auto& [id, t] : textures) glDeleteTextures(1, &t.name);
      for (auto& [k, g] : geoms) free_geom(g);
      if (white) glDeleteTextures(1, &white);
      if (fbo) glDeleteFramebuffers(1, &fbo);
      if (color_rb) glDeleteRenderbuffers(1, &color_rb);
      if (depth_rb) glDeleteRenderbuffers(1, &depth_rb);
      for (Program& p : programs)
        if (p.name) glDeleteProgram(p.name);
      eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    }
    eglDestroyContext(dpy, ctx);
  }

  static void free_geom(Geom& g) {
    if (g.vao) glDeleteVertexArrays(1, &g.vao);
    for (GLuint& b : g.vbo)
      if (b) glDeleteBuffers(1, &b);
    if (g.ibo) glDeleteBuffers(1, &g.ibo);
    g = Geom{};
  }

  void create_context();
  void make_current() {
    if (ctx == EGL_NO_CONTEXT) create_context();
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx))
      throw std::runtime_error("rasterizer: eglMakeCurrent failed: " + egl_error_name(eglGetError()) +
                               " (the context is current in another thread?)");
  }
  void release() { eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT); }

  void sync(const Scene& scene, std::vector<std::string>& warnings);
  void upload_texture(Id id, const Texture& src, Tex& t, bool decode, std::vector<std::string>& warnings);
  void upload_geom(const Scene& scene, const GeomKey& key, Geom& g);
  void ensure_framebuffer();
  void render(const Rect& pixels, const RenderSettings& settings, TaskResult& out);
};

// Makes the context current for the duration of one public call, and releases it after
// (so that the next call may come from another thread).
struct CurrentContext {
  Rasterizer::Impl& impl;
  explicit CurrentContext(Rasterizer::Impl& i) : impl(i) { impl.make_current(); }
  ~CurrentContext() { impl.release(); }
};

static GLuint compile(GLenum type, const char* src) {
  GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048] = {};
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    glDeleteShader(s);
    throw std::runtime_error(std::string("rasterizer: shader does not compile: ") + log);
  }
  return s;
}

void Rasterizer::Impl::create_context() {
  if (!context_error.empty()) throw std::runtime_error(context_error);
  try {
    dpy = surfaceless_display();
    if (!eglBindAPI(EGL_OPENGL_ES_API)) egl_fail("eglBindAPI(OpenGL ES): " + egl_error_name(eglGetError()));
    const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint n = 0;
    if (!eglChooseConfig(dpy, config_attribs, &config, 1, &n) || n < 1)
      egl_fail("no EGL config renders OpenGL ES 3 (" + egl_error_name(eglGetError()) + ")");
    const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 0, EGL_NONE};
    ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, context_attribs);
    if (ctx == EGL_NO_CONTEXT) egl_fail("eglCreateContext(OpenGL ES 3.0): " + egl_error_name(eglGetError()));
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
      EGLint e = eglGetError();
      eglDestroyContext(dpy, ctx);
      ctx = EGL_NO_CONTEXT;
      egl_fail("eglMakeCurrent without a surface: " + egl_error_name(e));
    }
    // Programs.
    for (int variant = 0; variant < 2; ++variant) {
      std::string fs_src = std::string("#version 300 es\n#define CAN_DISCARD ") + (variant == 0 ? "1" : "0") + "\n" +
                           kFragmentShader;
      GLuint vs = compile(GL_VERTEX_SHADER, kVertexShader), fs = compile(GL_FRAGMENT_SHADER, fs_src.c_str());
      GLuint program = glCreateProgram();
      programs[variant].name = program;
      glAttachShader(program, vs);
      glAttachShader(program, fs);
      glLinkProgram(program);
      glDeleteShader(vs);
      glDeleteShader(fs);
      GLint ok = 0;
      glGetProgramiv(program, GL_LINK_STATUS, &ok);
      if (!ok) {
        char log[2048] = {};
        glGetProgramInfoLog(program, sizeof log, nullptr, log);
        throw std::runtime_error(std::string("rasterizer: program does not link: ") + log);
      }
      auto loc = [&](const char* n) { return glGetUniformLocation(program, n); };
      Uniforms& u = programs[variant].u;
      u = {loc("uModel"), loc("uNormalMatrix"), loc("uViewProj"), loc("uModelKind"), loc("uDiffuseColor"),
           loc("uSpecularColor"), loc("uEmissiveColor"), loc("uShininess"), loc("uAmbientIntensity"), loc("uOpacity"),
           loc("uAlphaCutoff"), loc("uAlphaMask"), loc("uHasDiffuseTexture"), loc("uHasSpecularTexture"),
           loc("uHasEmissiveTexture"), loc("uDiffuseTexture"), loc("uSpecularTexture"), loc("uEmissiveTexture"),
           loc("uSceneAmbient"), loc("uNumPoint"), loc("uNumDir"), loc("uNumSpot"), loc("uPointPosition"),
           loc("uPointIntensity"), loc("uPointAttenuation"), loc("uDirDirection"), loc("uDirIntensity"),
           loc("uSpotPosition"), loc("uSpotDirection"), loc("uSpotIntensity"), loc("uSpotAttenuation"),
           loc("uSpotCone"), loc("uDiffuseScale"), loc("uExposure"), loc("uEncodeSrgb"), loc("uBlend"),
           loc("uUseVertexColor")};
      glUseProgram(program);
      glUniform1i(u.diffuse_tex, 0);
      glUniform1i(u.specular_tex, 1);
      glUniform1i(u.emissive_tex, 2);
    }
    // A white texel for samplers without a texture.
    const uint8_t texel[4] = {255, 255, 255, 255};
    glGenTextures(1, &white);
    glBindTexture(GL_TEXTURE_2D, white);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, 1, 1, 0, GL_RGBA, GL_UNSIGNED_BYTE, texel);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_texture);
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_renderbuffer);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGenFramebuffers(1, &fbo);
    if (glGetError() != GL_NO_ERROR) throw std::runtime_error("rasterizer: GL error while setting up the context");
  } catch (const std::exception& e) {
    context_error = e.what();
    if (ctx != EGL_NO_CONTEXT) {
      eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(dpy, ctx);
      ctx = EGL_NO_CONTEXT;
    }
    for (Program& p : programs) p.name = 0;
    white = fbo = 0;
    throw;
  }
}

// ---------------------------------------------------------------------------------------
// Sync: only what changed since the last sync is uploaded.
// ---------------------------------------------------------------------------------------

void Rasterizer::Impl::upload_texture(Id id, const Texture& src, Tex& t, bool decode, std::vector<std::string>& warnings) {
  if (src.width <= 0 || src.height <= 0 || src.rgba.size() != size_t(src.width) * src.height * 4) {
    warnings.push_back("texture " + std::to_string(id) + " has inconsistent size; ignored");
    if (t.name) glDeleteTextures(1, &t.name);
    t.name = 0;
    return;
  }
  if (src.width > max_texture || src.height > max_texture) {
    warnings.push_back("texture " + std::to_string(id) + " exceeds GL_MAX_TEXTURE_SIZE " + std::to_string(max_texture) +
                       "; ignored");
    if (t.name) glDeleteTextures(1, &t.name);
    t.name = 0;
    return;
  }
  if (!t.name) glGenTextures(1, &t.name);
  glBindTexture(GL_TEXTURE_2D, t.name);
  // Row 0 of the scene's texture is v = 0, which is GL's first row (t = 0): no flip.
  glTexImage2D(GL_TEXTURE_2D, 0, decode ? GL_SRGB8_ALPHA8 : GL_RGBA8, src.width, src.height, 0, GL_RGBA,
               GL_UNSIGNED_BYTE, src.rgba.data());
  bool linear = src.sampler.filter == Sampler::Filter::linear;
  // As three.js does for the WebGL fallback: trilinear mipmaps for minification.
  if (linear) glGenerateMipmap(GL_TEXTURE_2D);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, linear ? GL_LINEAR_MIPMAP_LINEAR : GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, linear ? GL_LINEAR : GL_NEAREST);
  auto wrap = [](Sampler::Wrap w) { return w == Sampler::Wrap::repeat ? GL_REPEAT : GL_CLAMP_TO_EDGE; };
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, wrap(src.sampler.wrap_s));
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, wrap(src.sampler.wrap_t));
  t.decoded = decode;
  t.has_alpha = src.has_alpha();
  if (glGetError() == GL_OUT_OF_MEMORY) throw std::runtime_error("rasterizer: out of memory uploading texture " + std::to_string(id));
  ++stats.textures_uploaded;
}

void Rasterizer::Impl::upload_geom(const Scene& scene, const GeomKey& key, Geom& g) {
  auto [pos_id, nrm_id, uv_id, col_id, idx_id] = key;
  const Buffer& pos = *scene.buffer(pos_id);
  size_t nv = pos.count();
  free_geom(g);
  glGenVertexArrays(1, &g.vao);
  glBindVertexArray(g.vao);
  glGenBuffers(4, g.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, g.vbo[0]);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(nv * 3 * sizeof(float)), pos.f.data(), GL_STATIC_DRAW);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
  glEnableVertexAttribArray(0);
  // Normals: given, or computed as three.js's computeVertexNormals does for the WebGL
  // fallback (area-weighted face normals summed at shared vertices; non-indexed meshes get
  // flat normals).
  const std::vector<uint32_t>* idx = idx_id != kNoId ? &scene.buffer(idx_id)->u : nullptr;
  std::vector<float> computed;
  const float* normals = nullptr;
  if (nrm_id != kNoId) {
    normals = scene.buffer(nrm_id)->f.data();
  } else {
    computed.assign(nv * 3, 0.0f);
    const float* p = pos.f.data();
    size_t nt = idx ? idx->size() / 3 : nv / 3;
    for (size_t t = 0; t < nt; ++t) {
      uint32_t a = idx ? (*idx)[t * 3] : uint32_t(t * 3), b = idx ? (*idx)[t * 3 + 1] : uint32_t(t * 3 + 1),
               c = idx ? (*idx)[t * 3 + 2] : uint32_t(t * 3 + 2);
      Vec3 va{p[a * 3], p[a * 3 + 1], p[a * 3 + 2]}, vb{p[b * 3], p[b * 3 + 1], p[b * 3 + 2]},
          vc{p[c * 3], p[c * 3 + 1], p[c * 3 + 2]};
      Vec3 n = cross(vc - vb, va - vb);
      for (uint32_t v : {a, b, c}) {
        computed[v * 3] += n.x; computed[v * 3 + 1] += n.y; computed[v * 3 + 2] += n.z;
      }
    }
    for (size_t v = 0; v < nv; ++v) {
      Vec3 n = normalize(Vec3{computed[v * 3], computed[v * 3 + 1], computed[v * 3 + 2]});
      computed[v * 3] = n.x; computed[v * 3 + 1] = n.y; computed[v * 3 + 2] = n.z;
    }
    normals = computed.data();
  }
  glBindBuffer(GL_ARRAY_BUFFER, g.vbo[1]);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(nv * 3 * sizeof(float)), normals, GL_STATIC_DRAW);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
  glEnableVertexAttribArray(1);
  g.has_uv = uv_id != kNoId;
  if (g.has_uv) {
    glBindBuffer(GL_ARRAY_BUFFER, g.vbo[2]);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(nv * 2 * sizeof(float)), scene.buffer(uv_id)->f.data(), GL_STATIC_DRAW);
    glVertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, 0, nullptr);
    glEnableVertexAttribArray(2);
  } else {
    glDisableVertexAttribArray(2);
    glVertexAttrib2f(2, 0, 0);
  }
  g.has_color = col_id != kNoId;  // read only where the material uses vertex colours (uUseVertexColor)
  if (g.has_color) {
    glBindBuffer(GL_ARRAY_BUFFER, g.vbo[3]);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(nv * 3 * sizeof(float)), scene.buffer(col_id)->f.data(), GL_STATIC_DRAW);
    glVertexAttribPointer(3, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
    glEnableVertexAttribArray(3);
  } else {
    glDisableVertexAttribArray(3);
  }
  g.indexed = idx != nullptr;
  if (idx) {
    glGenBuffers(1, &g.ibo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(idx->size() * sizeof(uint32_t)), idx->data(), GL_STATIC_DRAW);
    g.count = GLsizei(idx->size());
  } else {
    g.count = GLsizei(nv - nv % 3);
  }
  glBindVertexArray(0);
  g.lo = Vec3{INFINITY, INFINITY, INFINITY};
  g.hi = Vec3{-INFINITY, -INFINITY, -INFINITY};
  for (size_t v = 0; v < nv; ++v) {
    const float* q = &pos.f[v * 3];
    g.lo = {std::fmin(g.lo.x, q[0]), std::fmin(g.lo.y, q[1]), std::fmin(g.lo.z, q[2])};
    g.hi = {std::fmax(g.hi.x, q[0]), std::fmax(g.hi.y, q[1]), std::fmax(g.hi.z, q[2])};
  }
  if (glGetError() == GL_OUT_OF_MEMORY) throw std::runtime_error("rasterizer: out of memory uploading geometry");
  ++stats.geometries_uploaded;
}

void Rasterizer::Impl::sync(const Scene& scene, std::vector<std::string>& warnings) {
  stats = {};
  env = scene.environment();
  if (!std::isfinite(env.exposure)) env.exposure = 1.0f;
  // Textures: sRGB-decoded in the sampler when the scene is linear, as the ray tracer does.
  for (auto it = textures.begin(); it != textures.end();) {
    if (scene.textures().count(it->first)) { ++it; continue; }
    if (it->second.name) glDeleteTextures(1, &it->second.name);
    it = textures.erase(it);
  }
  for (auto& [id, e] : scene.textures()) {
    Tex& t = textures[id];
    bool decode = env.linear && e.value.srgb;
    if (t.version == e.version && (t.decoded == decode || !t.name)) continue;
    t.version = e.version;
    upload_texture(id, e.value, t, decode, warnings);
  }
  materials.clear();
  for (auto& [id, e] : scene.materials()) {
    Material m = e.value;
    m.opacity = std::fmin(std::fmax(std::isfinite(m.opacity) ? m.opacity : 1.0f, 0.0f), 1.0f);
    m.refraction = std::fmin(std::fmax(std::isfinite(m.refraction) ? m.refraction : 0.0f, 0.0f), 1.0f);
    materials[id] = m;
  }

  // Geometry per buffer set; instances per mesh.
  for (auto& [k, g] : geoms) g.used = false;
  std::map<Id, GeomKey> mesh_key;
  for (auto [id, mesh] : scene.renderable_meshes(warnings)) {
    const Mesh& m = *mesh;
    GeomKey key{m.positions, m.normals, m.texcoords, m.colors, m.indices};
    mesh_key[id] = key;
    uint64_t v = 0;
    for (Id b : {m.positions, m.normals, m.texcoords, m.colors, m.indices})
      if (b != kNoId) v = std::max(v, scene.buffers().at(b).version);
    Geom& g = geoms[key];
    if (!g.used && (!g.vao || g.version != v)) {
      upload_geom(scene, key, g);  // resets g
      g.version = v;
    }
    g.used = true;
  }
  for (auto it = insts.begin(); it != insts.end();) {
    if (mesh_key.count(it->first)) { ++it; continue; }
    it = insts.erase(it);
    ++stats.instances_removed;
  }
  for (auto& [id, key] : mesh_key) {
    const auto& e = scene.meshes().at(id);
    Inst& inst = insts[id];
    if (inst.version == e.version && inst.key == key) continue;
    inst.key = key;
    inst.transform = e.value.transform;
    inst.material = e.value.material;
    inst.version = e.version;
    ++stats.instances_updated;
  }
  for (auto it = geoms.begin(); it != geoms.end();) {
    if (it->second.used) { ++it; continue; }
    free_geom(it->second);
    it = geoms.erase(it);
  }

  lights.clear();
  int counts[3] = {0, 0, 0};
  for (auto& [id, e] : scene.lights()) {
    Light l = e.value;
    if (!l.on || !finite(l.position) || !finite(l.direction) || !finite(l.color) || !std::isfinite(l.intensity)) continue;
    l.direction = normalize(l.direction);
    if (l.type != Light::Type::point && length(l.direction) == 0) continue;
    if (counts[int(l.type)]++ >= kMaxLights) {
      warnings.push_back("light " + std::to_string(id) + " ignored: the rasterizer (as the WebGL fallback) shades at most " +
                         std::to_string(kMaxLights) + " lights of each type");
      continue;
    }
    lights.push_back(l);
  }
  camera = scene.camera();
  width = scene.width();
  height = scene.height();
  if (glGetError() == GL_OUT_OF_MEMORY) throw std::runtime_error("rasterizer: out of GL memory during sync");
}

// ---------------------------------------------------------------------------------------
// Rendering a task: the full frame's viewport and projection, scissored to the task.
// ---------------------------------------------------------------------------------------

void Rasterizer::Impl::ensure_framebuffer() {
  if (fb_w == width && fb_h == height && color_rb) return;
  if (width > max_renderbuffer || height > max_renderbuffer)
    throw std::runtime_error("rasterizer: " + std::to_string(width) + "x" + std::to_string(height) +
                             " exceeds GL_MAX_RENDERBUFFER_SIZE " + std::to_string(max_renderbuffer));
  if (!color_rb) glGenRenderbuffers(1, &color_rb);
  if (!depth_rb) glGenRenderbuffers(1, &depth_rb);
  glBindRenderbuffer(GL_RENDERBUFFER, color_rb);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_rb);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_rb);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_rb);
  GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    char b[64];
    std::snprintf(b, sizeof b, "0x%04x", unsigned(status));
    throw std::runtime_error(std::string("rasterizer: offscreen framebuffer incomplete: ") + b);
  }
  fb_w = width;
  fb_h = height;
}

void Rasterizer::Impl::render(const Rect& requested, const RenderSettings& settings, TaskResult& out) {
  Rect pixels = intersect(requested, {0, 0, width, height});
  out.pixels = pixels;
  out.image = Image(pixels.width(), pixels.height());
  out.cost = {};
  out.rays = {};
  out.kernel_ms = 0;
  out.rendering_ms = 0;
  if (pixels.empty()) return;
  auto t0 = std::chrono::steady_clock::now();
  ensure_framebuffer();
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  glViewport(0, 0, width, height);
  glEnable(GL_SCISSOR_TEST);
  glScissor(pixels.x0, height - pixels.y1, pixels.width(), pixels.height());  // GL rows go up

  // Camera at the origin of a camera-relative world.
  Vec3 eye = camera.to_world.transform_point({0, 0, 0});
  Mat4 view = inverse(camera.to_world) * Mat4::translate(eye);
  Mat4 rebase = Mat4::translate(-eye);
  // Near/far as the WebGL fallback (ThreeRenderer.updateCamera): the scene box in view space.
  float zmin = INFINITY, zmax = -INFINITY;
  for (auto& [id, inst] : insts) {
    const Geom& g = geoms.at(inst.key);
    Mat4 mv = view * rebase * inst.transform;
    for (int k = 0; k < 8; ++k) {
      Vec3 p{k & 1 ? g.hi.x : g.lo.x, k & 2 ? g.hi.y : g.lo.y, k & 4 ? g.hi.z : g.lo.z};
      float z = -mv.transform_point(p).z;
      zmin = std::fmin(zmin, z);
      zmax = std::fmax(zmax, z);
    }
  }
  float near = 1, far = 10;
  if (zmax > 0) {
    float margin = (zmax - std::fmax(zmin, 0.0f)) * 0.05f + 1e-3f;
    far = zmax + margin;
    near = std::fmax(std::fmax(zmin - margin, far * 1e-4f), 0.01f);
  }
  float tan_half = std::tan(std::fmin(std::fmax(camera.fov_y, 1e-6f), kPi - 1e-4f) * 0.5f);
  float aspect = float(width) / float(height);
  Mat4 proj;
  proj.m = {1.0f / (tan_half * aspect), 0, 0, 0, 0, 1.0f / tan_half, 0, 0, 0, 0, (far + near) / (near - far), -1,
            0, 0, 2 * far * near / (near - far), 0};
  Mat4 view_proj = proj * view;

  // Clear to the background, as the ray tracer shows it.
  const bool encode = env.linear;
  auto out_color = [&](float c) { c *= env.exposure; return encode ? srgb_encode(c) : std::fmin(std::fmax(c, 0.0f), 1.0f); };
  glClearColor(out_color(env.background.x), out_color(env.background.y), out_color(env.background.z), 1.0f);
  glClearDepthf(1.0f);
  glDepthMask(GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);

  float pp[kMaxLights * 3] = {}, pi[kMaxLights * 3] = {}, pa[kMaxLights * 3] = {}, dd[kMaxLights * 3] = {},
        di[kMaxLights * 3] = {}, sp[kMaxLights * 3] = {}, sd[kMaxLights * 3] = {}, si[kMaxLights * 3] = {},
        sa[kMaxLights * 3] = {}, sc[kMaxLights * 2] = {};
  int np = 0, nd = 0, ns = 0;
  auto put = [](float* a, int i, const Vec3& v) { a[i * 3] = v.x; a[i * 3 + 1] = v.y; a[i * 3 + 2] = v.z; };
  for (const Light& l : lights) {
    Vec3 I = l.color * l.intensity;
    Vec3 p = l.position - eye;
    if (l.type == Light::Type::point) {
      put(pp, np, p); put(pi, np, I); put(pa, np, l.attenuation); ++np;
    } else if (l.type == Light::Type::directional) {
      put(dd, nd, l.direction); put(di, nd, I); ++nd;
    } else {
      float soft = std::fmin(std::fmax(l.softness, 0.0f), 1.0f);
      put(sp, ns, p); put(sd, ns, l.direction); put(si, ns, I); put(sa, ns, l.attenuation);
      sc[ns * 2] = std::cos(l.cutoff);
      sc[ns * 2 + 1] = std::cos(l.cutoff * (1 - soft));
      ++ns;
    }
  }
  for (const Program& prog : programs) {
    const Uniforms& u = prog.u;
    glUseProgram(prog.name);
    glUniformMatrix4fv(u.view_proj, 1, GL_FALSE, view_proj.m.data());
    glUniform1f(u.diffuse_scale, env.linear ? 1.0f / kPi : 1.0f);
    glUniform1f(u.exposure, env.exposure);
    glUniform1i(u.encode_srgb, encode ? 1 : 0);
    glUniform3f(u.scene_ambient, env.ambient.x, env.ambient.y, env.ambient.z);
    glUniform1i(u.num_point, np);
    glUniform1i(u.num_dir, nd);
    glUniform1i(u.num_spot, ns);
    glUniform3fv(u.point_pos, kMaxLights, pp);
    glUniform3fv(u.point_int, kMaxLights, pi);
    glUniform3fv(u.point_att, kMaxLights, pa);
    glUniform3fv(u.dir_dir, kMaxLights, dd);
    glUniform3fv(u.dir_int, kMaxLights, di);
    glUniform3fv(u.spot_pos, kMaxLights, sp);
    glUniform3fv(u.spot_dir, kMaxLights, sd);
    glUniform3fv(u.spot_int, kMaxLights, si);
    glUniform3fv(u.spot_att, kMaxLights, sa);
    glUniform2fv(u.spot_cone, kMaxLights, sc);
  }

  // Draw list: opaque front to back, then transparent back to front (as three.js sorts,
  // by the clip-space depth of each object's origin, ties by id).
  struct Draw {
    const Inst* inst;
    const Geom* geom;
    const Material* mat;
    float opacity;
    bool transparent;
    float z;
    Id id;
    bool can_discard;
  };
  static const Material kDefault = default_material();
  std::vector<Draw> draws;
  draws.reserve(insts.size());
  for (auto& [id, inst] : insts) {
    auto mit = materials.find(inst.material);
    const Material* m = mit == materials.end() ? &kDefault : &mit->second;
    // The WebGL fallback draws refracting materials partly transparent (XML3DMaterial.js).
    float opacity = m->opacity * (m->refraction > 0 ? 1 - 0.7f * m->refraction : 1.0f);
    Vec3 o = (rebase * inst.transform).transform_point({0, 0, 0});
    const float* vp = view_proj.m.data();
    float cz = vp[2] * o.x + vp[6] * o.y + vp[10] * o.z + vp[14];
    float cw = vp[3] * o.x + vp[7] * o.y + vp[11] * o.z + vp[15];
    const Geom* g = &geoms.at(inst.key);
    auto tex = g->has_uv && m->diffuse_texture != kNoId ? textures.find(m->diffuse_texture) : textures.end();
    bool alpha_tex = tex != textures.end() && tex->second.name && tex->second.has_alpha;
    bool can_discard = m->alpha_mask || opacity < 0.05f || alpha_tex;
    draws.push_back({&inst, g, m, opacity, opacity < 1 && !m->alpha_mask, cw != 0 ? cz / cw : 0, id, can_discard});
  }
  std::stable_sort(draws.begin(), draws.end(), [](const Draw& a, const Draw& b) {
    if (a.transparent != b.transparent) return !a.transparent;
    if (a.z != b.z) return a.transparent ? a.z > b.z : a.z < b.z;
    return a.id < b.id;
  });

  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDisable(GL_CULL_FACE);  // XML3D: no face culling
  glDisable(GL_BLEND);
  bool blending = false;
  const Program* current = nullptr;
  for (const Draw& d : draws) {
    if (d.transparent && !blending) {
      glEnable(GL_BLEND);
      glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ZERO, GL_ONE);
      glDepthMask(GL_FALSE);
      blending = true;
    }
    const Program& prog = programs[d.can_discard ? 0 : 1];
    if (&prog != current) {
      glUseProgram(prog.name);
      current = &prog;
    }
    const Uniforms& u = prog.u;
    const Material& m = *d.mat;
    Mat4 model = rebase * d.inst->transform;
    Mat4 nm4 = transpose(inverse(d.inst->transform));
    const float nm[9] = {nm4.m[0], nm4.m[1], nm4.m[2], nm4.m[4], nm4.m[5], nm4.m[6], nm4.m[8], nm4.m[9], nm4.m[10]};
    glUniformMatrix4fv(u.model, 1, GL_FALSE, model.m.data());
    glUniformMatrix3fv(u.normal_matrix, 1, GL_FALSE, nm);
    glUniform1i(u.model_kind, int(m.model));
    glUniform3f(u.diffuse, m.diffuse_color.x, m.diffuse_color.y, m.diffuse_color.z);
    glUniform3f(u.specular, m.specular_color.x, m.specular_color.y, m.specular_color.z);
    glUniform3f(u.emissive, m.emissive_color.x, m.emissive_color.y, m.emissive_color.z);
    glUniform1f(u.shininess, m.shininess);
    glUniform1f(u.ambient_intensity, m.ambient_intensity);
    glUniform1f(u.opacity, d.opacity);
    glUniform1f(u.alpha_cutoff, m.alpha_cutoff);
    glUniform1i(u.alpha_mask, m.alpha_mask ? 1 : 0);
    glUniform1i(u.blend, d.transparent ? 1 : 0);
    glUniform1i(u.use_vertex_color, m.use_vertex_color && d.geom->has_color ? 1 : 0);
    auto bind = [&](int unit, Id tex, GLint flag) {
      auto it = tex != kNoId && d.geom->has_uv ? textures.find(tex) : textures.end();
      bool ok = it != textures.end() && it->second.name;
      glActiveTexture(GLenum(GL_TEXTURE0 + unit));
      glBindTexture(GL_TEXTURE_2D, ok ? it->second.name : white);
      glUniform1i(flag, ok ? 1 : 0);
    };
    bind(0, m.diffuse_texture, u.has_diffuse_tex);
    bind(1, m.specular_texture, u.has_specular_tex);
    bind(2, m.emissive_texture, u.has_emissive_tex);
    glBindVertexArray(d.geom->vao);
    if (d.geom->indexed) glDrawElements(GL_TRIANGLES, d.geom->count, GL_UNSIGNED_INT, nullptr);
    else glDrawArrays(GL_TRIANGLES, 0, d.geom->count);
  }
  glBindVertexArray(0);
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);

  // Read back (GL's rows go up; the image's go down).
  const int32_t w = pixels.width(), h = pixels.height();
  std::vector<uint8_t> rows(size_t(w) * h * 4);
  glReadPixels(pixels.x0, height - pixels.y1, w, h, GL_RGBA, GL_UNSIGNED_BYTE, rows.data());
  GLenum err = glGetError();
  if (err != GL_NO_ERROR) {
    char b[64];
    std::snprintf(b, sizeof b, "0x%04x", unsigned(err));
    throw std::runtime_error(std::string("rasterizer: GL error while rendering: ") + b);
  }
  for (int32_t y = 0; y < h; ++y) {
    uint8_t* dst = out.image.pixel(0, y);
    std::memcpy(dst, &rows[size_t(h - 1 - y) * w * 4], size_t(w) * 4);
    for (int32_t x = 0; x < w; ++x) dst[x * 4 + 3] = 255;
  }
  glDisable(GL_SCISSOR_TEST);
  (void)settings;  // no AO, secondary rays or shadows in a rasterizer (docs/renderer.md)
  out.rendering_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// ---------------------------------------------------------------------------------------
// Public interface
// ---------------------------------------------------------------------------------------

Rasterizer::Rasterizer() : impl_(std::make_unique<Impl>()) {}
Rasterizer::~Rasterizer() = default;

void Rasterizer::sync(const Scene& scene, std::vector<std::string>& warnings) {
  CurrentContext current(*impl_);
  impl_->sync(scene, warnings);
}

void Rasterizer::render(const Rect& pixels, const RenderSettings& settings, TaskResult& out) {
  CurrentContext current(*impl_);
  impl_->render(pixels, settings, out);
}

std::string Rasterizer::gl_description() {
  CurrentContext current(*impl_);
  auto str = [](GLenum e) {
    const GLubyte* s = glGetString(e);
    return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
  };
  return str(GL_RENDERER) + ", " + str(GL_VERSION);
}

Rasterizer::SyncStats Rasterizer::last_sync() const { return impl_->stats; }

bool rasterizer_available(std::string* why) {
  try {
    Rasterizer r;
    r.gl_description();
    return true;
  } catch (const std::exception& e) {
    if (why) *why = e.what();
    return false;
  }
}

}  // namespace tessera
