#pragma once
// The scene model shared by every renderer and by the sync channel that drives it.
//
// Entries (buffers, textures, materials, meshes, lights) are keyed by ids the client
// chooses and can be added, changed or removed at any time. Each entry carries the
// scene-wide version at which it last changed, so a renderer syncs by comparing versions
// with what it saw last time and touches only what changed (scene_sync.h).
//
// A mesh references geometry buffers by id and carries its own transform and material.
// Meshes that reference the same geometry buffers are instances of one geometry.
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/math.h"
#include "core/shared_bytes.h"

namespace tessera {

using Id = uint32_t;
constexpr Id kNoId = 0;  // "no reference" (ids chosen by clients start at 1)

// A typed array: float (positions, normals, texcoords, colours) or uint32 (indices).
struct Buffer {
  enum class Type : uint8_t { f32 = 0, u32 = 1 };
  Type type = Type::f32;
  uint8_t components = 1;  // 1..4 per element
  std::vector<float> f;    // type == f32
  std::vector<uint32_t> u; // type == u32
  size_t count() const { return (type == Type::f32 ? f.size() : u.size()) / (components ? components : 1); }
  size_t bytes() const { return f.size() * 4 + u.size() * 4; }
};

struct Sampler {
  enum class Wrap : uint8_t { clamp = 0, repeat = 1 };
  enum class Filter : uint8_t { nearest = 0, linear = 1 };
  Wrap wrap_s = Wrap::repeat, wrap_t = Wrap::repeat;
  Filter filter = Filter::linear;
};

// RGBA8 texels, row 0 at the top (texcoord v = 0), as images are stored and as glTF maps them.
struct Texture {
  int32_t width = 0, height = 0;
  SharedBytes rgba;  // shared with the copies of this texture and with the renderers that show it
  Sampler sampler;
  bool srgb = true;  // texels are sRGB-encoded colours (decoded to linear when shading, if the scene is linear)
  bool has_alpha() const;  // any texel with alpha < 255 (computed on demand)
};

// XML3D's matte / diffuse / phong materials plus the paper's reflection, refraction and IOR.
struct Material {
  enum class Model : uint8_t { matte = 0, diffuse = 1, phong = 2 };
  Model model = Model::phong;
  Vec3 diffuse_color{1, 1, 1};
  Vec3 specular_color{0, 0, 0};
  float shininess = 0.2f;         // XML3D: the specular exponent is shininess * 128
  Vec3 emissive_color{0, 0, 0};
  float ambient_intensity = 0.0f;  // XML3D's ambientIntensity
  float opacity = 1.0f;
  Id diffuse_texture = kNoId, specular_texture = kNoId, emissive_texture = kNoId;
  float reflection = 0.0f;  // mirror reflection coefficient (0..1), Fresnel-weighted when refracting
  float refraction = 0.0f;  // transmission coefficient (0..1)
  float ior = 1.0f;         // index of refraction of the material's inside
  bool alpha_mask = false;  // cut out where diffuse texture alpha (x opacity) < alpha_cutoff
  float alpha_cutoff = 0.5f;
  bool double_sided = true;
  bool use_vertex_color = false;  // XML3D's useVertexColor: the mesh's vertex colours multiply diffuse_color
};

struct Mesh {
  Id positions = kNoId;  // float3, required
  Id normals = kNoId;    // float3, optional (flat normals when missing)
  Id texcoords = kNoId;  // float2, optional
  Id colors = kNoId;     // float3 vertex colours, optional (used by materials with use_vertex_color)
  Id indices = kNoId;    // uint32 triangles, optional (non-indexed: positions taken in threes)
  Mat4 transform;        // object to world
  Id material = kNoId;   // kNoId: the default material
  bool visible = true;
};

struct Light {
  enum class Type : uint8_t { point = 0, directional = 1, spot = 2 };
  Type type = Type::directional;
  Vec3 color{1, 1, 1};
  float intensity = 1.0f;
  Vec3 position{0, 0, 0};      // point, spot (world)
  Vec3 direction{0, 0, -1};    // directional, spot: the direction light travels (world)
  Vec3 attenuation{0, 0, 1};   // point, spot: constant, linear, quadratic (XML3D)
  float cutoff = kPi / 4;      // spot: half-angle in radians
  float softness = 0.0f;       // spot: 0 = hard edge, 1 = fades over the whole cone
  bool on = true;
  bool cast_shadow = true;     // false: no shadow rays, it reaches every surface facing it
                               // (XML3D's castShadow, default false in markup; glTF lights cast)
};

struct Camera {
  Mat4 to_world;                  // camera looks down -Z, +Y up (XML3D / glTF convention)
  float fov_y = kPi / 4;          // vertical field of view in radians
};

// Lighting and colour conventions that are per scene, not per entry.
struct Environment {
  Vec3 ambient{0, 0, 0};  // radiance of a uniform sky, applied to diffuse surfaces (times AO)
  Vec3 background{0, 0, 0};
  float exposure = 1.0f;
  bool linear = true;     // true: sRGB textures decoded, output sRGB-encoded (glTF);
                          // false: XML3D/WebGL convention, colours used and written as given
};

template <class T>
struct Entry {
  T value;
  uint64_t version = 0;
};

class Scene {
 public:
  // Mutators bump the scene version and stamp the entry with it.
  // Buffer, texture and mesh mutators also keep the running totals below up to date.
  void set_buffer(Id id, Buffer b);
  void set_texture(Id id, Texture t);
  void set_material(Id id, Material m) { put(materials_, id, std::move(m)); }
  void set_mesh(Id id, Mesh m);
  void set_light(Id id, Light l) { put(lights_, id, std::move(l)); }
  bool remove_buffer(Id id);
  bool remove_texture(Id id);
  bool remove_material(Id id) { return drop(materials_, id); }
  bool remove_mesh(Id id);
  bool remove_light(Id id) { return drop(lights_, id); }

  void set_camera(const Camera& c) { camera_ = c; camera_version_ = bump(); }
  void set_environment(const Environment& e) { env_ = e; env_version_ = bump(); }
  void set_resolution(int32_t w, int32_t h) { width_ = w; height_ = h; bump(); }

  const std::map<Id, Entry<Buffer>>& buffers() const { return buffers_; }
  const std::map<Id, Entry<Texture>>& textures() const { return textures_; }
  const std::map<Id, Entry<Material>>& materials() const { return materials_; }
  const std::map<Id, Entry<Mesh>>& meshes() const { return meshes_; }
  const std::map<Id, Entry<Light>>& lights() const { return lights_; }
  const Camera& camera() const { return camera_; }
  const Environment& environment() const { return env_; }
  int32_t width() const { return width_; }
  int32_t height() const { return height_; }
  uint64_t version() const { return version_; }
  uint64_t camera_version() const { return camera_version_; }
  uint64_t environment_version() const { return env_version_; }

  const Buffer* buffer(Id id) const { return find(buffers_, id); }
  const Texture* texture(Id id) const { return find(textures_, id); }
  const Material* material(Id id) const { return find(materials_, id); }

  // Checks a mesh against the buffers it references: existence, element types and
  // component counts, matching vertex counts, index range, finite positions, and its
  // transform against the bounds of core/validate.h (check_transform with kMeshLimits,
  // and the world box its vertices land in), so that a scene built in code and never
  // validated still hands Embree nothing it asserts on. Returns an
  // empty string when the mesh can be rendered, else what is wrong. A missing material is
  // not an error (the default material is used until it arrives).
  std::string validate_mesh(const Mesh& m) const;
  // The meshes a renderer can draw now: visible ones that pass validate_mesh, by id. Why each
  // other visible mesh is skipped is appended to warnings.
  std::vector<std::pair<Id, const Mesh*>> renderable_meshes(std::vector<std::string>& warnings) const;

  // Triangles over visible meshes, instances counted each time. A mesh counts its index
  // buffer's triangles when it names one (0 while that buffer is missing), else its
  // positions / 3 (0 while missing). Kept as a running total: O(1).
  size_t triangle_count() const { return size_t(triangles_); }
  // What triangle_count() would be if buffer `id` held `b` (nullptr: removed), or if mesh `id`
  // were `m` (nullptr: removed). O(log n): the sync channel checks limits per record with these.
  uint64_t triangles_with_buffer(Id id, const Buffer* b) const;
  uint64_t triangles_with_mesh(Id id, const Mesh* m) const;
  // Bytes of the buffers (4 per element) and textures (RGBA8 texels) held. O(1).
  uint64_t held_bytes() const { return held_bytes_; }

 private:
  // Versions come from one counter for the whole process, not one per scene: an entry's version
  // then names its content in every scene, so a renderer that syncs from another scene object
  // (a worker's scene, made anew when its parent resets it, with the same ids) never mistakes
  // a new entry for the one it holds.
  static uint64_t next_version();
  uint64_t bump() { return version_ = next_version(); }
  template <class T>
  void put(std::map<Id, Entry<T>>& map, Id id, T v) {
    auto& e = map[id];
    e.value = std::move(v);
    e.version = bump();
  }
  template <class T>
  bool drop(std::map<Id, Entry<T>>& map, Id id) {
    if (map.erase(id) == 0) return false;
    bump();
    return true;
  }
  template <class T>
  static const T* find(const std::map<Id, Entry<T>>& map, Id id) {
    auto it = map.find(id);
    return it == map.end() ? nullptr : &it->second.value;
  }

  // Per buffer: facts validate_mesh needs, computed once when the buffer is set, and how
  // many visible meshes take their triangles from it (as index buffer / as non-indexed positions).
  struct BufferIndex {
    bool finite = true;        // every float is finite
    float max_abs = 0;         // largest |float| (when finite)
    uint64_t max_index = 0;    // largest uint32 element + 1 (0: none)
    uint32_t index_refs = 0, position_refs = 0;
  };
  static uint64_t index_triangles(const Buffer* b) { return b ? b->u.size() / 3 : 0; }
  static uint64_t position_triangles(const Buffer* b) { return b ? b->count() / 3 : 0; }
  uint64_t mesh_triangles(const Mesh& m) const;
  void count_mesh(const Mesh& m, int sign);  // adds/removes a mesh's references and triangles

  std::map<Id, BufferIndex> buffer_index_;   // ids of buffers held or referenced by a visible mesh
  uint64_t triangles_ = 0, held_bytes_ = 0;
  std::map<Id, Entry<Buffer>> buffers_;
  std::map<Id, Entry<Texture>> textures_;
  std::map<Id, Entry<Material>> materials_;
  std::map<Id, Entry<Mesh>> meshes_;
  std::map<Id, Entry<Light>> lights_;
  Camera camera_;
  Environment env_;
  int32_t width_ = 640, height_ = 480;
  uint64_t version_ = 0, camera_version_ = 0, env_version_ = 0;
};

}  // namespace tessera
